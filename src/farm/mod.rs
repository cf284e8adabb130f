//! The render farm: a shot's frames and layers as an engine-neutral task
//! graph (the plan, docs/farm.md), and the engines that execute it (`local`:
//! worker processes on this machine; `slurm`: sbatch job arrays).
//!
//! The plan is data: every task is a plain `throng` command line with its
//! expected outputs, resource needs and dependencies. Engines only decide
//! where and when those command lines run; whether a task is done is always
//! read back from its outputs (`status`), so a killed or resubmitted farm run
//! converges on the same files as a local render and comp.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{write_atomic, Error, IoContext, Result};
use crate::fingerprint::{hash_file, hex, Fingerprinter, ALGORITHM};

pub mod local;
pub(crate) mod plan;
pub(crate) mod run;
pub mod slurm;
pub(crate) mod status;

pub use plan::{write_new_plan, PlanOptions};
pub use run::run_task;
pub use status::{plan_status, TaskState, TaskStatus};

/// What a submit claims in the plan's state folder (no task has this id:
/// ids are `render.<layer>.<chunk>` and `comp.<frame>`).
pub(crate) const SUBMIT_CLAIM: &str = "submit";

/// `format` of a plan file.
pub(crate) const PLAN_FORMAT: &str = "throng-farm-plan";
/// The plan file version this throng reads and writes.
pub(crate) const PLAN_VERSION: u32 = 1;
/// The plan's file name inside its output directory.
pub(crate) const PLAN_FILE: &str = "plan.json";

/// What a task does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TaskKind {
    /// `throng render` of one layer over a chunk of frames.
    Render,
    /// `throng comp` of one frame.
    Comp,
}

/// One node of the task graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    /// `render.<layer>.<chunk>` or `comp.<frame>`; unique in the plan.
    pub id: String,
    /// Render or comp.
    pub kind: TaskKind,
    /// The layer rendered (render tasks).
    pub layer: Option<String>,
    /// Chunk index within the layer (render tasks): the Slurm array index.
    pub(crate) chunk: Option<usize>,
    /// Shot frames the task writes.
    pub frames: Vec<i32>,
    /// The command line; `argv[0]` is `throng`, which engines resolve to a binary.
    pub argv: Vec<String>,
    /// Files the task writes; the task is done when each reads back whole.
    pub outputs: Vec<PathBuf>,
    /// CPU cores to request (render tasks pass the same to `--threads`).
    pub cores: u32,
    /// Memory to request, bytes.
    pub memory_bytes: u64,
    /// Ids of the tasks that must be done first.
    pub depends_on: Vec<String>,
    /// The task's log file (stdout and stderr of every attempt, appended).
    pub log: PathBuf,
}

/// One input file covered by the fingerprint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FingerprintInput {
    /// `shot`, `cache`, `rig`, `wardrobe`, `set` or `manifest`.
    pub(crate) role: String,
    /// The file.
    pub(crate) path: PathBuf,
    /// Its size.
    pub(crate) bytes: u64,
    /// Its bytes' hash ([`crate::fingerprint`]), 16 hex digits.
    pub(crate) fnv1a64: String,
}

/// What the plan was made from, so a plan for an edited shot is refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fingerprint {
    /// Always `fnv1a64` ([`crate::fingerprint`]).
    pub(crate) algorithm: String,
    /// The hash of every input's role, path and hash, 16 hex digits.
    pub value: String,
    /// The inputs, in a fixed order.
    pub inputs: Vec<FingerprintInput>,
}

/// The task graph of a shot (docs/farm.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// [`PLAN_FORMAT`].
    pub(crate) format: String,
    /// [`PLAN_VERSION`].
    pub(crate) version: u32,
    /// Shot name.
    pub shot: String,
    /// The shot file (absolute).
    pub(crate) shot_file: PathBuf,
    /// The inputs' fingerprint.
    pub fingerprint: Fingerprint,
    /// The layer manifest, computed once at planning time.
    pub manifest: PathBuf,
    /// The plan's directory (absolute).
    pub(crate) out: PathBuf,
    /// Where render tasks write (`render/<layer>/...`) and comps go (`render/comp/...`).
    pub(crate) render_dir: PathBuf,
    /// Task logs.
    pub log_dir: PathBuf,
    /// Planned frames, in order.
    pub frames: Vec<i32>,
    /// Planned layers, back to front.
    pub layers: Vec<String>,
    /// Frames per render task.
    pub chunk: usize,
    /// Samples per pixel.
    pub(crate) spp: u32,
    /// Image size.
    pub(crate) resolution: [u32; 2],
    /// Extra attempts of a failed task before it counts as failed.
    pub(crate) retries: u32,
    /// The tasks: render tasks layer by layer, then comps frame by frame.
    pub tasks: Vec<Task>,
}

