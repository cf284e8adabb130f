//! The Slurm engine: one sbatch job array per layer (array index = the
//! render task's chunk), one job per comp with `afterok` dependencies on the
//! array elements that write its frame. Every job runs `throng farm
//! run-task PLAN TASK`, which retries and leaves markers; Slurm writes the
//! job's output to the task's log (appended across resubmissions).
//! Job ids are kept in `<out>/farm/slurm.json` for `status`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde::{Deserialize, Serialize};

use super::{shell_quote, task_done, tasks_to_run, Plan, Task, TaskKind};
use crate::error::{write_atomic, Error, IoContext, Result};

/// `<out>/farm/slurm.json`: the job id of every submitted task.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct Submission {
    /// Always `slurm`.
    pub(crate) engine: String,
    /// Task id -> Slurm job id (`123` or `123_4` for an array element).
    pub(crate) jobs: BTreeMap<String, String>,
}

/// A task's job as the scheduler sees it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct JobState {
    /// Slurm job id.
    pub(crate) id: String,
    /// squeue's state (`PENDING`, `RUNNING`, `COMPLETED`, `FAILED`,
    /// `CANCELLED`, ...), empty when squeue no longer lists the job.
    pub(crate) state: String,
}

/// What one submission did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SubmitReport {
    /// (what, job id): `render.crowd0 array 0-2`, `comp.1001`.
    pub submitted: Vec<(String, String)>,
    /// Tasks already done, not submitted.
    pub done: usize,
    /// Tasks still queued or running from an earlier submission, not submitted again.
    pub queued: Vec<String>,
}

fn submission_path(plan: &Plan) -> PathBuf {
    plan.farm_dir().join("slurm.json")
}

fn read_submission(plan: &Plan) -> Option<Submission> {
    super::run::read_marker(&submission_path(plan))
}

/// A missing binary or a refusal, as one clear message.
fn slurm_command(name: &str, args: &[String]) -> Result<String> {
    let out = Command::new(name).args(args).output().map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            Error::Usage(format!(
                "`{name}` is not on PATH: the slurm engine needs Slurm's client commands (Debian: apt-get install slurm-client), or use the local engine"
            ))
        } else {
            Error::Usage(format!("cannot run `{name}`: {e}"))
        }
    })?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr).trim().to_string();
        return Err(Error::Usage(format!("{name} refused ({}): {err}", out.status)));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Asks squeue about the plan's submitted jobs: `Ok(None)` when the plan
/// was never submitted to Slurm, `Err(reason)` when squeue cannot answer.
pub(crate) fn query(plan: &Plan) -> std::result::Result<Option<BTreeMap<String, JobState>>, String> {
    let Some(sub) = read_submission(plan) else { return Ok(None) };
    let mut base: Vec<&str> = sub.jobs.values().map(|j| j.split('_').next().unwrap_or(j)).collect();
    base.sort_unstable();
    base.dedup();
    let args = ["-h", "-r", "-t", "all", "-o", "%i|%T", "-j", &base.join(",")].map(String::from);
    // squeue errors on ids it has forgotten (older than MinJobAge); then
    // only the markers remain, which is what Err says.
    let text = slurm_command("squeue", &args).map_err(|e| e.to_string())?;
    let states: BTreeMap<&str, &str> = text.lines().filter_map(|l| l.trim().split_once('|')).collect();
    Ok(Some(
        sub.jobs
            .iter()
            .map(|(task, job)| {
                let state = states.get(job.as_str()).copied().unwrap_or_default().to_string();
                (task.clone(), JobState { id: job.clone(), state })
            })
            .collect(),
    ))
}

/// What an array element or job runs: `throng farm run-task PLAN TASK`.
fn wrap(exe: &Path, plan_path: &Path, task: &str) -> String {
    format!(
        "exec {} farm run-task {} {task}",
        shell_quote(&exe.display().to_string()),
        shell_quote(&plan_path.display().to_string())
    )
}

/// Whole MB for `--mem` (Slurm's M is MiB).
fn mem_mb(bytes: u64) -> u64 {
    bytes.div_ceil(1 << 20).max(1)
}

