//! `throng farm`: plan a shot as a task graph, submit it to an engine
//! (Slurm, or local workers), and follow it (docs/farm.md).

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand, ValueEnum};

use super::values::{frame_list, resolution, FrameList, Resolution};
use throng::error::{Error, Result};
use throng::farm::{self, PlanOptions, TaskState};

/// `throng farm ...`.
#[derive(Debug, Subcommand)]
pub enum FarmVerb {
    /// Write the shot's task graph (and its layer manifest) into DIR/plan.json.
    Plan(PlanArgs),
    /// Submit what is not done of a plan to an engine.
    Submit(SubmitArgs),
    /// Each task done, running, failed or waiting; exit 0 when all are done, 1 while some are
    /// waiting or running, 3 when one failed.
    Status(StatusArgs),
    /// Run one task of a plan (what engines run; retries and leaves state markers).
    #[command(hide = true)]
    RunTask(RunTaskArgs),
    /// Print this message or the help of the given farm verb(s).
    Help(super::shell::HelpArgs),
}

/// `throng farm plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Shot frames, e.g. 1001-1010 (default: the whole shot).
    #[arg(long, value_parser = frame_list)]
    pub frames: Option<FrameList>,
    /// Layers, e.g. set,crowd0 (default: every layer; comps only when every layer is planned).
    #[arg(long, value_delimiter = ',')]
    pub layers: Option<Vec<String>>,
    /// Frames per render task.
    #[arg(long, default_value_t = 1, value_parser = super::values::count)]
    pub chunk: usize,
    /// Samples per pixel, 1-65536 (default: the shot's).
    #[arg(long, value_parser = super::values::spp)]
    pub spp: Option<u32>,
    /// Image size override, e.g. 480x270 (default: the shot's).
    #[arg(long, value_parser = resolution)]
    pub resolution: Option<Resolution>,
    /// Cores per render task (its `--threads`; output does not depend on it).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub cores: u32,
    /// Extra attempts of a failed task, 0-100.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=100))]
    pub retries: u32,
    /// Every render task denoises with Open Image Denoise at this quality, or `off` (`--denoise`
    /// alone is `high`; default: the shot's `render.denoise`). Tasks ask for the denoiser's memory.
    #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "high", value_name = "QUALITY")]
    pub denoise: Option<super::render::DenoiseFlag>,
    /// Plan directory: plan.json, the manifest, render/, logs/, farm/.
    #[arg(long)]
    pub out: PathBuf,
    /// Machine-readable output: the plan itself.
    #[arg(long)]
    pub json: bool,
    /// Render tasks also write deep OpenEXRs (`render --deep`) and comps merge them (`comp
    /// --deep`); a shot with a `[render.deep]` table does so without it.
    #[arg(long)]
    pub deep: bool,
}

/// `--engine`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Engine {
    /// sbatch job arrays with afterok dependencies.
    Slurm,
    /// Worker processes on this machine.
    Local,
}