impl Plan {
    /// A task by id.
    pub fn task(&self, id: &str) -> Option<&Task> {
        self.tasks.iter().find(|t| t.id == id)
    }

    /// Engine bookkeeping (markers, submissions): `<out>/farm`.
    pub(crate) fn farm_dir(&self) -> PathBuf {
        self.out.join("farm")
    }

    /// Per-task state markers written by `farm run-task`.
    pub(crate) fn state_dir(&self) -> PathBuf {
        self.farm_dir().join("state")
    }

    /// Claims the plan for one submit ([`crate::output::WriterLock`] on
    /// [`SUBMIT_CLAIM`] in the state folder), held while the submit runs or
    /// submits its tasks: a second submit of the same plan meanwhile is
    /// refused up front, naming the first's process. The tasks' own claims
    /// (`run-task`: its task id in the same folder) name other files, so
    /// the submit's workers are not refused by it.
    pub(crate) fn claim_submit(&self) -> Result<crate::output::WriterLock> {
        crate::output::WriterLock::claim(&self.state_dir(), &[SUBMIT_CLAIM.to_string()], "").map_err(|e| match e {
            Error::Usage(m) => {
                Error::Usage(format!("the plan of shot {} is being submitted by another throng: {m}", self.shot))
            }
            e => e,
        })
    }

    /// Tasks by id.
    pub(crate) fn by_id(&self) -> BTreeMap<&str, &Task> {
        self.tasks.iter().map(|t| (t.id.as_str(), t)).collect()
    }
}

/// Fingerprints `inputs` (role, path): each file's content hash
/// ([`crate::fingerprint`], read in blocks), and one value over every
/// input's role, path and hash.
pub(crate) fn fingerprint(inputs: &[(String, PathBuf)]) -> Result<Fingerprint> {
    let mut files = Vec::with_capacity(inputs.len());
    let mut all = Fingerprinter::new();
    for (role, path) in inputs {
        let h = hash_file(path)?;
        let hash = hex(h.hash);
        all.text("role", role).bytes("path", path.as_os_str().as_encoded_bytes()).text("hash", &hash);
        files.push(FingerprintInput { role: role.clone(), path: path.clone(), bytes: h.bytes, fnv1a64: hash });
    }
    Ok(Fingerprint { algorithm: ALGORITHM.into(), value: all.hex(), inputs: files })
}

/// Writes a plan atomically (pretty JSON, a final newline).
pub(crate) fn write_plan(path: &Path, plan: &Plan) -> Result<()> {
    write_atomic(path, |w| {
        use std::io::Write;
        serde_json::to_writer_pretty(&mut *w, plan).map_err(|e| Error::io(path, e.into()))?;
        w.write_all(b"\n").at(path)
    })
}

/// Largest plan file read (a plan of a million tasks is far below it).
const MAX_PLAN_BYTES: u64 = 1 << 30;

/// Reads a plan, checking its format and version (not its fingerprint: see [`check_fingerprint`]).
pub fn read_plan(path: &Path) -> Result<Plan> {
    #[derive(Deserialize)]
    struct Head {
        format: Option<String>,
        version: Option<u32>,
    }
    let len = std::fs::metadata(path).at(path)?.len();
    if len > MAX_PLAN_BYTES {
        return Err(Error::invalid(path, format!("{len} bytes is too large for a farm plan")));
    }
    crate::error::check_readable_file(path)?;
    let text = std::fs::read_to_string(path).at(path)?;
    let json_err = |e: serde_json::Error| Error::invalid(path, e.to_string()).line(e.line());
    let head: Head = serde_json::from_str(&text).map_err(json_err)?;
    if head.format.as_deref() != Some(PLAN_FORMAT) {
        return Err(
            Error::invalid(path, format!("not a throng farm plan (`format` is not `{PLAN_FORMAT}`)")).field("format")
        );
    }
    if head.version != Some(PLAN_VERSION) {
        return Err(Error::invalid(
            path,
            format!(
                "unsupported farm plan version {} (this throng reads {PLAN_VERSION})",
                head.version.map_or("none".into(), |v| v.to_string())
            ),
        )
        .field("version"));
    }
    let plan: Plan = serde_json::from_str(&text).map_err(json_err)?;
    check_graph(path, &plan)?;
    Ok(plan)
}

