//! The parallel scheme of one process (paper §4, docs/parallel-engine.md): synchronous groups of pinned threads
//! (`group`), the semi-synchronous level that deals them random tile masks and forms the whole image (`engine`,
//! `mask`), and the slots through which groups open their photon maps to each other with atomic counters
//! (`map_slot`, model-checked with loom through `sync_primitives`), with each thread's plain buffer and
//! held-back light vertices for its gathers in bucket order (`thread_gathers`). `sync`, `async` and `two-level`
//! are configurations of it (`EngineConfig`).

pub mod engine;
pub mod group;
pub mod map_slot;
pub mod mask;
pub mod sync_primitives;
pub mod thread_gathers;

pub use engine::{ConfigError, EngineConfig, ParallelEngine, ParallelMethod, PhaseCap};
