//! The programs' logs through `tracing`: one line per event on standard error, with its level, its module and
//! its fields (the job and the worker it concerns), filtered by `RUST_LOG` (default `info`; e.g.
//! `RUST_LOG=warn`, or `RUST_LOG=info,coordinator::cluster=debug`). A `worker serve` under systemd or Slurm can
//! so be filtered by level and module. Colours only on a terminal.

use std::io::IsTerminal;
use tracing_subscriber::EnvFilter;

/// Installs the logger of `coordinator` and `worker`; a malformed `RUST_LOG` falls back to `info` and says so.
pub fn init() {
    let (filter, bad) = match EnvFilter::try_from_default_env() {
        Ok(f) => (f, None),
        Err(e) => (EnvFilter::new("info"), std::env::var("RUST_LOG").ok().filter(|v| !v.is_empty()).map(|v| (v, e))),
    };
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
    if let Some((value, e)) = bad {
        tracing::warn!("RUST_LOG={value:?} is not a filter ({e}); logging at info");
    }
}
