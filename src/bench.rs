//! Process figures for benchmarks (`examples/*_bench.rs`) and the render
//! summary's per-layer peak memory: peak memory and CPU time, read from /proc so they stay meaningful when other jobs share
//! the cores. NaN where /proc is not available.

/// Peak resident set size of this process in MiB (VmHWM).
pub fn peak_rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// Peak resident set size of this process in bytes (`None` without /proc).
pub fn peak_rss_bytes() -> Option<u64> {
    let mib = peak_rss_mib();
    mib.is_finite().then_some((mib * 1048576.0) as u64)
}

/// Resets the process's peak RSS (VmHWM) to its current RSS, so the next
/// [`peak_rss_mib`] measures one stretch of work (one layer's render).
/// Returns false where the kernel does not allow it (no /proc, not Linux).
pub(crate) fn reset_peak_rss() -> bool {
    // "5" in clear_refs resets the peak resident set size (Linux >= 4.0).
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// CPU seconds of the calling thread.
pub fn thread_cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

/// CPU seconds of the whole process (all threads, user + system).
pub fn process_cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the ")" of the command name; utime and stime are fields 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(f64::NAN);
    (tick(11) + tick(12)) / 100.0 // USER_HZ is 100 on Linux
}

/// A `/proc`-style figure: the number after `key` on its line of `text`.
fn proc_field(text: &str, key: &str) -> Option<u64> {
    text.lines().find(|l| l.starts_with(key))?.split_whitespace().nth(1)?.parse().ok()
}

/// The bytes this process may still allocate: the least of what its
/// address-space limit (`ulimit -v`, RLIMIT_AS, over its present size),
/// its control group's memory limit (cgroup v2 `memory.max`, over
/// `memory.current`: a farm node's job limit) and the system's available
/// memory and free swap leave. `None` when /proc says none of them.
pub fn memory_headroom() -> Option<u64> {
    let mut free: Vec<u64> = Vec::new();
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let limits = std::fs::read_to_string("/proc/self/limits").unwrap_or_default();
    // "Max address space   <soft>   <hard>   bytes"
    let soft = limits.lines().find(|l| l.starts_with("Max address space")).and_then(|l| {
        l.trim_start_matches("Max address space").split_whitespace().next().and_then(|v| v.parse::<u64>().ok())
    });
    if let (Some(limit), Some(size_kb)) = (soft, proc_field(&status, "VmSize:")) {
        free.push(limit.saturating_sub(size_kb.saturating_mul(1024)));
    }
    let cgroup = std::fs::read_to_string("/proc/self/cgroup").unwrap_or_default();
    if let Some(dir) = cgroup.lines().find_map(|l| l.strip_prefix("0::")) {
        let dir = std::path::Path::new("/sys/fs/cgroup").join(dir.trim_start_matches('/'));
        let read = |f: &str| std::fs::read_to_string(dir.join(f)).ok()?.trim().parse::<u64>().ok();
        if let (Some(max), Some(current)) = (read("memory.max"), read("memory.current")) {
            free.push(max.saturating_sub(current));
        }
    }
    let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
    if let Some(kb) = proc_field(&meminfo, "MemAvailable:") {
        let swap = proc_field(&meminfo, "SwapFree:").unwrap_or(0);
        free.push(kb.saturating_add(swap).saturating_mul(1024));
    }
    free.into_iter().min()
}