/// A plan's graph must be closed (every dependency a task of the plan) and
/// every command line a `throng` one, so engines never run something else.
fn check_graph(path: &Path, plan: &Plan) -> Result<()> {
    let ids = plan.by_id();
    if ids.len() != plan.tasks.len() {
        return Err(Error::invalid(path, "two tasks share an id").field("tasks"));
    }
    for t in &plan.tasks {
        // Ids name log and marker files and go into Slurm's --wrap line.
        let safe = |w: &str| !w.starts_with('.') && w.bytes().all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b));
        if !safe(&t.id) || !t.layer.as_deref().is_none_or(safe) {
            return Err(Error::invalid(
                path,
                format!("task id or layer `{}` is not letters, digits, `.`, `_`, `-`", t.id),
            )
            .field("id"));
        }
        if t.argv.first().map(String::as_str) != Some("throng") {
            return Err(Error::invalid(path, format!("task `{}` does not run `throng`", t.id)).field("argv"));
        }
        if let Some(d) = t.depends_on.iter().find(|d| !ids.contains_key(d.as_str())) {
            return Err(
                Error::invalid(path, format!("task `{}` depends on unknown task `{d}`", t.id)).field("depends_on")
            );
        }
    }
    Ok(())
}

/// Refuses a plan whose inputs changed since planning (or that names
/// another shot than `shot`, when given), naming the file that changed.
pub(crate) fn check_fingerprint(plan_path: &Path, plan: &Plan, shot: Option<&Path>) -> Result<()> {
    if let Some(shot) = shot {
        let asked = std::fs::canonicalize(shot).at(shot)?;
        if asked != plan.shot_file {
            return Err(Error::invalid(
                plan_path,
                format!(
                    "this plan is for shot `{}` ({}), not {}",
                    plan.shot,
                    plan.shot_file.display(),
                    asked.display()
                ),
            )
            .field("shot_file"));
        }
    }
    for input in &plan.fingerprint.inputs {
        let now = hash_file(&input.path).map_err(|e| {
            Error::invalid(plan_path, format!("planned {} cannot be read now: {e}", input.role)).field("fingerprint")
        })?;
        let hash = hex(now.hash);
        if hash != input.fnv1a64 {
            return Err(Error::invalid(
                plan_path,
                format!(
                    "the {} {} changed since this plan was made (fingerprint {} != planned {}): plan the shot again into a new folder",
                    input.role,
                    input.path.display(),
                    hash,
                    input.fnv1a64
                ),
            )
            .field("fingerprint"));
        }
    }
    Ok(())
}

/// Reads a plan and checks its fingerprint: what every engine and `status` start with.
pub fn open_plan(path: &Path, shot: Option<&Path>) -> Result<Plan> {
    let plan = read_plan(path)?;
    check_fingerprint(path, &plan, shot)?;
    Ok(plan)
}

/// Whether every output of `task` exists and reads back whole (an EXR that
/// decodes completely, a deep EXR whole: [`crate::render::exr::deep::is_whole`]);
/// the one definition of "done" for every engine.
pub(crate) fn task_done(task: &Task) -> bool {
    use crate::render::exr;
    let whole = |p: &PathBuf| {
        if p.to_string_lossy().ends_with(".deep.exr") {
            exr::deep::is_whole(p)
        } else {
            exr::read_layer(p).is_ok()
        }
    };
    !task.outputs.is_empty() && task.outputs.iter().all(whole)
}

/// The tasks a (re)submission must run: every task not done, and every task
/// downstream of one that runs (a comp over a re-rendered layer is redone).
/// In plan order, which is a topological order.
pub(crate) fn tasks_to_run<'a>(plan: &'a Plan, done: &dyn Fn(&Task) -> bool) -> Vec<&'a Task> {
    let mut run: std::collections::BTreeSet<&str> = std::collections::BTreeSet::new();
    let mut out = Vec::new();
    for t in &plan.tasks {
        if !done(t) || t.depends_on.iter().any(|d| run.contains(d.as_str())) {
            run.insert(&t.id);
            out.push(t);
        }
    }
    out
}

/// Quotes a word for a POSIX shell.
pub(crate) fn shell_quote(word: &str) -> String {
    if !word.is_empty() && word.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_./=:,+@%".contains(&b)) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', r"'\''"))
    }
}
