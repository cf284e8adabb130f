//! `throng completions SHELL` (clap_complete) and `throng man` (clap_mangen).

use std::path::PathBuf;

use clap::{Args, CommandFactory};

use throng::error::{Error, Result};

/// `throng completions`.
#[derive(Debug, Args)]
pub struct CompletionsArgs {
    /// bash, zsh, fish, elvish or powershell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// `throng man`.
#[derive(Debug, Args)]
pub struct ManArgs {
    /// Write `throng.1` and one `throng-<verb>.1` per verb into this existing
    /// folder (default: print `throng.1` to stdout).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Prints the completion script for a shell to stdout.
pub fn completions(args: &CompletionsArgs) -> Result<()> {
    let mut cmd = super::Cli::command();
    let mut bytes = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "throng", &mut bytes);
    out!("{}", String::from_utf8_lossy(&bytes));
    Ok(())
}

/// Prints or writes the man pages.
pub fn man(args: &ManArgs) -> Result<()> {
    let cmd = super::Cli::command();
    match &args.out {
        None => {
            let mut bytes = Vec::new();
            clap_mangen::Man::new(cmd).render(&mut bytes).map_err(|e| Error::Usage(format!("man page: {e}")))?;
            out!("{}", String::from_utf8_lossy(&bytes));
        }
        Some(dir) => {
            if !dir.is_dir() {
                return Err(Error::Usage(format!("--out {}: no such folder (create it first)", dir.display())));
            }
            clap_mangen::generate_to(cmd, dir).map_err(|e| Error::io(dir, e))?;
            outln!("wrote man pages into {}", dir.display());
        }
    }
    Ok(())
}
