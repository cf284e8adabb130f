//! `farm run-task`: what an engine runs for one task. It runs the task's
//! `throng` command line, retrying up to the plan's `retries`, and leaves
//! state markers (`<out>/farm/state/<task>.started|.exit`) that `status`
//! reads when no scheduler can be asked.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde::{Deserialize, Serialize};

use super::{task_done, Plan, Task};
use crate::error::{write_atomic, Error, IoContext, Result};

/// `<task>.started`: who runs the task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Started {
    /// Host name.
    pub(crate) host: String,
    /// Process id of `farm run-task`.
    pub(crate) pid: u32,
}

/// `<task>.exit`: how the last run ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Exited {
    /// Exit status of the last attempt (-1: killed by a signal; 0 and
    /// outputs whole: done).
    pub(crate) status: i32,
    /// Attempts made.
    pub(crate) attempts: u32,
}

/// The marker files of a task.
pub(crate) fn marker(plan: &Plan, task: &str, what: &str) -> PathBuf {
    plan.state_dir().join(format!("{task}.{what}"))
}

pub(crate) use crate::output::host_name;

fn write_json(path: &Path, v: &impl Serialize) -> Result<()> {
    write_atomic(path, |w| serde_json::to_writer(&mut *w, v).map_err(|e| Error::io(path, e.into())))
}

/// Reads a marker; `None` when absent or unreadable (a marker is a hint, outputs decide).
pub(crate) fn read_marker<T: for<'de> Deserialize<'de>>(path: &Path) -> Option<T> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// Runs task `id` of `plan` with the `throng` binary `exe`; the task's own
/// output goes to this process's stdout and stderr (the engine points them
/// at the log), and each attempt and outcome is told to `log`.
pub fn run_task(plan: &Plan, id: &str, exe: &Path, log: &mut dyn FnMut(&str)) -> Result<()> {
    let task: &Task = plan.task(id).ok_or_else(|| {
        Error::Usage(format!(
            "no task `{id}` in the plan of shot {} (tasks: {}...)",
            plan.shot,
            plan.tasks.iter().take(3).map(|t| t.id.as_str()).collect::<Vec<_>>().join(", ")
        ))
    })?;
    let state = plan.state_dir();
    std::fs::create_dir_all(&state).at(&state)?;
    // One worker per task: a second run of the same task is refused while this one runs.
    let _claim = crate::output::WriterLock::claim(&state, &[id.to_string()], "")?;
    let exit_path = marker(plan, id, "exit");
    let _ = std::fs::remove_file(&exit_path);
    write_json(&marker(plan, id, "started"), &Started { host: host_name(), pid: std::process::id() })?;
    let attempts = plan.retries.saturating_add(1);
    let mut status = -1;
    for attempt in 1..=attempts {
        log(&format!("task {id} attempt {attempt} of {attempts}: {}", shell_line(&task.argv)));
        let run = Command::new(exe).args(&task.argv[1..]).status().at(exe)?;
        status = run.code().unwrap_or(-1);
        if run.success() && task_done(task) {
            log(&format!("task {id} done"));
            return write_json(&exit_path, &Exited { status: 0, attempts: attempt });
        }
        if run.success() {
            // Exit 0 with an output that does not read back: count it failed.
            status = 1;
            log(&format!("task {id} exited 0 but its outputs do not read back whole"));
        } else {
            log(&format!("task {id} attempt {attempt} failed with exit status {status}"));
        }
    }
    write_json(&exit_path, &Exited { status, attempts })?;
    Err(Error::Usage(format!(
        "task {id} failed after {attempts} attempt(s) (last exit status {status}); log {}",
        task.log.display()
    )))
}

fn shell_line(argv: &[String]) -> String {
    argv.iter().map(|a| super::shell_quote(a)).collect::<Vec<_>>().join(" ")
}
