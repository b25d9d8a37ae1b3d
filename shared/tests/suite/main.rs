//! The renderer library's integration tests, one module per property (the files beside this one), built as one
//! test binary: one link instead of one per file, and one pool of test threads over all of them. Tests that
//! measure their own process (`memory_flat`, `spectral_cost`) or need another build of the library
//! (`backend_agreement`, `spectral_cost`) are binaries of their own beside this folder.
#![allow(clippy::needless_range_loop)]

#[path = "../common/mod.rs"]
mod common;

mod analytic_bounds;
mod analytic_scenes;
mod bad_scenes;
mod bsdfs;
mod calibration;
mod depth_choice;
mod determinism;
mod edge_bias;
mod forecast;
mod ghost_partition;
mod glossy_scenes;
mod hud;
mod infinite_lights;
mod lens;
mod lit_mask;
mod mitsuba_families;
mod mitsuba_import;
mod mitsuba_reader;
mod mitsuba_twins;
mod outdoor_reference;
mod partition;
mod phase_cap;
mod prism;
mod protocol_hostile_input;
mod quasi_random;
mod ray_map;
mod scene_description;
mod stress_scenes;
mod textures;
