//! Command-line interface. Flag names are a contract: scripts depend on them.

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// photonfarm: physically based rendering with progressive backward photon mapping.
#[derive(Parser, Debug)]
#[command(name = "coordinator", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a scene file and write image.exr, preview.png and run.json into an output folder.
    Render(RenderArgs),
}

/// Estimators selectable with --method.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MethodArg {
    /// Progressive backward photon mapping (single thread until the parallel engine lands).
    Pbpm,
    /// The reference path tracer, for comparison.
    Path,
}

/// Which pixels δ is computed over for --target-error and the progress display.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorOverArg {
    /// Pixels that do not see a light directly.
    Unlit,
    /// All pixels (the paper's eq. 6).
    All,
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The scene file (TOML), e.g. scenes/cornell.toml.
    pub scene: PathBuf,
    /// Stop after this many seconds of rendering. Default when no stop rule is given: 30.
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
    /// Stop after this many phases.
    #[arg(long, value_name = "N")]
    pub phases: Option<u64>,
    /// Stop once the relative error δ (see --error-over) is at or below D, e.g. 0.05.
    #[arg(long, value_name = "D")]
    pub target_error: Option<f64>,
    /// Pixels δ is measured over for --target-error and the progress bar.
    #[arg(long, value_enum, default_value = "unlit")]
    pub error_over: ErrorOverArg,
    /// Output folder (created if missing). Default: a new folder under out/.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Estimator.
    #[arg(long, value_enum, default_value = "pbpm")]
    pub method: MethodArg,
    /// Job seed; the same seed and settings give bit-identical sums.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Override the scene's max_depth (total path segments).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Override the scene's backward_diffuse_depth (1 or 2).
    #[arg(long)]
    pub backward_diffuse_depth: Option<u32>,
    /// Override the initial photon radius, in pixel footprints.
    #[arg(long)]
    pub radius_scale: Option<f32>,
    /// Override the number of light paths per phase, per pixel.
    #[arg(long)]
    pub light_paths_per_pixel: Option<f32>,
    /// A reference EXR (layer "total", or a plain RGB EXR) to measure the true error against.
    #[arg(long, value_name = "EXR")]
    pub reference: Option<PathBuf>,
    /// Seconds between refreshes of the output files during the run.
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS")]
    pub save_interval: f64,
    /// No progress bar (for logs and scripts).
    #[arg(long)]
    pub quiet: bool,
}
