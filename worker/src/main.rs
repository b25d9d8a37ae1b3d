//! `worker`: the rendering process a coordinator starts on every NUMA node (or dials on a remote server).
//!
//! The multi-threaded engine (synchronous groups, masks, shared photon maps) is the next milestone; until it
//! lands, `coordinator render` renders in-process on one thread and this program only says so.

fn main() -> std::process::ExitCode {
    eprintln!(
        "worker: the parallel worker engine is not part of this build yet; `coordinator render SCENE` renders \
         in-process (see README.md)"
    );
    std::process::ExitCode::from(2)
}
