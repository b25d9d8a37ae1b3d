//! Progressive backward photon mapping (paper §2, docs/estimator.md): each phase traces camera paths that store
//! backward photons, builds a map of them, traces light paths that gather into the map, and closes the phase
//! into the running sums. `phase` puts the stages together once, for the single-threaded engine and the
//! worker's groups alike; the other files are the stages' parts (camera and light paths, the photon and its
//! map, the area a photon gathers over and the inner disc that measures its blur, the buffers gathered light
//! waits in, the light vertices waiting for a gather in bucket order, the ghost paths and the pilot that
//! decides their pairs and aims, the radius schedule) and where the stages run (`executor`).

pub mod backward_pass;
pub mod executor;
pub mod forward_pass;
pub mod gather_buffer;
pub mod gather_disc;
pub mod ghost_paths;
pub mod inner_disc;
pub mod phase;
pub mod photon;
pub mod photon_map;
pub mod radius;
pub mod sensor_kernel;
pub mod sorted_gather;

pub use backward_pass::{trace_camera_path, BackwardSettings};
pub use executor::Executor;
pub use forward_pass::{
    gather, gather_in_bucket, gather_point, trace_light_path, ForwardStats, Gather, GatherPoint, LightEvent,
    LightSettings, LightVertex, SensorHit,
};
pub use gather_buffer::{AtomicGatherBuffer, AtomicSink, GatherBuffer};
pub use ghost_paths::{ghost_pairs, trace_ghost_paths};
pub use phase::{LocalPixels, Phase, PhaseBuffers};
pub use photon::{BackwardPhoton, PhotonKind};
pub use photon_map::PhotonMap;
pub use radius::{mean_phase, PhaseNumbering, PixelPhase, ProcessShare, RadiusSchedule};
pub use sensor_kernel::SensorKernel;
pub use sorted_gather::{SortedGathers, SORTED_GATHER_BATCH};
