//! The counters a render reports: totals over a run, which workers send in snapshots and records and
//! checkpoints keep, and what one phase of the single-threaded engine did. They depend on nothing of the engine,
//! so that the protocol and the records can read them.

use serde::{Deserialize, Serialize};

/// Counts accumulated over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RayTotals {
    pub phases: u64,
    /// Rays of camera paths (segments and shadow rays).
    pub backward_rays: u64,
    /// Rays of light paths.
    pub forward_rays: u64,
    pub light_paths: u64,
    /// Light paths counted against the photon maps: a light path counts once per map it gathered into, so this
    /// exceeds `light_paths` where groups share their maps (two-level) and equals it elsewhere.
    pub map_light_paths: u64,
    pub backward_photons: u64,
    /// Light-path vertices that met a backward photon.
    pub merges: u64,
    /// Light paths stopped by `max_depth` while still carrying flux.
    pub capped_light_paths: u64,
}

impl std::ops::AddAssign for RayTotals {
    fn add_assign(&mut self, o: RayTotals) {
        self.phases += o.phases;
        self.backward_rays += o.backward_rays;
        self.forward_rays += o.forward_rays;
        self.light_paths += o.light_paths;
        self.map_light_paths += o.map_light_paths;
        self.backward_photons += o.backward_photons;
        self.merges += o.merges;
        self.capped_light_paths += o.capped_light_paths;
    }
}

/// What one phase did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseReport {
    pub phase: u64,
    pub backward_rays: u64,
    pub forward_rays: u64,
    pub light_paths: u64,
    pub merges: u64,
}
