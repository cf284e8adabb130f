//! Names of rendered files and layers, shared by render (which writes them)
//! and comp (which finds and stacks them), so the two can never disagree.

use std::path::{Path, PathBuf};

use crate::error::{file_id, Error, Result};

/// The render that needs no manifest: the set and every agent, fully visible.
pub const FULL_LAYER: &str = "full";
/// The layer name `throng comp` writes into its EXR header.
pub(crate) const COMP_LAYER: &str = "comp";
/// The set layer.
pub(crate) const SET_LAYER: &str = "set";

/// `crowdN`: the name of crowd layer `index` (0 nearest the camera).
pub(crate) fn crowd_layer_name(index: usize) -> String {
    format!("crowd{index}")
}

/// Crowd layer index of a `crowdN` name.
pub(crate) fn crowd_layer_index(name: &str) -> Option<usize> {
    name.strip_prefix("crowd")?.parse().ok()
}

/// `OUT/<layer>/<shot>.<layer>.<frame:04>.exr`.
pub fn layer_path(out: &Path, shot: &str, layer: &str, frame: i32) -> PathBuf {
    out.join(layer).join(format!("{shot}.{layer}.{frame:04}.exr"))
}

/// The inputs a verb reads, each as the shot (or the verb) names it
/// (`cache.path`, `rigs.walker.file`, `layer crowd0`) with its path, so an
/// output that is one of them can be refused before it is written.
#[derive(Debug, Clone, Default)]
pub struct InputFiles {
    files: Vec<Input>,
}

/// One input: what it is, its path, its (device, inode) when it exists,
/// its canonical path.
#[derive(Debug, Clone)]
struct Input {
    what: String,
    path: PathBuf,
    id: Option<(u64, u64)>,
    canonical: Option<PathBuf>,
}

/// What makes two output paths one file: its (device, inode) when it
/// exists, its canonical path.
#[derive(Debug, PartialEq, Eq, Hash)]
enum OutputKey {
    Id((u64, u64)),
    Path(PathBuf),
}

/// A path that may not exist yet, made absolute through its existing
/// folder (symlinked folders resolved), so two spellings of one path compare equal.
fn canonical(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Some(p);
    }
    let name = path.file_name()?;
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    Some(std::fs::canonicalize(dir).ok()?.join(name))
}

impl InputFiles {
    /// The inputs `files` ((what, path)); each is looked up once.
    pub fn new(files: impl IntoIterator<Item = (String, PathBuf)>) -> InputFiles {
        let mut out = InputFiles::default();
        out.extend(files);
        out
    }

    /// Adds more inputs.
    pub fn extend(&mut self, files: impl IntoIterator<Item = (String, PathBuf)>) {
        for (what, path) in files {
            let (id, canonical) = (file_id(&path), canonical(&path));
            self.files.push(Input { what, path, id, canonical });
        }
    }

    /// Refuses `output` when it is the same file as one of the inputs: by
    /// (device, inode) when it exists (so a symlink or a hard link to an
    /// input is caught), else by its canonical path. The error names both.
    pub fn check(&self, output: &Path) -> Result<()> {
        let id = file_id(output);
        let canon = if id.is_none() { canonical(output) } else { None };
        let same = self.files.iter().find(|i| match (id, i.id) {
            (Some(id), Some(i)) => id == i,
            _ => canon.is_some() && canon == i.canonical,
        });
        match same {
            Some(Input { what, path, .. }) => Err(Error::Usage(format!(
                "refusing to write {}: it is the same file as the {what} {}, which this command reads \
                 (write the output elsewhere)",
                output.display(),
                path.display()
            ))),
            None => Ok(()),
        }
    }

    /// Refuses the first of `outputs` that is one of the inputs, and an
    /// output that is the same file as an earlier one (`--out m.json --map
    /// m.json`: the second write would replace the first).
    pub fn check_all<'a>(&self, outputs: impl IntoIterator<Item = &'a Path>) -> Result<()> {
        let mut seen: std::collections::HashMap<OutputKey, &Path> = std::collections::HashMap::new();
        for o in outputs {
            self.check(o)?;
            let keys = [file_id(o).map(OutputKey::Id), canonical(o).map(OutputKey::Path)];
            if let Some(first) = keys.iter().flatten().find_map(|k| seen.get(k)) {
                return Err(Error::Usage(format!(
                    "refusing to write {} twice: it is the same file as {}, which this command also writes \
                     (give each output its own name)",
                    o.display(),
                    first.display()
                )));
            }
            for k in keys.into_iter().flatten() {
                seen.insert(k, o);
            }
        }
        Ok(())
    }
}

/// Refuses (naming both) any of `outputs` that is the same file as any of
/// `inputs` ((what, path)), through symlinks and hard links: no verb ever
/// writes over a file it reads.
pub fn refuse_input_overwrite<'a>(
    outputs: impl IntoIterator<Item = &'a Path>,
    inputs: impl IntoIterator<Item = (String, PathBuf)>,
) -> Result<()> {
    InputFiles::new(inputs).check_all(outputs)
}

