//! photonfarm's renderer library: scenes, ray tracing, progressive backward photon mapping (PBPM), the
//! reference path tracer, accumulation with the SEM error estimate, and image output.

pub mod accumulation;
pub mod camera;
pub mod color;
pub mod geometry;
pub mod ghost;
pub mod image_io;
pub mod integrator;
pub mod light;
pub mod material;
pub mod pbpm;
pub mod protocol;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod spectrum;
pub mod texture;
