//! The bad-input matrices' harness (`tests/bad_input_matrix.rs`, issue 15;
//! `tests/safety_matrix.rs`, issue 26): a [`Case`] is a setup over a base
//! shot, a `throng` command (or a custom body) and what must hold after it;
//! [`check`] runs one as its own test, [`write_table`] runs them all and
//! writes the markdown table of results.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use super::{fixture, repo_path};

/// What a run gave: exit code (-1 when killed by a signal), stdout, stderr.
pub struct Ran {
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

/// Replaces `from` by `to` in `dir/file` (which must contain it).
pub fn edit(dir: &Path, file: &str, from: &str, to: &str) {
    let path = dir.join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{file} has no `{from}`");
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
}

/// Appends `text` to `dir/file`.
pub fn append(dir: &Path, file: &str, text: &str) {
    let path = dir.join(file);
    let mut t = std::fs::read_to_string(&path).unwrap();
    t.push_str(text);
    std::fs::write(&path, t).unwrap();
}

/// Runs throng with `args` in `dir` and asserts success (case setup).
pub fn ok(dir: &Path, args: &[&str]) {
    let out = Command::new(super::bin()).args(args).current_dir(dir).output().unwrap();
    assert!(out.status.success(), "setup `throng {}`: {}", args.join(" "), String::from_utf8_lossy(&out.stderr));
}

/// One case of a matrix.
pub struct Case {
    pub kind: &'static str,
    pub name: &'static str,
    /// Writes or changes files in the case's folder (after the base shot).
    pub setup: fn(&Path),
    /// Arguments; `{d}` is the case's folder, `{fixture}` tests/fixtures.
    pub args: &'static [&'static str],
    /// Every one must appear in stderr (case-sensitive; also stdout when the
    /// harness says so).
    pub says: &'static [&'static str],
    /// Paths under the folder that must not exist afterwards.
    pub absent: &'static [&'static str],
    /// The exit code wanted: 2 for a refusal, 0 for input that is legal.
    pub expect: i32,
    /// A body run instead of `args` (two writers at once, a server).
    pub body: Option<fn(&Path) -> Ran>,
    /// More checks after the run: each problem found.
    pub after: Option<fn(&Path, &Ran) -> Vec<String>>,
    /// Paths (prefixes, relative to the folder) the command may write or
    /// change; with [`Harness::untouched`] every other file must be as setup
    /// left it and no other file may appear.
    pub writes: &'static [&'static str],
}

/// A case: `setup`, then `throng ARGS` must exit 2 saying every one of `says`, leaving no `absent` path.
pub fn c(
    kind: &'static str,
    name: &'static str,
    setup: fn(&Path),
    args: &'static [&'static str],
    says: &'static [&'static str],
    absent: &'static [&'static str],
) -> Case {
    Case { kind, name, setup, args, says, absent, expect: 2, body: None, after: None, writes: &[] }
}

/// How a matrix runs its cases.
pub struct Harness {
    /// Writes the base of every case into its folder.
    pub base: fn(&Path),
    /// The shell text that runs the binary (`$0`) with its arguments under the caps.
    pub wrap: &'static str,
    /// Check that a run changed no file setup made and made none, beyond `writes`.
    pub untouched: bool,
    /// `says` may be found on stdout as well as stderr.
    pub says_on_stdout: bool,
}

/// One case's outcome.
pub struct Outcome {
    pub code: i32,
    pub stderr: String,
    pub problems: Vec<String>,
}

/// The case's arguments with `{d}` and `{fixture}` filled in.
pub fn args_in(args: &[&str], dir: &Path) -> Vec<String> {
    args.iter()
        .map(|a| a.replace("{d}", &dir.display().to_string()).replace("{fixture}", &fixture("").display().to_string()))
        .collect()
}

