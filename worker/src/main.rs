//! `worker`: the rendering process a coordinator starts on every NUMA node (or dials on a remote server).
//!
//! Until the coordinator–worker protocol lands, `coordinator render --method sync|async|two-level` runs this
//! crate's engine in-process; this program only says so.

fn main() -> std::process::ExitCode {
    eprintln!(
        "worker: the coordinator–worker protocol is not part of this build yet; run `coordinator render SCENE \
         --method two-level` to use the parallel engine in-process (see README.md)"
    );
    std::process::ExitCode::from(2)
}
