//! `throng completions SHELL` (clap_complete) and `throng man` (clap_mangen).

use std::io::Write;
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

/// `throng help [VERB]...` (and `throng farm help`, `throng cache help`).
#[derive(Debug, Args)]
pub struct HelpArgs {
    /// The verb (and sub-verb) to print the help of, e.g. `farm plan`.
    #[arg(value_name = "VERB")]
    pub verb: Vec<String>,
}

/// Prints the long help of the verb `under` + `args.verb` names (`--help`'s text).
pub fn help(under: &[&str], args: &HelpArgs) -> Result<()> {
    let mut cmd = super::Cli::command();
    cmd.build();
    let mut at = &mut cmd;
    let mut path = vec!["throng".to_string()];
    for name in under.iter().copied().chain(args.verb.iter().map(String::as_str)) {
        let verbs: Vec<String> =
            at.get_subcommands().filter(|s| !s.is_hide_set()).map(|s| s.get_name().to_string()).collect();
        at = match at.find_subcommand_mut(name) {
            Some(sub) => sub,
            None if verbs.is_empty() => {
                return Err(Error::Usage(format!("`{}` has no verbs; `{name}` is not one", path.join(" "))));
            }
            None => {
                return Err(Error::Usage(format!(
                    "`{} {name}` is not a verb (verbs: {})",
                    path.join(" "),
                    verbs.join(", ")
                )));
            }
        };
        path.push(name.to_string());
    }
    // Exactly what `--help` prints there: asked of the parser itself.
    path.push("--help".to_string());
    match super::Cli::command().try_get_matches_from(&path) {
        Err(e) if e.kind() == clap::error::ErrorKind::DisplayHelp => out!("{}", e.render()),
        _ => out!("{}", at.render_long_help()),
    }
    Ok(())
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
    // `help` has no page of its own: it prints the others' text.
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set() && s.get_name() != "help") {
        write_pages(sub, dir, written)?;
    }
    let page = clap_mangen::Man::new(cmd.clone());
    let path = dir.join(page.get_filename());
    let text = page_of(cmd).map_err(|e| Error::io(&path, e))?;
    throng::error::write_atomic(&path, |w| w.write_all(&text).map_err(|e| Error::io(&path, e)))?;
    *written += 1;
    Ok(())
}

/// The man page of `cmd`: clap_mangen's sections, then EXAMPLES and EXIT STATUS.
fn page_of(cmd: &clap::Command) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    clap_mangen::Man::new(cmd.clone()).render(&mut bytes)?;
    let path = cmd.get_bin_name().unwrap_or(cmd.get_name());
    let verb = path.strip_prefix("throng").unwrap_or(path).trim();
    let mut extra = String::from(".SH EXAMPLES\n");
    for (line, what) in examples(verb) {
        extra += &format!(".TP\n\\fB{}\\fR\n{}\n", roff(&line), roff(&what));
    }
    extra += ".SH \"EXIT STATUS\"\n";
    for (code, what) in exit_status(verb) {
        extra += &format!(".TP\n{code}\n{}\n", roff(what));
    }
    bytes.extend_from_slice(extra.as_bytes());
    Ok(bytes)
}

/// Text made safe for a roff line: backslashes and hyphens escaped, and a
/// leading `.` or `'` not read as a request.
fn roff(text: &str) -> String {
    let t = text.replace('\\', "\\e").replace('-', "\\-");
    if t.starts_with(['.', '\'']) {
        format!("\\&{t}")
    } else {
        t
    }
}