/// Runs `throng args` in `dir` under `wrap` (a [`Harness::wrap`]).
pub fn run_wrapped(wrap: &str, dir: &Path, args: &[String]) -> Ran {
    let out = Command::new("sh").arg("-c").arg(wrap).arg(super::bin()).args(args).current_dir(dir).output().unwrap();
    Ran {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Every file under `dir` with its bytes (symlinks followed).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    // Regular files only: reading a FIFO a case made would block.
    walk(dir)
        .into_iter()
        .filter(|p| std::fs::metadata(p).is_ok_and(|m| m.is_file()))
        .filter_map(|p| Some((p.clone(), std::fs::read(&p).ok()?)))
        .collect()
}

/// Runs `case` in `dir` (made here, it must not exist yet).
pub fn run_case(h: &Harness, case: &Case, dir: &Path) -> Outcome {
    std::fs::create_dir_all(dir).unwrap();
    (h.base)(dir);
    (case.setup)(dir);
    let before = if h.untouched { snapshot(dir) } else { BTreeMap::new() };
    let ran = match case.body {
        Some(body) => body(dir),
        None => run_wrapped(h.wrap, dir, &args_in(case.args, dir)),
    };
    let code = ran.code;
    let stderr = ran.stderr.clone();
    let mut problems = Vec::new();
    if code != case.expect {
        let what = match code {
            124 => " (hung: killed by the time cap)".to_string(),
            134 | -1 => " (aborted or killed)".to_string(),
            _ => String::new(),
        };
        problems.push(format!("exit {code}{what}, want {}", case.expect));
    }
    if stderr.contains("panicked") {
        problems.push("panicked".into());
    }
    for s in case.says {
        if !(stderr.contains(s) || h.says_on_stdout && ran.stdout.contains(s)) {
            problems.push(format!("stderr does not say `{s}`"));
        }
    }
    for a in case.absent {
        if dir.join(a).exists() {
            problems.push(format!("{a} exists"));
        }
    }
    if let Some(after) = case.after {
        problems.extend(after(dir, &ran));
    }
    // No output under a final name from a failed run: nothing named *.exr,
    // *.crowd, *.json or *.glb appeared beyond what setup made is checked
    // by `absent`; temporaries must be gone too.
    for e in walk(dir) {
        let name = e.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if name.ends_with(".tmp") {
            problems.push(format!("temporary {} left behind", e.display()));
        }
    }
    if h.untouched {
        let allowed = |p: &Path| p.strip_prefix(dir).is_ok_and(|rel| case.writes.iter().any(|w| rel.starts_with(w)));
        let after = snapshot(dir);
        for (p, bytes) in &before {
            if allowed(p) {
                continue;
            }
            match after.get(p) {
                Some(b) if b == bytes => {}
                Some(_) => problems.push(format!("{} changed (an input written over)", rel(dir, p))),
                None => problems.push(format!("{} is gone", rel(dir, p))),
            }
        }
        for p in after.keys().filter(|p| !before.contains_key(*p) && !allowed(p)) {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            if !name.ends_with(".tmp") {
                problems.push(format!("{} was written", rel(dir, p)));
            }
        }
    }
    // Shown relative to the case folder and the repository, as the table's commands are.
    let stderr = stderr
        .replace(&format!("{}/", dir.display()), "")
        .replace(&format!("{}/", repo_path("").display().to_string().trim_end_matches('/')), "");
    Outcome { code, stderr, problems }
}

fn rel(dir: &Path, p: &Path) -> String {
    p.strip_prefix(dir).unwrap_or(p).display().to_string()
}

/// Every file under `dir`, recursively (symlinked folders followed).
pub fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else { return out };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// The message line to show: the first line naming an error or warning.
pub fn excerpt(stderr: &str) -> String {
    let line = stderr
        .lines()
        .find(|l| l.contains("error") || l.contains("warning"))
        .or_else(|| stderr.lines().next())
        .unwrap_or("");
    let line: String = line.chars().take(160).collect();
    line.replace('|', "\\|").replace('`', "'")
}

/// Where a case runs: `THRONG_MATRIX_KEEP=DIR` keeps every case's folder
/// there (named by its test), to look at; else inside `temp`.
pub fn case_dir(temp: &Path, test: &str) -> PathBuf {
    std::env::var_os("THRONG_MATRIX_KEEP").map_or_else(|| temp.to_path_buf(), PathBuf::from).join(test)
}

/// One case's test: it fails with every problem the case has, not only the first.
pub fn check(h: &Harness, test: &str, case: &Case) {
    let temp = super::tempdir().unwrap();
    let o = run_case(h, case, &case_dir(temp.path(), test));
    assert!(
        o.problems.is_empty(),
        "{test}: {} ({}): {}\n    stderr: {}",
        case.name,
        case.kind,
        o.problems.join("; "),
        o.stderr.trim()
    );
}

/// A matrix's table of results.
pub struct Table<'a> {
    /// Written to `target/tmp/<md>` (and to `$THRONG_MATRIX_MD` when set).
    pub md: &'a str,
    /// Add the column of the exit code wanted.
    pub expected_column: bool,
    /// The closing line: (cases, "kind n, ...", passed, not passed).
    pub summary: fn(usize, &str, usize, usize) -> String,
}

