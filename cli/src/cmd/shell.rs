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
    let mut cmd = without_hidden(&super::Cli::command());
    let mut bytes = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, "throng", &mut bytes);
    out!("{}", String::from_utf8_lossy(&bytes));
    Ok(())
}

/// Writes the page of `cmd` and of each of its visible subcommands into
/// `dir`, named as clap_mangen names them (`throng-farm-plan.1`), each
/// through a temporary file renamed whole, like every other output.
fn write_pages(cmd: &clap::Command, dir: &std::path::Path, written: &mut usize) -> Result<()> {
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
        write_pages(sub, dir, written)?;
    }
    let page = clap_mangen::Man::new(cmd.clone());
    let path = dir.join(page.get_filename());
    throng::error::write_atomic(&path, |w| page.render(w).map_err(|e| Error::io(&path, e)))?;
    *written += 1;
    Ok(())
}

/// A copy of `cmd` without its hidden subcommands (`farm run-task`, which
/// only engines call): completions offer only what a user types. clap cannot
/// remove a subcommand, so the tree is rebuilt from names, about texts and
/// arguments, which is all a completion script uses.
fn without_hidden(cmd: &clap::Command) -> clap::Command {
    let mut out = clap::Command::new(cmd.get_name().to_string()).args(cmd.get_arguments().cloned());
    if let Some(about) = cmd.get_about() {
        out = out.about(about.clone());
    }
    if let Some(version) = cmd.get_version() {
        out = out.version(version.to_string());
    }
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set()) {
        out = out.subcommand(without_hidden(sub));
    }
    out
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
            let mut cmd = cmd.disable_help_subcommand(true);
            cmd.build();
            let mut written = 0;
            write_pages(&cmd, dir, &mut written)?;
            outln!("wrote {written} man pages into {}", dir.display());
        }
    }
    Ok(())
}
