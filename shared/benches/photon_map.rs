//! The backward photon map of one PBPM phase of `scenes/cornell.toml` (256×256, the scene's own settings, phase
//! 64, seed 1): building the grid over the photons of a real backward pass, sequentially and with
//! `build_parallel` in rayon pools of 1 and 2 threads, and gathering the vertices of a real forward pass into
//! it: the whole `gather` of each vertex as it comes, the same vertices held back and gathered in the map's
//! bucket order (`SortedGathers`, as the single-threaded engine's forward pass does, its sorts included), and
//! the `containing` lookup alone.
//!
//! `cargo bench -p photonfarm --bench photon_map` — criterion prints elements/s = photons/s for the builds and
//! light vertices/s for the gathers; the photon, vertex and merge counts are printed once.

use criterion::{criterion_group, criterion_main, Criterion, SamplingMode, Throughput};
use glam::Vec3;
use photonfarm::color::Rgb;
use photonfarm::geometry::SurfaceHit;
use photonfarm::integrator::Layer;
use photonfarm::pbpm::backward_pass::BackwardStats;
use photonfarm::pbpm::photon::PhotonLists;
use photonfarm::pbpm::{
    gather, trace_camera_path, trace_light_path, BackwardPhoton, BackwardSettings, ForwardStats, GatherPoint,
    LightEvent, LightSettings, LightVertex, PhotonMap, SortedGathers,
};
use photonfarm::ray_map::Unrecorded;
use photonfarm::render::{Method, RenderSettings};
use photonfarm::sampling::{Pass, Sampler};
use photonfarm::scene::Scene;
use photonfarm::spectrum::PhaseSpectrum;
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

const SEED: u64 = 1;
/// A phase typical of a render (10 s of `cornell` on one thread run about 70 phases), not the first: radii shrink
/// with the phase, and phase 1 finds four times as many photons per light vertex as phase 64.
const PHASE: u64 = 64;

/// A light vertex that owns its hit: `LightVertex` borrows it from the light path being traced, and the bench
/// gathers the same vertices many times after the paths are gone.
struct OwnedVertex {
    hit: SurfaceHit,
    wi: Vec3,
    flux: Rgb,
    m: u32,
    all_specular: bool,
}

impl OwnedVertex {
    fn view(&self) -> LightVertex<'_> {
        LightVertex {
            hit: &self.hit,
            wi: self.wi,
            flux: self.flux,
            m: self.m,
            all_specular: self.all_specular,
            all_pass: self.all_specular,
            spectrum: 0,
            phase: &PhaseSpectrum::RGB,
        }
    }
}

fn cornell() -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell.toml");
    Scene::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// The photons of one backward pass over the whole image, as the single-threaded engine makes them.
fn backward_photons(scene: &Scene, settings: &RenderSettings) -> Vec<BackwardPhoton> {
    let cam = &scene.camera;
    let bs = BackwardSettings {
        max_depth: settings.max_depth,
        backward_diffuse_depth: settings.backward_diffuse_depth,
        radius: settings.radius_schedule(scene),
        phase: PHASE,
        spectrum: PhaseSpectrum::RGB,
        sensor_ghosts: false,
    };
    let (mut photons, mut vertices) = (Vec::new(), Vec::new());
    let mut stats = BackwardStats::default();
    for pixel in 0..cam.pixel_count() {
        let (x, y) = ((pixel % cam.width as usize) as u32, (pixel / cam.width as usize) as u32);
        let mut s = Sampler::new(settings.seed, Pass::Camera, PHASE, pixel as u64);
        let ray = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
        let store = &mut PhotonLists { photons: &mut photons, vertices: &mut vertices };
        trace_camera_path(scene, &bs, pixel as u32, ray, &mut s, &mut stats, store, &mut Unrecorded);
    }
    photons
}

