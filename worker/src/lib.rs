//! photonfarm's rendering process. `parallel` is the engine: synchronous groups of pinned threads (level 1)
//! rendering random tile masks and sharing their backward photon maps through atomic counters (level 2), with
//! the classic parallel methods as configurations of it. The rest is the process around it: `job` renders a job
//! and sends its snapshots, `link` is the worker's end of the protocol, `files` receives and keeps the scene's
//! files, `machine` and `memory_binding` find and
//! bind the cores and memory it may use; `main.rs` is `worker join` and `worker serve`.

pub mod files;
pub mod job;
pub mod link;
pub mod logging;
pub mod machine;
pub mod memory_binding;
pub mod parallel;

pub use parallel::{ConfigError, EngineConfig, ParallelEngine, ParallelMethod, PhaseCap};
