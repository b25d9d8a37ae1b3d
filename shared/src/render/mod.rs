//! Rendering runs: settings, the counters a run reports, the single-threaded progressive engine, images from the
//! sums, memory, checkpoints, the run record, the forecast of a run's remaining time and the choice of light paths per pixel.

pub mod active_tiles;
pub mod checkpoint;
pub mod engine;
pub mod forecast;
pub mod images;
pub mod light_balance;
pub mod memory;
pub mod method;
pub mod record;
pub mod session;
pub mod settings;
pub mod totals;

pub use active_tiles::ActiveTiles;
pub use engine::Engine;
pub use method::{Estimator, Layout, Method, ParallelMethod};
pub use settings::RenderSettings;
pub use totals::{PhaseReport, RayTotals};
