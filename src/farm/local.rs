//! The local engine: the plan's graph on this machine, with N worker
//! processes (`throng farm run-task PLAN TASK`, each task's output appended
//! to its log), starting a task only when its dependencies are done.
//! It is the farm path without a farm, so it is testable everywhere.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde::Serialize;

use super::{task_done, tasks_to_run, Plan, Task};
use crate::error::{Error, IoContext, Result};

/// What a local run did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LocalReport {
    /// Tasks run to completion, in the order they finished.
    pub ran: Vec<String>,
    /// Tasks already done, not run.
    pub skipped: usize,
    /// Tasks that failed (after their retries), with their logs.
    pub failed: Vec<(String, String)>,
    /// Tasks not run because a dependency failed.
    pub blocked: Vec<String>,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// Most workers a local run starts.
pub(crate) const MAX_WORKERS: usize = 256;

/// Runs every task not done with `workers` processes of `exe`; `say`
/// receives one line per task started and finished (flushed by the caller).
pub fn run_local(plan: &Plan, plan_path: &Path, exe: &Path, workers: usize, say: &dyn Fn(&str)) -> Result<LocalReport> {
    if workers == 0 || workers > MAX_WORKERS {
        return Err(Error::setting("workers", format!("must be 1 to {MAX_WORKERS}")));
    }
    // One submit of the plan at a time (held until the last task ends).
    let _claim = plan.claim_submit()?;
    let clock = Instant::now();
    let todo: Vec<&Task> = tasks_to_run(plan, &task_done);
    let mut report = LocalReport { skipped: plan.tasks.len() - todo.len(), ..Default::default() };
    let pending_ids: BTreeSet<&str> = todo.iter().map(|t| t.id.as_str()).collect();
    let mut waiting: Vec<&Task> = todo;
    let mut finished: BTreeSet<&str> = BTreeSet::new();
    let mut failed: BTreeSet<&str> = BTreeSet::new();
    let mut running: BTreeMap<&str, (Child, Instant)> = BTreeMap::new();
    std::fs::create_dir_all(&plan.log_dir).at(&plan.log_dir)?;
    loop {
        let mut i = 0;
        while i < waiting.len() {
            let t = waiting[i];
            // A dependency outside this run is done already (tasks_to_run).
            let ready = t.depends_on.iter().all(|d| !pending_ids.contains(d.as_str()) || finished.contains(d.as_str()));
            let blocked = t.depends_on.iter().any(|d| failed.contains(d.as_str()) || report.blocked.contains(d));
            if blocked {
                report.blocked.push(t.id.clone());
                say(&format!("local: {} blocked (a dependency failed)", t.id));
                waiting.remove(i);
            } else if running.len() < workers && ready {
                let log = std::fs::OpenOptions::new().create(true).append(true).open(&t.log).at(&t.log)?;
                let err = log.try_clone().at(&t.log)?;
                let child = Command::new(exe)
                    .args(["farm", "run-task"])
                    .arg(plan_path)
                    .arg(&t.id)
                    .stdin(Stdio::null())
                    .stdout(log)
                    .stderr(err)
                    .spawn()
                    .at(exe)?;
                say(&format!("local: {} started (log {})", t.id, t.log.display()));
                running.insert(&t.id, (child, Instant::now()));
                waiting.remove(i);
            } else {
                i += 1;
            }
        }
        if running.is_empty() {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
        let mut ended = Vec::new();
        for (id, (child, started)) in running.iter_mut() {
            if let Some(status) = child.try_wait().at(exe)? {
                ended.push((*id, status.success(), started.elapsed().as_secs_f64()));
            }
        }
        for (id, ok, secs) in ended {
            running.remove(id);
            let log = plan.task(id).map(|t| t.log.display().to_string()).unwrap_or_default();
            if ok {
                finished.insert(id);
                report.ran.push(id.to_string());
                say(&format!("local: {id} done in {secs:.1} s"));
            } else {
                failed.insert(id);
                say(&format!("local: {id} FAILED; log {log}"));
                report.failed.push((id.to_string(), log));
            }
        }
    }
    report.seconds = clock.elapsed().as_secs_f64();
    Ok(report)
}