/// The file in an output folder that records who is writing into it
/// ([`WriterLock`]).
pub const WRITERS_FILE: &str = ".throng-writers";

/// One process writing into a folder, as [`WRITERS_FILE`] records it (one
/// JSON object a line).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
struct Writer {
    /// Process id.
    pid: u32,
    /// The process's start time (clock ticks since boot, /proc), so a
    /// reused pid is not taken for the writer.
    start: u64,
    /// Host name.
    host: String,
    /// What it writes with (a layer's render fingerprint; empty: not compared).
    settings: String,
    /// The file names it writes in the folder.
    targets: Vec<String>,
}

/// Start time of process `pid` (field 22 of /proc/PID/stat); `None` when
/// there is no such process (or no /proc), or when it has ended and only
/// its entry is left: a zombie (state `Z`) that its parent has not reaped,
/// as a process killed under a farm job or in a container whose PID 1
/// never reaps stays, writes nothing more, so its claims are void.
fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces.
    let mut rest = stat[stat.rfind(')')? + 1..].split_whitespace();
    let state = rest.next()?;
    if matches!(state, "Z" | "X" | "x") {
        return None;
    }
    rest.nth(18)?.parse().ok()
}

/// Whether process `pid` is alive on this host: it exists and has not
/// ended (a zombie has); no /proc: assumed alive.
pub(crate) fn process_alive(pid: u32) -> bool {
    !Path::new("/proc/self").exists() || process_start(pid).is_some()
}

/// This machine's host name (the kernel's, no `hostname` binary needed).
pub(crate) fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname").map(|h| h.trim().to_string()).unwrap_or_default()
}

impl Writer {
    fn me(settings: &str, targets: &[String]) -> Writer {
        let pid = std::process::id();
        Writer {
            pid,
            start: process_start(pid).unwrap_or(0),
            host: host_name(),
            settings: settings.to_string(),
            targets: targets.to_vec(),
        }
    }

    /// Whether the process is still running: on this host, the same pid
    /// with the same start time; on another host it cannot be asked, so yes.
    fn alive(&self, host: &str) -> bool {
        if self.host != host || !Path::new("/proc/self").exists() {
            return true;
        }
        process_start(self.pid).is_some_and(|s| s == self.start || self.start == 0)
    }
}

/// The claim of one process on an output folder: while it is held, no other
/// throng process writes the same files there, or writes there with other
/// settings. Taken by `render` (each layer folder), `comp` and `export`
/// (the output's folder), a farm task (its state folder, by task id) and a farm
/// submit (the same folder, as `submit`); released when
/// dropped. A process killed without releasing leaves its line in
/// [`WRITERS_FILE`], which the next claim drops once that process is gone.
///
/// The record is guarded by an advisory lock ([`std::fs::File::lock`]) held
/// only while it is read and rewritten, so writers of disjoint frames with
/// the same settings (a farm's chunks of one layer) run side by side.
#[derive(Debug)]
pub struct WriterLock {
    file: PathBuf,
    me: Writer,
    /// Process ids of the other live writers when the claim was taken.
    others: Vec<u32>,
}

/// The writers recorded in `text`; a line that does not read is dropped.
fn parse_writers(text: &str) -> Vec<Writer> {
    text.lines().filter_map(|l| serde_json::from_str(l).ok()).collect()
}

/// Opens the record of `dir` and locks it, and gives the writers it lists.
/// The last writer to leave removes the file (holding the lock), so a
/// process that opened it meanwhile finds, once it has the lock, that its
/// file is no longer the one at `file`, and opens that one again.
fn open_writers(file: &Path) -> Result<(std::fs::File, Vec<Writer>)> {
    use std::io::Read;
    use std::os::unix::fs::MetadataExt;
    let mut f = loop {
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(file)
            .map_err(|e| Error::io(file, e))?;
        f.lock().map_err(|e| Error::io(file, e))?;
        let held = f.metadata().map_err(|e| Error::io(file, e))?;
        if file_id(file) == Some((held.dev(), held.ino())) {
            break f;
        }
    };
    let mut text = String::new();
    // A record that is not text is as good as empty: it lists no one.
    let _ = f.read_to_string(&mut text);
    Ok((f, parse_writers(&text)))
}

/// Rewrites the locked record `f` with `writers`.
fn write_writers(f: &mut std::fs::File, file: &Path, writers: &[Writer]) -> Result<()> {
    use std::io::{Seek, Write};
    let mut text = String::new();
    for w in writers {
        text.push_str(&serde_json::to_string(w).unwrap_or_default());
        text.push('\n');
    }
    f.set_len(0).and_then(|()| f.rewind()).and_then(|()| f.write_all(text.as_bytes())).map_err(|e| Error::io(file, e))
}