/// A page's EXAMPLES: command lines and what each does, by verb path
/// (`""` for `throng` itself, `"farm status"`).
fn examples(verb: &str) -> Vec<(String, String)> {
    let e = |line: &str, what: &str| (line.to_string(), what.to_string());
    match verb {
        "" => vec![
            e("throng demo --out out/demo", "Build the bundled demo shot and run every stage on it."),
            e("throng layers shot.toml", "Split the shot's agents into render layers (writes shot.layers.json)."),
            e("throng render shot.toml --frames 1001-1010 --out renders", "Render every layer of ten frames."),
            e("throng help render", "The help of one verb (as throng render --help)."),
        ],
        "demo" => vec![e("throng demo --out out/demo --spp 4", "The demo at 4 samples per pixel, into out/demo.")],
        "cache" | "cache info" => vec![
            e("throng cache info crowd.crowd", "Frames, agents, rigs, cycles and bounds of a cache."),
            e("throng cache info traj.txt --preset petrack", "The same of a PeTrack trajectory table."),
        ],
        "cache convert" => vec![e("throng cache convert sim.sqlite crowd.crowd", "A JuPedSim run as a .crowd cache.")],
        "sim" => vec![e("throng sim scene.toml --out crowd.crowd", "Simulate a steering scene into a cache.")],
        "cast" => vec![
            e("throng cast shot.toml", "Scheme, parts, materials and height of every agent."),
            e("throng cast shot.toml --json", "The same as JSON (docs/farm.md)."),
        ],
        "botinfo" => vec![
            e("throng botinfo shot.toml 17 42 --frame 1010", "Who agents 17 and 42 are at frame 1010."),
            e(
                "throng botinfo shot.toml --exr renders/crowd0/shot.crowd0.1010.exr --pixel 480,270 --json",
                "The agent at a pixel of a rendered layer, as JSON (agent null at the set or sky).",
            ),
        ],
        "layers" => vec![
            e("throng layers shot.toml --count 3 --map layers.png", "Three crowd layers, and a map of who is where."),
            e("throng layers shot.toml --budget 2.8GB", "As many layers as a render node's memory needs."),
        ],
        "render" => vec![
            e("throng render shot.toml --frames 1001-1010 --out renders", "Every layer of ten frames."),
            e(
                "throng render shot.toml --layer crowd0 --frames 1001 --spp 4 --passes diffuse_direct,P --out renders",
                "One layer of one frame, fast, with two extra passes.",
            ),
            e("throng render shot.toml --frames 1001-1100 --resume --out renders", "Render only what is not complete."),
        ],
        "comp" => vec![e(
            "throng comp renders --frame 1001 --out comp.1001.exr --png comp.1001.png",
            "Stack frame 1001's layers into one EXR, and a PNG preview.",
        )],
        "export" => vec![
            e("throng export shot.toml --frame 1001 --out crowd.glb", "One frame of the crowd as glTF."),
            e("throng export shot.toml --frames 1001-1048 --out crowd.usda", "A frame range as USD."),
        ],
        "review" => {
            vec![e("throng review shot.toml --renders renders", "A local page of the renders: click an agent.")]
        }
        "farm" | "farm plan" => vec![e(
            "throng farm plan shot.toml --frames 1001-1048 --chunk 4 --cores 8 --out /farm/shot",
            "Plan the shot as render and comp tasks into /farm/shot/plan.json.",
        )],
        "farm submit" => vec![
            e("throng farm submit /farm/shot/plan.json --engine slurm", "Submit what is not done to Slurm."),
            e("throng farm submit /farm/shot/plan.json --engine local --workers 2", "Run it here, two at a time."),
        ],
        "farm status" => vec![e(
            "until throng farm status /farm/shot/plan.json >/dev/null; do [ $? -eq 1 ] || exit 1; sleep 60; done",
            "Wait for the plan to finish; stop when a task failed (3) or on an error (2).",
        )],
        "completions" => {
            vec![e("throng completions bash > ~/.local/share/bash-completion/completions/throng", "Bash completion.")]
        }
        "man" => vec![e("throng man --out ~/.local/share/man/man1", "Write this page and one per verb.")],
        v => vec![e(&format!("throng {v} --help"), "The verb's options.")],
    }
}

/// A page's EXIT STATUS, by verb path.
fn exit_status(verb: &str) -> Vec<(u8, &'static str)> {
    let error = (2, "An error: bad input, a bad flag or a refused output; stderr names the file and key, or the flag. Under --strict a warning is one too.");
    match verb {
        "farm status" => vec![
            (0, "Every task is done (its outputs read back whole)."),
            (1, "Not finished: some task is waiting or running, none failed."),
            error,
            (3, "A task failed: read its log (named in the output), fix, submit again."),
        ],
        "botinfo" => vec![
            (0, "Every agent asked about was found; or, with --exr, the pixel shows no agent (said so, in JSON with --json)."),
            error,
        ],
        _ => vec![(0, "Success."), error],
    }
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
    // Not our `help` verbs either: clap adds its own to the copy, which completes verb names.
    for sub in cmd.get_subcommands().filter(|s| !s.is_hide_set() && s.get_name() != "help") {
        out = out.subcommand(without_hidden(sub));
    }
    out
}

/// Prints or writes the man pages.
pub fn man(args: &ManArgs) -> Result<()> {
    let cmd = super::Cli::command();
    match &args.out {
        None => {
            let mut cmd = cmd;
            cmd.build();
            let bytes = page_of(&cmd).map_err(|e| Error::Usage(format!("man page: {e}")))?;
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
