//! Progressive backward photon mapping (paper §2, DESIGN §1): each phase traces camera paths that store
//! backward photons, builds a map of them, traces light paths that gather into the map, and closes the phase
//! into the running sums.

pub mod backward_pass;
pub mod forward_pass;
pub mod photon;
pub mod photon_map;
pub mod radius;

pub use backward_pass::{trace_camera_path, BackwardSettings};
pub use forward_pass::{gather, trace_light_path, ForwardStats, Gather, LightVertex};
pub use photon::BackwardPhoton;
pub use photon_map::PhotonMap;
pub use radius::RadiusSchedule;