impl WriterLock {
    /// Claims `targets` (file names) in `dir` (created if missing), written
    /// with `settings`. Refused, naming the process, when another live
    /// throng process writes one of the same files there, or writes there
    /// with other (non-empty) settings.
    pub fn claim(dir: &Path, targets: &[String], settings: &str) -> Result<WriterLock> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let file = dir.join(WRITERS_FILE);
        let (mut f, writers) = open_writers(&file)?;
        let me = Writer::me(settings, targets);
        let live: Vec<Writer> =
            writers.into_iter().filter(|w| w.alive(&me.host) && !(w.pid == me.pid && w.host == me.host)).collect();
        for w in &live {
            let shared = w.targets.iter().find(|t| targets.contains(t));
            let why = match shared {
                Some(t) => format!("it writes {t} too"),
                None if !w.settings.is_empty() && !settings.is_empty() && w.settings != settings => {
                    format!("with other settings (fingerprint {}, this run's {settings})", w.settings)
                }
                None => continue,
            };
            return Err(Error::Usage(format!(
                "{} is being written by throng process {} on {} ({why}): wait for it to end, or, if that process \
                 is gone, remove {}",
                dir.display(),
                w.pid,
                if w.host.is_empty() { "this host" } else { &w.host },
                file.display()
            )));
        }
        let mut keep = live.clone();
        keep.push(me.clone());
        write_writers(&mut f, &file, &keep)?;
        Ok(WriterLock { file, me, others: live.iter().map(|w| w.pid).collect() })
    }

    /// Claims the files `outputs` in their folders (one claim per folder),
    /// with no settings compared: what `comp` and `export` take.
    pub fn claim_files<'a>(outputs: impl IntoIterator<Item = &'a Path>) -> Result<Vec<WriterLock>> {
        let mut by_dir: std::collections::BTreeMap<PathBuf, Vec<String>> = std::collections::BTreeMap::new();
        for o in outputs {
            let dir = o.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
            let name = o.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            by_dir.entry(dir.to_path_buf()).or_default().push(name);
        }
        by_dir.iter().map(|(dir, names)| WriterLock::claim(dir, names, "")).collect()
    }

    /// Whether a temporary named for process `pid` may belong to a live
    /// writer of the folder (another claimant, or a process alive on this host).
    pub fn may_be_writing(&self, pid: u32) -> bool {
        pid == self.me.pid || self.others.contains(&pid) || process_alive(pid)
    }
}

impl Drop for WriterLock {
    fn drop(&mut self) {
        let Ok((mut f, writers)) = open_writers(&self.file) else { return };
        let rest: Vec<Writer> = writers.into_iter().filter(|w| *w != self.me && w.alive(&self.me.host)).collect();
        if rest.is_empty() {
            // The last writer leaves no file behind (see `open_writers`).
            let _ = std::fs::remove_file(&self.file);
        } else {
            let _ = write_writers(&mut f, &self.file, &rest);
        }
    }
}

/// The frame of a layer file named as [`layer_path`] names it
/// (`<shot>.<layer>.<frame:04>.exr`), `None` for any other name.
pub(crate) fn layer_file_frame(file_name: &str, shot: &str, layer: &str) -> Option<i32> {
    let digits = file_name.strip_prefix(shot)?.strip_prefix('.')?.strip_prefix(layer)?.strip_prefix('.')?;
    let digits = digits.strip_suffix(".exr")?;
    if digits.len() < 4 || !digits.bytes().all(|b| b.is_ascii_digit() || b == b'-') {
        return None;
    }
    let frame: i32 = digits.parse().ok()?;
    // Only the spelling layer_path gives (so each frame has one file).
    (format!("{frame:04}") == digits).then_some(frame)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_killed_writer_its_parent_has_not_reaped_holds_no_claim() {
        // A child killed and not waited for stays a zombie: /proc/PID is
        // still there, but it writes nothing more.
        let mut child = std::process::Command::new("sleep").arg("30").spawn().expect("spawn sleep");
        let pid = child.id();
        let dir = std::env::temp_dir().join(format!("throng-zombie-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let live = Writer {
            pid,
            start: process_start(pid).expect("the child runs"),
            host: host_name(),
            settings: "other".into(),
            targets: vec!["a.exr".into()],
        };
        std::fs::write(dir.join(WRITERS_FILE), format!("{}\n", serde_json::to_string(&live).unwrap())).unwrap();
        assert!(process_alive(pid));
        let refused = WriterLock::claim(&dir, &["a.exr".to_string()], "mine").unwrap_err().to_string();
        assert!(refused.contains(&pid.to_string()), "{refused}");
        child.kill().unwrap();
        // SIGKILL is delivered asynchronously: wait (bounded) for the zombie state.
        let zombie = (0..200).any(|_| {
            std::thread::sleep(std::time::Duration::from_millis(10));
            std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| s.contains(") Z "))
        });
        assert!(zombie, "the killed child never showed as a zombie");
        assert!(Path::new(&format!("/proc/{pid}")).exists(), "a zombie keeps its /proc entry");
        assert!(!process_alive(pid));
        let claim = WriterLock::claim(&dir, &["a.exr".to_string()], "mine");
        assert!(claim.is_ok(), "a zombie's claim still refused a writer: {:?}", claim.err());
        drop(claim);
        child.wait().unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
