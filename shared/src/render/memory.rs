//! Process memory as the kernel counts it, for the run record, `--memory-limit` and the flat-memory test.

/// Peak resident set size of this process (VmHWM), in bytes, where the OS reports it.
pub fn peak_rss_bytes() -> Option<u64> {
    status_field("VmHWM:")
}

/// Resident set size of this process now (VmRSS), in bytes, where the OS reports it.
pub fn current_rss_bytes() -> Option<u64> {
    status_field("VmRSS:")
}

/// Why a render that needs `need` bytes (`base` in use after loading the scene, plus the engine's buffers)
/// does not start under `--memory-limit` `limit`; `detail` ends the sentence.
pub fn over_limit(limit: u64, need: u64, base: u64, detail: &str) -> String {
    let mib = |b: u64| format!("{:.0} MiB", b as f64 / (1u64 << 20) as f64);
    format!(
        "--memory-limit {} is too small: this render needs about {} ({} in use after loading the scene, plus the \
         engine's buffers){detail}",
        mib(limit),
        mib(need),
        mib(base)
    )
}

fn status_field(name: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(name))?;
    let kb: u64 = line[name.len()..].trim().trim_end_matches("kB").trim().parse().ok()?;
    Some(kb * 1024)
}
