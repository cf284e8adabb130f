//! `farm status`: each task done, running, failed or waiting. Done comes
//! from the outputs alone (each EXR reads back whole); the rest from the
//! scheduler where it can be asked, else from the markers `run-task` leaves.

use std::path::PathBuf;

use serde::Serialize;

use super::run::{host_name, marker, read_marker, Exited, Started};
use super::{slurm, task_done, Plan};

/// A task's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TaskState {
    /// Every output reads back whole.
    Done,
    /// Started and not finished.
    Running,
    /// Ended without its outputs (after its retries), or cancelled.
    Failed,
    /// Not started: queued, held by a dependency, or never submitted.
    Waiting,
}

impl TaskState {
    /// The word `status` prints.
    pub fn word(self) -> &'static str {
        match self {
            TaskState::Done => "done",
            TaskState::Running => "running",
            TaskState::Failed => "failed",
            TaskState::Waiting => "waiting",
        }
    }
}

/// One task's status.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskStatus {
    /// Task id.
    pub id: String,
    /// State.
    pub state: TaskState,
    /// Why, in a wrangler's words (scheduler state, exit status).
    pub detail: String,
    /// Scheduler job id, when submitted to one.
    pub(crate) job: Option<String>,
    /// The task's log.
    pub log: PathBuf,
}

/// Status of every task, and a note on the scheduler (reached or why not).
pub fn plan_status(plan: &Plan) -> (Vec<TaskStatus>, Option<String>) {
    let (jobs, note) = match slurm::query(plan) {
        Ok(None) => (None, None),
        Ok(Some(j)) => (Some(j), Some("slurm: asked squeue".to_string())),
        Err(why) => (None, Some(format!("slurm: cannot ask the scheduler ({why}); states from task markers"))),
    };
    let here = host_name();
    let statuses = plan
        .tasks
        .iter()
        .map(|t| {
            let job = jobs.as_ref().and_then(|j| j.get(&t.id));
            let status = |state, detail: String| TaskStatus {
                id: t.id.clone(),
                state,
                detail,
                job: job.map(|j| j.id.clone()),
                log: t.log.clone(),
            };
            if task_done(t) {
                return status(TaskState::Done, "outputs read back whole".into());
            }
            if let Some(j) = job.filter(|j| !j.state.is_empty()) {
                let s = j.state.as_str();
                let state = match s {
                    "PENDING" | "CONFIGURING" | "REQUEUED" | "REQUEUE_HOLD" | "SUSPENDED" => TaskState::Waiting,
                    "RUNNING" | "COMPLETING" => TaskState::Running,
                    _ => TaskState::Failed,
                };
                let why = if s == "COMPLETED" { " but its outputs do not read back whole" } else { "" };
                return status(state, format!("slurm job {} {s}{why}", j.id));
            }
            let exited: Option<Exited> = read_marker(&marker(plan, &t.id, "exit"));
            let started: Option<Started> = read_marker(&marker(plan, &t.id, "started"));
            match (exited, started) {
                (Some(e), _) => status(
                    TaskState::Failed,
                    format!("last run ended with exit status {} after {} attempt(s)", e.status, e.attempts),
                ),
                (None, Some(s)) if s.host == here && !std::path::Path::new(&format!("/proc/{}", s.pid)).exists() => {
                    status(
                        TaskState::Failed,
                        format!("run-task process {} on {} stopped without finishing", s.pid, s.host),
                    )
                }
                (None, Some(s)) => status(TaskState::Running, format!("started by process {} on {}", s.pid, s.host)),
                (None, None) => status(TaskState::Waiting, "not started".into()),
            }
        })
        .collect();
    (statuses, note)
}
