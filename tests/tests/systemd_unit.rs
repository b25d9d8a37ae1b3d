//! deploy/photonfarm-worker.service: systemd reads it without a warning, with the built worker in place of the
//! installed one, and rates its hardening at an exposure of at most 2.0 of 10. Both checks run offline
//! (`systemd-analyze verify` and `security --offline`): they need no running systemd, which containers lack.

use end_to_end::{binary, repo_root, scratch_dir};
use std::path::Path;
use std::process::Command;

const INSTALLED: &str = "/opt/photonfarm/worker";

/// The unit as shipped, with the worker program this build made.
fn unit_with_built_worker(dir: &Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(repo_root().join("deploy/photonfarm-worker.service")).unwrap();
    assert!(text.contains(&format!("ExecStart={INSTALLED} serve ")), "{text}");
    let path = dir.join("photonfarm-worker.service");
    std::fs::write(&path, text.replace(INSTALLED, binary("worker").to_str().unwrap())).unwrap();
    path
}

fn systemd_analyze(args: &[&str], unit: &Path) -> (bool, String) {
    let o = Command::new("systemd-analyze")
        .args(args)
        .arg(unit)
        .output()
        .expect("cannot run systemd-analyze (scripts/system-packages installs systemd)");
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    (o.status.success(), text)
}

#[test]
fn the_worker_unit_verifies_without_a_warning() {
    let dir = scratch_dir("systemd-verify");
    let unit = unit_with_built_worker(&dir);
    // verify exits 0 on unknown keys and unparsable values, which it only warns about: any output is a fault.
    let (ok, text) = systemd_analyze(&["verify"], &unit);
    assert!(ok && text.trim().is_empty(), "{text}");
}

#[test]
fn the_worker_unit_takes_its_secret_from_a_credential_and_is_hardened() {
    let dir = scratch_dir("systemd-security");
    let unit = unit_with_built_worker(&dir);
    let text = std::fs::read_to_string(&unit).unwrap();
    for line in ["LoadCredential=secret:", "--secret-file %d/secret", "DynamicUser=yes", "ProtectSystem=strict"] {
        assert!(text.contains(line), "the unit lacks {line}");
    }
    // --threshold is on a 0–100 scale: 20 is an exposure of 2.0 of 10.
    let (ok, report) = systemd_analyze(&["security", "--offline=yes", "--threshold=20"], &unit);
    let overall = report.lines().find(|l| l.contains("Overall exposure level")).unwrap_or("no overall level");
    eprintln!("{overall}");
    assert!(ok, "exposure above 2.0:\n{report}");
}