/// Submits what is not done; prints nothing (the verb prints the report).
pub fn submit(plan: &Plan, plan_path: &Path, exe: &Path) -> Result<SubmitReport> {
    // One submit of the plan at a time (held while it reads what is queued
    // and submits the rest, so two submits never queue the same tasks).
    let _claim = plan.claim_submit()?;
    let mut sub = read_submission(plan).unwrap_or(Submission { engine: "slurm".into(), jobs: BTreeMap::new() });
    // Jobs of an earlier submission still queued or running stay; the
    // rest of what is not done is submitted again.
    let live: BTreeMap<String, String> = match query(plan) {
        Ok(Some(jobs)) => jobs
            .into_iter()
            .filter(|(_, j)| matches!(j.state.as_str(), "PENDING" | "RUNNING" | "CONFIGURING" | "COMPLETING"))
            .map(|(t, j)| (t, j.id))
            .collect(),
        _ => BTreeMap::new(),
    };
    let done: std::collections::BTreeSet<&str> =
        plan.tasks.iter().filter(|t| task_done(t)).map(|t| t.id.as_str()).collect();
    let run: Vec<&Task> = tasks_to_run(plan, &|t| done.contains(t.id.as_str()) || live.contains_key(&t.id));
    let mut report = SubmitReport { done: done.len(), queued: live.keys().cloned().collect(), ..Default::default() };
    let log_dir = &plan.log_dir;
    std::fs::create_dir_all(log_dir).at(log_dir)?;
    let mut job_of: BTreeMap<String, String> = live.clone();
    // Render arrays, one per layer, in plan order.
    let mut arrays: BTreeMap<&str, Vec<&Task>> = BTreeMap::new();
    let mut order: Vec<&str> = Vec::new();
    for t in run.iter().filter(|t| t.kind == TaskKind::Render) {
        let layer = t.layer.as_deref().unwrap_or_default();
        if !arrays.contains_key(layer) {
            order.push(layer);
        }
        arrays.entry(layer).or_default().push(t);
    }
    for layer in order {
        let tasks = &arrays[layer];
        let indices: Vec<String> = tasks.iter().map(|t| t.chunk.unwrap_or(0).to_string()).collect();
        let first = tasks[0];
        for t in tasks {
            clear_markers(plan, &t.id);
        }
        let array_task = format!("render.{layer}.$SLURM_ARRAY_TASK_ID");
        let args = vec![
            "--parsable".to_string(),
            format!("--job-name=throng.{}.render.{layer}", plan.shot),
            format!("--array={}", indices.join(",")),
            format!("--cpus-per-task={}", first.cores),
            format!("--mem={}M", mem_mb(tasks.iter().map(|t| t.memory_bytes).max().unwrap_or(0))),
            format!("--output={}", log_dir.join(format!("render.{layer}.%a.log")).display()),
            "--open-mode=append".to_string(),
            format!("--chdir={}", plan.out.display()),
            format!("--wrap={}", wrap(exe, plan_path, &array_task)),
        ];
        let id = sbatch(&args, &format!("render.{layer}"))?;
        for t in tasks {
            let job = format!("{id}_{}", t.chunk.unwrap_or(0));
            job_of.insert(t.id.clone(), job.clone());
            sub.jobs.insert(t.id.clone(), job);
        }
        report.submitted.push((format!("render.{layer} array {}", indices.join(",")), id));
        write_submission(plan, &sub)?;
    }
    for t in run.iter().filter(|t| t.kind == TaskKind::Comp) {
        clear_markers(plan, &t.id);
        let deps: Vec<&str> = t.depends_on.iter().filter_map(|d| job_of.get(d).map(String::as_str)).collect();
        let mut args = vec![
            "--parsable".to_string(),
            format!("--job-name=throng.{}.{}", plan.shot, t.id),
            format!("--cpus-per-task={}", t.cores),
            format!("--mem={}M", mem_mb(t.memory_bytes)),
            format!("--output={}", t.log.display()),
            "--open-mode=append".to_string(),
            format!("--chdir={}", plan.out.display()),
        ];
        if !deps.is_empty() {
            // A failed layer cancels its comps instead of leaving them pending forever.
            args.push(format!("--dependency=afterok:{}", deps.join(":")));
            args.push("--kill-on-invalid-dep=yes".into());
        }
        args.push(format!("--wrap={}", wrap(exe, plan_path, &t.id)));
        let id = sbatch(&args, &t.id)?;
        job_of.insert(t.id.clone(), id.clone());
        sub.jobs.insert(t.id.clone(), id.clone());
        report.submitted.push((t.id.clone(), id));
        write_submission(plan, &sub)?;
    }
    Ok(report)
}

fn clear_markers(plan: &Plan, task: &str) {
    for what in ["started", "exit"] {
        let _ = std::fs::remove_file(super::run::marker(plan, task, what));
    }
}

fn write_submission(plan: &Plan, sub: &Submission) -> Result<()> {
    let path = submission_path(plan);
    write_atomic(&path, |w| serde_json::to_writer_pretty(&mut *w, sub).map_err(|e| Error::io(&path, e.into())))
}

/// Runs sbatch; the job id from `--parsable` (`123` or `123;cluster`).
fn sbatch(args: &[String], what: &str) -> Result<String> {
    let out = slurm_command("sbatch", args).map_err(|e| Error::Usage(format!("submitting {what}: {e}")))?;
    let id = out.trim().split(';').next().unwrap_or_default().to_string();
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(Error::Usage(format!("submitting {what}: sbatch printed no job id (`{}`)", out.trim())));
    }
    Ok(id)
}
