//! Rendering runs: settings, the single-threaded progressive engine, images from the sums, memory and the run
//! record.

pub mod checkpoint;
pub mod engine;
pub mod images;
pub mod memory;
pub mod method;
pub mod record;
pub mod session;
pub mod settings;

pub use engine::{Engine, PhaseReport, RayTotals};
pub use method::{Estimator, Layout, Method, ParallelMethod};
pub use settings::RenderSettings;
