//! The worker's shared-map counter protocol, model-checked on its own: the same two source files as the
//! worker's `parallel::map_slot` and `parallel::sync_primitives`, whose loom test runs with
//!
//! ```text
//! RUSTFLAGS="--cfg photonfarm_loom" CARGO_TARGET_DIR=target/loom cargo test -p map-slot-loom --lib
//! ```
//!
//! Compiled inside the worker, the check would build the worker's every dependency without optimisation first.

#[path = "../src/parallel/sync_primitives.rs"]
pub mod sync_primitives;

#[path = "../src/parallel/map_slot.rs"]
pub mod map_slot;
