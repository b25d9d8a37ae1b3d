//! Ray-tracing throughput on a mesh of about one million triangles, one core: coherent primary rays from a
//! camera and incoherent rays between random points, the two extremes a renderer's rays fall between. Every
//! backend the build has traces the same rays through `SceneGeometry`, after a check that they return the same
//! hits.
//!
//! `cargo bench -p photonfarm --bench ray_tracing` (obvhs), `... --features embree` (obvhs and Embree side by
//! side); `PHOTONFARM_BVH=obvhs-medium` adds that backend — criterion prints elements/s = rays/s.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::{Vec2, Vec3};
use photonfarm::camera::{Camera, Lens};
use photonfarm::geometry::{Backend, MeshTriangle, ObvhsPreset, Ray, SceneGeometry};
use photonfarm::sampling::{uniform_sphere, Pass, Sampler};
use std::hint::black_box;

/// A bumpy sphere of 2 · 512 · 1024 ≈ 1.05 M triangles (radius ≈ 1), so that rays see real depth complexity.
fn bumpy_sphere() -> Vec<(u32, MeshTriangle)> {
    let (rings, segments) = (512usize, 1024usize);
    let point = |i: usize, j: usize| {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        let phi = 2.0 * std::f32::consts::PI * j as f32 / segments as f32;
        let r = 1.0 + 0.03 * (7.0 * theta).sin() * (11.0 * phi).cos();
        Vec3::new(r * theta.sin() * phi.cos(), r * theta.cos(), r * theta.sin() * phi.sin())
    };
    let mut tris = Vec::with_capacity(2 * rings * segments);
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (point(i, j), point(i + 1, j), point(i + 1, j + 1), point(i, j + 1));
            for v in [[a, b, c], [a, c, d]] {
                let t = MeshTriangle { v, n: None };
                if t.area() > 1e-12 {
                    tris.push((0, t));
                }
            }
        }
    }
    tris
}

/// Rays on which `other` disagrees with `reference` (hit or miss, or another triangle), and the largest
/// relative difference of t where both hit the same triangle.
fn disagreements(reference: &SceneGeometry, other: &SceneGeometry, rays: &[Ray]) -> (usize, f32) {
    let (mut differ, mut max_dt) = (0, 0.0f32);
    for r in rays {
        match (reference.intersect(r), other.intersect(r)) {
            (None, None) => {}
            (Some(a), Some(b)) if a.triangle == b.triangle => max_dt = max_dt.max((a.t - b.t).abs() / a.t),
            _ => differ += 1,
        }
    }
    (differ, max_dt)
}

fn ray_tracing(c: &mut Criterion) {
    let tris = bumpy_sphere();
    let count = tris.len();
    assert!(count >= 1_000_000, "benchmark mesh has only {count} triangles");
    // obvhs with its default preset, Embree when the build has it, and the backend PHOTONFARM_BVH names.
    let mut backends: Vec<Backend> =
        Backend::all().into_iter().filter(|b| !matches!(b, Backend::Obvhs(p) if *p != ObvhsPreset::DEFAULT)).collect();
    let asked = Backend::from_env().unwrap_or_else(|e| panic!("{e}"));
    if !backends.contains(&asked) {
        backends.push(asked);
    }
    let geometries: Vec<(Backend, SceneGeometry)> = backends
        .into_iter()
        .map(|b| (b, SceneGeometry::build_with(b, tris.clone(), vec![]).unwrap_or_else(|e| panic!("{e}"))))
        .collect();

    let camera = Camera::new(Vec3::new(0.0, 0.3, -3.0), Vec3::ZERO, Vec3::Y, 40.0, 512, 512, Lens::Pinhole);
    let primary: Vec<Ray> = (0..512 * 512)
        .map(|i| camera.generate_ray((i % 512) as u32, (i / 512) as u32, Vec2::splat(0.5), Vec2::ZERO).ray)
        .collect();
    let mut s = Sampler::new(1, Pass::Light, 1, 1);
    let incoherent: Vec<Ray> = (0..512 * 512)
        .map(|_| {
            let from = uniform_sphere(s.next_2d()) * 1.5;
            let to = uniform_sphere(s.next_2d()) * 0.5;
            Ray::new(from, (to - from).normalize())
        })
        .collect();

    let (reference_backend, reference) = &geometries[0];
    for (backend, geometry) in &geometries[1..] {
        for (name, rays) in [("primary", &primary), ("incoherent", &incoherent)] {
            let (differ, max_dt) = disagreements(reference, geometry, rays);
            println!(
                "{} against {}, {name} rays: {differ} of {} differ in hit or triangle, t within {max_dt:.1e} \
                 (relative) on the others",
                backend.name(),
                reference_backend.name(),
                rays.len()
            );
            // Rays that graze an edge shared by two triangles may be given to either: a handful of the 262,144,
            // never more.
            assert!(differ * 10_000 < rays.len(), "the backends disagree on {differ} {name} rays");
            assert!(max_dt < 1e-4, "the backends' distances differ by up to {max_dt} (relative)");
        }
    }

    let mut group = c.benchmark_group(format!("closest_hit_{count}_triangles"));
    group.sample_size(10);
    for (backend, geometry) in &geometries {
        let name = backend.name();
        group.throughput(Throughput::Elements(primary.len() as u64));
        group.bench_function(format!("{name}/primary_rays"), |b| {
            b.iter(|| primary.iter().filter(|r| geometry.intersect(black_box(r)).is_some()).count())
        });
        group.throughput(Throughput::Elements(incoherent.len() as u64));
        group.bench_function(format!("{name}/incoherent_rays"), |b| {
            b.iter(|| incoherent.iter().filter(|r| geometry.intersect(black_box(r)).is_some()).count())
        });
        group.bench_function(format!("{name}/incoherent_shadow_rays"), |b| {
            b.iter(|| incoherent.iter().filter(|r| geometry.unoccluded(r.origin, r.at(2.0))).count())
        });
    }
    group.finish();
}

criterion_group!(benches, ray_tracing);
criterion_main!(benches);
