//! photonfarm's renderer library: scenes, ray tracing, progressive backward photon mapping (PBPM), the
//! reference path tracer, accumulation with the SEM error estimate, image output, and the protocol between the
//! coordinator and its workers.
//!
//! # Crate map
//!
//! The modules form layers, listed here from the bottom up. A module imports modules of its own layer or of
//! lower ones, never of a higher one.
//!
//! **Colour, sampling and geometry.** `color` (linear RGB), `sampling` (random streams, the warps from
//! uniform numbers to directions and points, and densities learnt per cell of a grid) and `geometry` (rays,
//! triangle meshes, analytic lens surfaces and the BVH over them) import nothing of the crate. `camera`
//! (pinhole, thin lens, sensor behind a lens) builds its rays from `geometry` and `sampling`.
//!
//! **Spectra, textures, scattering and lights.** `spectrum` holds wavelengths, dispersive refractive indices
//! and the colour state of a path; it knows of materials only through its `Dispersive` trait. `texture`
//! (constants, bitmaps and patterns over a surface's texture coordinates) serves materials and lights. `bsdf`
//! is the scattering interface with one file per family (diffuse, conductor, dielectric, coating, …) and the
//! lobe classes the estimator reads; `material` is a scene's material (textured parameters, two sides, an
//! opacity) resolved into a `bsdf::Bsdf` at a surface point; `light` holds emitters and their sampling (with
//! the densities over a lens's front element that ghost paths aim by). They read `geometry`'s hits and
//! `sampling`'s warps.
//!
//! **Scene.** `scene` is the loaded scene the integrators read (objects, materials, geometry, lights, camera).
//! `scene::description` is a scene as its readers describe it, format-free and serialisable (files named by
//! path and SHA-256, every element by its file, line and element), which jobs carry to workers; `scene::loader`
//! reads a TOML file into one with errors that name the file, line and field, and `scene::mitsuba` a Mitsuba 3
//! XML scene, with notes on what it ignored or approximated; `scene::build` is the one step from a description
//! and its files (meshes, also serialized and PLY, and images) to the `Scene`; `scene::ghost` holds what a scene declares about the ghosts its lens
//! makes (its front element, its ghost settings, the table of surface pairs ghost paths reflect at, which it
//! keeps once the estimator's pilot has filled it). It builds on the two layers below it.
//!
//! **Integrators.** `integrator` holds the image layers, next-event estimation, the one path walk
//! (`integrator::walk`, a bounce loop with a technique for what each kind of path does) with its camera
//! technique, the reference path tracer, and which pixels see a light (`integrator::lit_pixels`); `ghost` tells
//! which light is ghost light (reflected inside a lens); `ray_map` records a share of a run's paths and reads
//! them back. They read the scene.
//!
//! **Accumulation and error.** `accumulation` keeps the running sums of every pixel and layer, the auxiliary
//! layers (ghost light, wavelength bands), the error estimate δ over the SEM, the lit mask δ unlit leaves out,
//! and `accumulation::delta`, the exact compressed deltas of the sums that snapshots and checkpoints carry. It
//! reads the layers of `integrator` and chooses the auxiliary layers from the scene.
//!
//! **The PBPM estimator.** `pbpm` is the backward pass that stores photons on camera paths, the photon map, the
//! forward pass that gathers light paths into it, the ghost paths with the pilot that fills the scene's pair
//! table, and the radius schedule; its phases close into the sums of `accumulation`.
//!
//! **Image output.** `image_io` writes multi-layer OpenEXR files (and reads them back, for references) and PNG
//! previews, each replaced atomically; it imports nothing of the crate.
//!
//! **Render sessions and records.** `render` holds a run's settings and counters (`render::totals`), the
//! single-threaded engine that every parallel method must agree with, progressive sessions, images from the
//! sums, checkpoints and the JSON record of a run. It drives the layers below.
//!
//! **Protocol.** `protocol` is the coordinator–worker link: frames, messages, the handshake. It reads only
//! `render::settings`, `render::method` and `scene::description` (what a job asks for) and `render::totals`
//! (what a worker counted); the sums travel as `accumulation::delta` bytes.

pub mod accumulation;
pub mod bsdf;
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
pub mod ray_map;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod spectrum;
pub mod texture;