/// The diffuse vertices (m ≥ 2) of one phase's light paths, the points the forward pass gathers at.
fn light_vertices(scene: &Scene, settings: &RenderSettings) -> Vec<OwnedVertex> {
    let mut vertices = Vec::new();
    let mut stats = ForwardStats::default();
    for i in 0..settings.light_paths_per_phase(scene.camera.pixel_count()) {
        let mut s = Sampler::new(settings.seed, Pass::Light, PHASE, i);
        let light = LightSettings { max_depth: settings.max_depth, sensor: false, vertices: true, ghost_paths: 0 };
        trace_light_path(
            scene,
            light,
            &PhaseSpectrum::RGB,
            i,
            &mut s,
            &mut stats,
            &mut |e: &LightEvent| {
                if let LightEvent::Vertex(v) = e {
                    vertices.push(OwnedVertex {
                        hit: *v.hit,
                        wi: v.wi,
                        flux: v.flux,
                        m: v.m,
                        all_specular: v.all_specular,
                    })
                }
            },
            &mut Unrecorded,
        );
    }
    vertices
}

fn photon_map(c: &mut Criterion) {
    let scene = cornell();
    let settings = RenderSettings::for_scene(&scene, Method::Pbpm, SEED);
    let photons = backward_photons(&scene, &settings);
    let vertices = light_vertices(&scene, &settings);
    let mut map = PhotonMap::new();
    map.extend(&photons);
    map.build();

    let (max_depth, bdd) = (settings.max_depth, settings.backward_diffuse_depth);
    // The engine's sink: per-pixel (indirect, caustic) sums.
    let mut gathered = vec![[Rgb::ZERO; 2]; scene.camera.pixel_count()];
    let mut sink = |pixel: u32, layer: Layer, _ghost: bool, v: Rgb| {
        gathered[pixel as usize][(layer == Layer::Caustic) as usize] += v
    };
    let merges: u64 = vertices.iter().map(|v| gather(&map, &v.view(), max_depth, bdd, &mut sink)).sum();
    let candidates: usize = vertices.iter().map(|v| map.containing(v.hit.p).count()).sum();
    eprintln!(
        "cornell 256×256, phase {PHASE}: {} backward photons, {} light vertices, {} photons containing a vertex, \
         {merges} merges",
        photons.len(),
        vertices.len(),
        candidates
    );

    let mut group = c.benchmark_group("photon_map_cornell");
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Elements(photons.len() as u64));
    // Rebuilding over the same photons reuses the map's buffers, as every phase after the first does.
    group.bench_function("build", |b| {
        b.iter(|| {
            map.build();
            black_box(&map);
        })
    });
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("rayon pool");
        group.bench_function(format!("build_parallel_{threads}_threads"), |b| {
            b.iter(|| {
                pool.install(|| map.build_parallel());
                black_box(&map);
            })
        });
    }

    // A whole phase's gathers take about 0.1 s, too long for criterion's linear sampling within 3 s.
    group.sampling_mode(SamplingMode::Flat);
    group.throughput(Throughput::Elements(vertices.len() as u64));
    group.bench_function("gather", |b| {
        b.iter(|| vertices.iter().map(|v| gather(&map, black_box(&v.view()), max_depth, bdd, &mut sink)).sum::<u64>())
    });
    let points: Vec<GatherPoint> = vertices.iter().map(|v| v.view().point()).collect();
    let mut sorted = SortedGathers::new();
    group.bench_function("gather_sorted", |b| {
        b.iter(|| {
            let mut merges = 0;
            for &v in &points {
                sorted.push(&map, black_box(v));
                if sorted.room() == 0 {
                    merges += sorted.gather_into(&map, &PhaseSpectrum::RGB, max_depth, bdd, &mut sink);
                }
            }
            merges + sorted.gather_into(&map, &PhaseSpectrum::RGB, max_depth, bdd, &mut sink)
        })
    });
    group.bench_function("containing", |b| {
        b.iter(|| vertices.iter().map(|v| map.containing(black_box(v.hit.p)).count()).sum::<usize>())
    });
    group.finish();
}

criterion_group!(benches, photon_map);
criterion_main!(benches);
