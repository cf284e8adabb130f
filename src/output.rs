//! Names of rendered files and layers, shared by render (which writes them)
//! and comp (which finds and stacks them), so the two can never disagree.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

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

/// A file's (device, inode): the same for every name of one file (hard
/// links, symlinks followed). `None` when it does not exist.
fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
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

    /// Refuses the first of `outputs` that is one of the inputs.
    pub fn check_all<'a>(&self, outputs: impl IntoIterator<Item = &'a Path>) -> Result<()> {
        outputs.into_iter().try_for_each(|o| self.check(o))
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
