//! The worker engine: synchronous groups of pinned threads (level 1) rendering random tile masks and sharing
//! their backward photon maps through atomic counters (level 2), and the classic parallel methods as
//! configurations of the same engine (DESIGN §2).

pub mod engine;
pub mod group;
pub mod job;
pub mod link;
pub mod machine;
pub mod map_slot;
pub mod mask;
pub mod memory_binding;
pub mod sync_primitives;

pub use engine::{ConfigError, EngineConfig, ParallelEngine, ParallelMethod};
