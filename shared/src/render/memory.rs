//! Process memory as the kernel counts it, for the run record, the memory budget checked before a render
//! allocates (`--memory-limit` or the machine's available memory) and the flat-memory test.

/// Peak resident set size of this process (VmHWM), in bytes, where the OS reports it.
pub fn peak_rss_bytes() -> Option<u64> {
    status_field("VmHWM:")
}

/// Resident set size of this process now (VmRSS), in bytes, where the OS reports it.
pub fn current_rss_bytes() -> Option<u64> {
    status_field("VmRSS:")
}

/// What the machine could give new allocations now without swapping (MemAvailable), in bytes, where the OS
/// reports it.
pub fn available_bytes() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    kilobytes_field(&info, "MemAvailable:")
}

/// The memory a render may hold: the `--memory-limit` given, or else what the machine has available when the
/// render is about to allocate its buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemoryBudget {
    Limit(u64),
    Available(u64),
}

impl MemoryBudget {
    /// `--memory-limit` if given, else the machine's available memory (none where the OS does not say).
    pub fn new(limit: Option<u64>) -> Option<MemoryBudget> {
        limit.map(MemoryBudget::Limit).or_else(|| available_bytes().map(MemoryBudget::Available))
    }

    pub fn bytes(self) -> u64 {
        match self {
            MemoryBudget::Limit(b) | MemoryBudget::Available(b) => b,
        }
    }

    /// "--memory-limit 300 MiB" or "the 2048 MiB of memory this machine has available".
    pub fn describe(self) -> String {
        match self {
            MemoryBudget::Limit(b) => format!("--memory-limit {}", mib(b)),
            MemoryBudget::Available(b) => format!("the {} of memory this machine has available", mib(b)),
        }
    }
}

/// Why a render that needs `need` bytes (`base` in use after loading the scene, plus the engine's buffers)
/// does not start within `budget`; `detail` follows the estimate, and the flags that lower it end the message.
pub fn over_limit(budget: MemoryBudget, need: u64, base: u64, detail: &str) -> String {
    let why = match budget {
        MemoryBudget::Limit(_) => format!("{} is too small", budget.describe()),
        MemoryBudget::Available(_) => format!("{} is not enough", budget.describe()),
    };
    let set = match budget {
        MemoryBudget::Limit(_) => "",
        MemoryBudget::Available(_) => "; --memory-limit sets the budget instead",
    };
    format!(
        "{why}: this render needs about {} ({} in use after loading the scene, plus the engine's buffers){detail}. \
         The buffers grow with the image's pixels and the photons each pixel holds: a smaller image, \
         --backward-diffuse-depth 1, or fewer --threads with async (one image per thread) need less{set}",
        mib(need),
        mib(base)
    )
}

fn mib(bytes: u64) -> String {
    format!("{:.0} MiB", bytes as f64 / (1u64 << 20) as f64)
}

fn status_field(name: &str) -> Option<u64> {
    kilobytes_field(&std::fs::read_to_string("/proc/self/status").ok()?, name)
}

/// The value of a "Name:   1234 kB" line of a /proc file, in bytes.
fn kilobytes_field(text: &str, name: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(name))?;
    let kb: u64 = line[name.len()..].trim().trim_end_matches("kB").trim().parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_available_memory_is_read_from_meminfo_and_a_limit_given_overrides_it() {
        let text = "MemTotal:       24000000 kB\nMemFree:        19000000 kB\nMemAvailable:   22000000 kB\n";
        assert_eq!(kilobytes_field(text, "MemAvailable:"), Some(22_000_000 * 1024));
        assert_eq!(kilobytes_field(text, "SwapTotal:"), None);
        assert_eq!(MemoryBudget::new(Some(5)), Some(MemoryBudget::Limit(5)));
        if cfg!(target_os = "linux") {
            assert!(matches!(MemoryBudget::new(None), Some(MemoryBudget::Available(b)) if b > 0));
        }
    }

    #[test]
    fn a_refusal_names_the_budget_the_estimate_and_the_flags_that_lower_it() {
        let m = over_limit(MemoryBudget::Limit(20 << 20), 300 << 20, 40 << 20, "");
        assert!(m.starts_with("--memory-limit 20 MiB is too small: this render needs about 300 MiB (40 MiB"), "{m}");
        assert!(m.contains("--backward-diffuse-depth 1") && !m.contains("sets the budget"), "{m}");
        let m = over_limit(MemoryBudget::Available(1 << 30), 2 << 30, 1 << 20, " on 4 threads");
        assert!(
            m.starts_with(
                "the 1024 MiB of memory this machine has available is not enough: this render needs \
                               about 2048 MiB"
            ),
            "{m}"
        );
        assert!(
            m.contains("on 4 threads. The buffers") && m.ends_with("--memory-limit sets the budget instead"),
            "{m}"
        );
    }
}
