//! The short run of `fuzz-inputs` that CI keeps: generated frames, snapshot deltas, checkpoints and scene
//! files fed to the decoders and loaders give errors, never a panic, and the process's memory stays bounded.

use end_to_end::binary;
use std::process::Command;

#[test]
fn generated_hostile_inputs_are_refused_without_a_panic_in_bounded_memory() {
    let o = Command::new(binary("fuzz-inputs")).args(["--inputs", "8000", "--seed", "7"]).output().unwrap();
    let report = String::from_utf8_lossy(&o.stdout);
    println!("{report}");
    assert!(o.status.success(), "{report}{}", String::from_utf8_lossy(&o.stderr));
    for kind in ["frames", "snapshot deltas", "checkpoints", "scene files"] {
        let line = report.lines().find(|l| l.trim_start().starts_with(kind)).expect(kind);
        assert!(line.ends_with(" 0 panics"), "{line}");
        // The generator reaches the checks: every kind gets inputs that are refused.
        let count = |what: &str| -> u64 {
            let words: Vec<&str> = line.split_whitespace().collect();
            let at = words.iter().position(|w| w.trim_end_matches(',') == what).expect(what);
            words[at - 1].parse().unwrap()
        };
        assert!(count("refused") > 0, "{line}");
    }
    let peak_mib: f64 = report
        .lines()
        .find_map(|l| l.strip_prefix("peak memory: "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("the peak memory line");
    assert!(peak_mib < 256.0, "peak memory {peak_mib} MiB");
}