/// Runs every case of `cases` ((test, case, why it is ignored)) one after
/// another and writes the table, failing ignored cases listed under it;
/// fails naming every case that failed and is not ignored.
pub fn write_table(h: &Harness, t: &Table, cases: &[(&str, Case, Option<&str>)]) {
    let temp = super::tempdir().unwrap();
    let mut table = if t.expected_column {
        String::from(
            "| # | case | test | input kind | command | expected | exit | message (excerpt) | result |\n\
             |---|---|---|---|---|---|---|---|---|\n",
        )
    } else {
        String::from(
            "| # | case | test | input kind | command | exit | message (excerpt) | result |\n\
             |---|---|---|---|---|---|---|---|\n",
        )
    };
    let (mut failures, mut known) = (Vec::new(), Vec::new());
    for (i, (test, case, ignored)) in cases.iter().enumerate() {
        let o = run_case(h, case, &case_dir(temp.path(), test));
        let cmd: Vec<String> = match case.body {
            Some(_) => vec!["(custom body)".to_string()],
            None => std::iter::once("throng".to_string())
                .chain(case.args.iter().map(|a| a.replace("{d}/", "").replace("{fixture}", "tests/fixtures")))
                .collect(),
        };
        let mut result =
            if o.problems.is_empty() { "ok".to_string() } else { format!("FAIL: {}", o.problems.join("; ")) };
        if let Some(why) = ignored {
            result = format!("{result} (ignored: {why})");
        }
        let expected = if t.expected_column { format!(" {} |", case.expect) } else { String::new() };
        writeln!(
            table,
            "| {} | {} | `{test}` | {} | `{}` |{expected} {} | {} | {} |",
            i + 1,
            case.name,
            case.kind,
            cmd.join(" ").replace('|', "\\|"),
            o.code,
            excerpt(&o.stderr),
            result.replace('|', "\\|")
        )
        .unwrap();
        match (o.problems.is_empty(), ignored) {
            (true, _) => {}
            (false, None) => failures.push(format!("{test}: {}", o.problems.join("; "))),
            (false, Some(why)) => known.push(format!("- `{test}` ({}): {why}", case.kind)),
        }
    }
    let passed = cases.len() - failures.len() - known.len();
    let mut kinds: Vec<(&str, usize)> = Vec::new();
    for (_, case, _) in cases {
        match kinds.iter_mut().find(|k| k.0 == case.kind) {
            Some(k) => k.1 += 1,
            None => kinds.push((case.kind, 1)),
        }
    }
    let kinds: Vec<String> = kinds.iter().map(|(k, n)| format!("{k} {n}")).collect();
    writeln!(table, "\n{}", (t.summary)(cases.len(), &kinds.join(", "), passed, failures.len() + known.len())).unwrap();
    if !known.is_empty() {
        writeln!(
            table,
            "\nFailing and ignored (known: findings not fixed yet, or fixes under way):\n\n{}",
            known.join("\n")
        )
        .unwrap();
    }
    let md = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(t.md);
    std::fs::write(&md, &table).unwrap();
    if let Ok(p) = std::env::var("THRONG_MATRIX_MD") {
        std::fs::write(p, &table).unwrap();
    }
    assert!(failures.is_empty(), "{} of {} cases failed:\n{}", failures.len(), cases.len(), failures.join("\n"));
}

/// A JuPedSim trajectory file `dir/j.sqlite` made by `sql`.
pub fn sqlite(dir: &Path, sql: &str) {
    let db = rusqlite::Connection::open(dir.join("j.sqlite")).unwrap();
    db.execute_batch(sql).unwrap();
}

/// A small valid JuPedSim file's SQL: one agent over two frames at 25 fps.
pub const JUPEDSIM_OK: &str = "CREATE TABLE metadata(key TEXT, value TEXT);
INSERT INTO metadata VALUES ('version', '1'), ('fps', '25');
CREATE TABLE trajectory_data(frame INTEGER, id INTEGER, pos_x REAL, pos_y REAL, ori_x REAL, ori_y REAL);
INSERT INTO trajectory_data VALUES (0, 1, 0.0, 0.0, 1.0, 0.0), (1, 1, 0.05, 0.0, 1.0, 0.0);";
