//! The crate's error type. Every error that comes from user data names the
//! file and, where known, the line, frame, agent and field, so a lighter can
//! find the bad record without a debugger.

use std::fmt;
use std::path::{Path, PathBuf};

/// Result with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Where in a user file something went wrong.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Location {
    /// File the data came from.
    pub(crate) path: PathBuf,
    /// 1-based line (text formats).
    pub(crate) line: Option<usize>,
    /// Frame number (cache frame or shot frame, as the message says).
    pub(crate) frame: Option<i64>,
    /// Agent id.
    pub(crate) agent: Option<u32>,
    /// Field or key name.
    pub(crate) field: Option<String>,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        let mut parts = Vec::new();
        if let Some(fr) = self.frame {
            parts.push(format!("frame {fr}"));
        }
        if let Some(a) = self.agent {
            parts.push(format!("agent {a}"));
        }
        if let Some(k) = &self.field {
            parts.push(format!("field `{k}`"));
        }
        if !parts.is_empty() {
            write!(f, ": {}", parts.join(", "))?;
        }
        Ok(())
    }
}

/// Everything that can go wrong in throng.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A user file holds bad data.
    #[error("{at}: {msg}")]
    Invalid {
        /// Where.
        at: Box<Location>,
        /// What is wrong, in a lighter's words.
        msg: String,
    },
    /// The command line asks for something impossible.
    #[error("{0}")]
    Usage(String),
    /// A stage's option is out of range or conflicts with another. `option`
    /// is its name in the stage's options struct (`workers`); the command
    /// line words it as its flag (`--workers`), so no stage names a flag.
    #[error("{option}: {msg}")]
    Setting {
        /// The option's name, snake_case.
        option: &'static str,
        /// What is wrong with it.
        msg: String,
    },
}

impl Error {
    /// A bad-data error in `path`; add context with the builder methods.
    pub fn invalid(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::Invalid {
            at: Box::new(Location { path: path.as_ref().to_path_buf(), ..Default::default() }),
            msg: msg.into(),
        }
    }

    /// A TOML parse error in `path` (whose text is `text`): the line, and the
    /// key written on that line, since toml's messages for wrong types do
    /// not name it.
    pub(crate) fn toml(path: impl AsRef<Path>, text: &str, e: toml::de::Error) -> Self {
        let mut err = Error::invalid(path, e.message().to_string());
        if let Some(span) = e.span() {
            let line = line_of(text, span.start);
            err = err.line(line);
            let key = text.lines().nth(line - 1).and_then(|l| l.split_once('=')).map(|(k, _)| k.trim());
            if let Some(key) = key.filter(|k| !k.is_empty() && !k.starts_with('[')) {
                // Under the table it sits in (`rigs.walker.forward`), where
                // that is a plain `[table]`: an array's `[[table]]` has no index here.
                let table = text.lines().take(line - 1).map(str::trim).filter(|l| l.starts_with('[')).last();
                let table = table.filter(|t| !t.starts_with("[[")).and_then(|t| t.strip_prefix('[')?.split(']').next());
                err = err.field(match table.map(str::trim) {
                    Some(t) if !t.is_empty() => format!("{t}.{}", key.trim_matches('"')),
                    _ => key.trim_matches('"').to_string(),
                });
            }
        }
        err
    }

    /// A bad value for the stage option `option` (see [`Error::Setting`]).
    pub(crate) fn setting(option: &'static str, msg: impl Into<String>) -> Self {
        Error::Setting { option, msg: msg.into() }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io { path: path.as_ref().to_path_buf(), source }
    }

    fn with(mut self, f: impl FnOnce(&mut Location)) -> Self {
        if let Error::Invalid { at, .. } = &mut self {
            f(at);
        }
        self
    }

    /// Adds the 1-based line number.
    pub(crate) fn line(self, line: usize) -> Self {
        self.with(|l| l.line = Some(line))
    }
    /// Adds the frame.
    pub(crate) fn frame(self, frame: i64) -> Self {
        self.with(|l| l.frame = Some(frame))
    }
    /// Adds the agent id.
    pub(crate) fn agent(self, agent: u32) -> Self {
        self.with(|l| l.agent = Some(agent))
    }
    /// Adds the field or key.
    pub fn field(self, field: impl Into<String>) -> Self {
        let field = field.into();
        self.with(|l| l.field = Some(field))
    }
    /// Names the field or key when the error does not name one yet: the
    /// key of the file that led here (`rigs.walker.file` for a rig's glTF).
    pub(crate) fn or_field(self, field: impl Into<String>) -> Self {
        let field = field.into();
        self.with(|l| {
            l.field.get_or_insert(field);
        })
    }
    /// Qualifies the field, if any, with the key path it sits under (`rigs.walker`).
    pub(crate) fn field_prefix(self, prefix: &str) -> Self {
        self.with(|l| {
            if let Some(f) = &l.field {
                l.field = Some(format!("{prefix}.{f}"));
            }
        })
    }
}

/// The 1-based line of a byte offset in `text`.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// Adds the path to `std::io::Result`s.
pub trait IoContext<T> {
    /// Maps an I/O error to [`Error::Io`] naming `path`.
    fn at(self, path: impl AsRef<Path>) -> Result<T>;
}

impl<T> IoContext<T> for std::io::Result<T> {
    fn at(self, path: impl AsRef<Path>) -> Result<T> {
        self.map_err(|e| Error::io(path, e))
    }
}

/// Writes a file atomically: `write` fills a temporary file beside `path`,
/// which is renamed over `path` only when complete, so no reader ever sees a
/// partial file under the final name (even after kill -9).
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> Result<()>,
) -> Result<()> {
    use std::io::Write;
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).at(dir)?;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| {
        let file = std::fs::File::create(&tmp).at(&tmp)?;
        let mut w = std::io::BufWriter::new(file);
        write(&mut w)?;
        w.flush().at(&tmp)?;
        w.get_ref().sync_all().at(&tmp)?;
        Ok(())
    })();
    match result {
        // A failed rename (the output is a folder) leaves no temporary either.
        Ok(()) => std::fs::rename(&tmp, path).at(path).inspect_err(|_| {
            let _ = std::fs::remove_file(&tmp);
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// A file's (device, inode): the same for every name of one file (hard
/// links, symlinks followed). `None` when it does not exist.
pub(crate) fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

/// Whether two paths name one file (hard links and symlinks too); paths
/// that do not exist are one file when they are spelled the same.
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
    match (file_id(a), file_id(b)) {
        (Some(a), Some(b)) => a == b,
        _ => a == b,
    }
}

/// Refuses an input path that is a FIFO, a device or a socket, before it
/// is opened: reading one would block forever (a FIFO with no writer) or
/// never end (`/dev/zero`). A folder is refused too: readers such as SQLite
/// would call it a "disk I/O error". Regular files and missing paths pass
/// (the reader says what is wrong with a missing one). Symlinks are followed.
pub fn check_readable_file(path: &Path) -> Result<()> {
    use std::os::unix::fs::FileTypeExt;
    let Ok(meta) = std::fs::metadata(path) else { return Ok(()) };
    let t = meta.file_type();
    let kind = if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO (named pipe)"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        return Ok(());
    };
    Err(Error::invalid(path, format!("is {kind}, not a file: throng reads inputs from regular files only")))
}