/// `throng farm submit`.
#[derive(Debug, Args)]
pub struct SubmitArgs {
    /// The plan (DIR/plan.json).
    pub plan: PathBuf,
    /// Where to run it.
    #[arg(long, value_enum)]
    pub engine: Engine,
    /// Worker processes (local engine).
    #[arg(long, default_value_t = 1, value_parser = super::values::whole)]
    pub workers: usize,
    /// Refuse the plan unless it is for this shot file.
    #[arg(long)]
    pub shot: Option<PathBuf>,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// `throng farm status`.
#[derive(Debug, Args)]
pub struct StatusArgs {
    /// The plan (DIR/plan.json).
    pub plan: PathBuf,
    /// Refuse the plan unless it is for this shot file.
    #[arg(long)]
    pub shot: Option<PathBuf>,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// `throng farm run-task`.
#[derive(Debug, Args)]
pub struct RunTaskArgs {
    /// The plan.
    pub plan: PathBuf,
    /// Task id.
    pub task: String,
}

/// Runs a farm verb.
pub fn run(verb: &FarmVerb) -> Result<()> {
    match verb {
        FarmVerb::Plan(a) => plan(a),
        FarmVerb::Submit(a) => submit(a),
        FarmVerb::Status(a) => status(a),
        FarmVerb::Help(a) => super::shell::help(&["farm"], a),
        FarmVerb::RunTask(a) => {
            let plan = farm::open_plan(&a.plan, None)?;
            if plan.task(&a.task).is_none() {
                let some: Vec<&str> = plan.tasks.iter().take(3).map(|t| t.id.as_str()).collect();
                return Err(Error::invalid(&a.plan, format!("no task `{}` (tasks: {}...)", a.task, some.join(", ")))
                    .field("tasks"));
            }
            farm::run_task(&plan, &a.task, &exe()?, &mut |line| eprintln!("throng farm: {line}"))
        }
    }
}

/// This binary: what engines run for `throng`.
fn exe() -> Result<PathBuf> {
    std::env::current_exe().map_err(|e| Error::Usage(format!("cannot find the throng binary to run tasks: {e}")))
}

/// The plan path made absolute, as engines hand it to other processes.
fn absolute(p: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(p).map_err(|e| Error::io(p, e))
}

fn plan(a: &PlanArgs) -> Result<()> {
    let opts = PlanOptions {
        frames: a.frames.as_ref().map(|FrameList(f)| f.clone()),
        layers: a.layers.clone(),
        chunk: a.chunk,
        spp: a.spp,
        resolution: a.resolution.map(|Resolution(r)| r),
        cores: a.cores,
        retries: a.retries,
        denoise: a.denoise.map(super::render::DenoiseFlag::preset),
        deep: a.deep,
        ..PlanOptions::new(a.shot.clone(), a.out.clone())
    };
    let (path, plan) = farm::write_new_plan(&opts)?;
    if a.json {
        outln!("{}", super::to_json(&plan)?);
        return Ok(());
    }
    let renders = plan.tasks.iter().filter(|t| t.kind == farm::TaskKind::Render).count();
    outln!(
        "plan {}: shot {}, {} frames x {} layers -> {renders} render tasks ({} frames each) and {} comps",
        path.display(),
        plan.shot,
        plan.frames.len(),
        plan.layers.len(),
        plan.chunk,
        plan.tasks.len() - renders
    );
    outln!(
        "fingerprint {} over {} inputs; manifest {}",
        plan.fingerprint.value,
        plan.fingerprint.inputs.len(),
        plan.manifest.display()
    );
    Ok(())
}

fn submit(a: &SubmitArgs) -> Result<()> {
    let plan_path = absolute(&a.plan)?;
    let plan = farm::open_plan(&plan_path, a.shot.as_deref())?;
    let exe = exe()?;
    match a.engine {
        Engine::Slurm => {
            let report = farm::slurm::submit(&plan, &plan_path, &exe)?;
            if a.json {
                outln!("{}", super::to_json(&report)?);
                return Ok(());
            }
            for (what, id) in &report.submitted {
                outln!("submitted {what}: slurm job {id}");
            }
            for t in &report.queued {
                outln!("still queued from an earlier submission: {t}");
            }
            outln!(
                "{} jobs submitted, {} tasks already done; follow with `throng farm status {}`",
                report.submitted.len(),
                report.done,
                a.plan.display()
            );
            Ok(())
        }
        Engine::Local => {
            let say = |line: &str| {
                if !a.json {
                    outln!("{line}");
                    let _ = std::io::stdout().flush();
                }
            };
            let report = farm::local::run_local(&plan, &plan_path, &exe, a.workers, &say)?;
            if a.json {
                outln!("{}", super::to_json(&report)?);
            } else {
                outln!(
                    "local: {} tasks ran, {} already done, {} failed, {} blocked in {:.1} s",
                    report.ran.len(),
                    report.skipped,
                    report.failed.len(),
                    report.blocked.len(),
                    report.seconds
                );
            }
            if let Some((id, log)) = report.failed.first() {
                return Err(Error::Usage(format!(
                    "{} task(s) failed, first {id}: see its log {log}",
                    report.failed.len()
                )));
            }
            Ok(())
        }
    }
}

fn status(a: &StatusArgs) -> Result<()> {
    let plan = farm::open_plan(&a.plan, a.shot.as_deref())?;
    let (tasks, note) = farm::plan_status(&plan);
    let count = |s: TaskState| tasks.iter().filter(|t| t.state == s).count();
    let all_done = count(TaskState::Done) == tasks.len();
    if a.json {
        let v = serde_json::json!({
            "shot": plan.shot,
            "done": all_done,
            "scheduler": note,
            "tasks": tasks,
        });
        outln!("{}", super::to_json(&v)?);
    } else {
        let w = tasks.iter().map(|t| t.id.len()).max().unwrap_or(4);
        for t in &tasks {
            let log = if t.state == TaskState::Failed { format!("  log {}", t.log.display()) } else { String::new() };
            outln!("{:<w$}  {:<7}  {}{log}", t.id, t.state.word(), t.detail);
        }
        if let Some(n) = &note {
            outln!("{n}");
        }
        outln!(
            "{}: {} done, {} running, {} failed, {} waiting of {} tasks",
            plan.shot,
            count(TaskState::Done),
            count(TaskState::Running),
            count(TaskState::Failed),
            count(TaskState::Waiting),
            tasks.len()
        );
    }
    let code = status_code(&tasks.iter().map(|t| t.state).collect::<Vec<_>>());
    if code != 0 {
        let _ = std::io::stdout().flush();
        std::process::exit(code);
    }
    Ok(())
}

/// `farm status`'s exit status, for a pipeline that polls it: 0 when every
/// task is done, [`UNFINISHED`] while some are still waiting or running,
/// [`FAILED`] when one failed (it will not finish by itself: look at its
/// log, fix, submit again). 2 stays every verb's error (a bad plan).
fn status_code(states: &[TaskState]) -> i32 {
    if states.contains(&TaskState::Failed) {
        FAILED
    } else if states.iter().all(|&s| s == TaskState::Done) {
        0
    } else {
        UNFINISHED
    }
}

/// `farm status`: some task still waiting or running, none failed.
const UNFINISHED: i32 = 1;
/// `farm status`: some task failed.
const FAILED: i32 = 3;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_is_0_done_1_unfinished_3_failed() {
        use TaskState::*;
        assert_eq!(status_code(&[Done, Done]), 0);
        assert_eq!(status_code(&[Done, Waiting]), 1);
        assert_eq!(status_code(&[Running, Waiting]), 1);
        assert_eq!(status_code(&[Done, Running, Failed]), 3);
        assert_eq!(status_code(&[]), 0);
    }
}
