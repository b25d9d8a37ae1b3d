//! The Embree backend (the `embree` feature) returns the hits obvhs returns, with each of its build presets: on
//! random rays over every shipped scene's geometry, the same hit or miss, object, triangle, distance and
//! normals, but for rare numerical ties (`Comparison`), and the same occlusion answers, every one. `cargo test -p photonfarm --features embree --test backend_agreement`.

#![cfg(feature = "embree")]

mod common;

use glam::Vec3;
use photonfarm::geometry::{ray::offset_origin, Backend, ObvhsPreset, Ray, SceneGeometry, SurfaceHit};
use photonfarm::scene::Scene;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;
use std::path::Path;

/// Random rays per kind and scene.
const RAYS: usize = 20_000;

/// The smallest barycentric coordinate of the hit point in its triangle: near 0 on an edge, where either of two
/// triangles may take the ray.
fn edge_distance(g: &SceneGeometry, h: &SurfaceHit) -> f32 {
    if h.triangle == u32::MAX {
        return f32::INFINITY;
    }
    let [a, b, c] = g.triangle(h.triangle).v;
    let n = (b - a).cross(c - a);
    let area = n.length_squared();
    let u = (c - b).cross(h.p - b).dot(n) / area;
    let v = (a - c).cross(h.p - c).dot(n) / area;
    u.min(v).min(1.0 - u - v)
}

/// How the two backends' answers to the rays compare. Two kinds of difference are numerical and allowed, in
/// small numbers: a ray that grazes a triangle edge, where either of two triangles may take it; and coincident
/// surfaces (a box standing on a floor), where either may win the tie. A hit just past the ray's origin that one
/// backend misses (obvhs's traversal did, before `geometry::accel` started it further back) fails, as does any
/// other difference.
#[derive(Default)]
struct Comparison {
    rays: usize,
    hits: usize,
    grazing: usize,
    coincident: usize,
    near_origin: usize,
}

impl Comparison {
    fn closest(&mut self, scene: &str, obvhs: &SceneGeometry, embree: &SceneGeometry, ray: &Ray, near: f32) {
        self.rays += 1;
        let (a, b) = (obvhs.intersect(ray), embree.intersect(ray));
        match (&a, &b) {
            (None, None) => return,
            (Some(a), Some(b)) if a.object == b.object && a.triangle == b.triangle => {
                self.hits += 1;
                let close = |x: Vec3, y: Vec3, tol: f32| (x - y).length() <= tol;
                // Embree's robust mode takes t from the ray's sheared coordinates, which lose a few dozen ulps of
                // the coordinates' size on a hit near the origin.
                let t_tolerance = 1e-4 * a.t.max(1e-3) + 64.0 * f32::EPSILON * ray.origin.abs().max_element();
                assert!(
                    (a.t - b.t).abs() <= t_tolerance
                        && close(a.ng, b.ng, 1e-4)
                        && close(a.ns, b.ns, 1e-3)
                        && close(a.p, b.p, 1e-4 * (1.0 + a.p.abs().max_element())),
                    "{scene}: the backends hit the same surface differently: {a:?} against {b:?} for {ray:?}"
                );
                return;
            }
            _ => {}
        }
        if [(&a, obvhs), (&b, embree)].into_iter().any(|(h, g)| h.as_ref().is_some_and(|h| edge_distance(g, h) < 1e-4))
        {
            self.grazing += 1;
        } else if matches!((&a, &b), (Some(x), Some(y)) if (x.t - y.t).abs() <= 1e-5 * x.t) {
            self.coincident += 1;
        } else if [&a, &b].into_iter().flatten().map(|h| h.t).fold(f32::INFINITY, f32::min) < near {
            self.near_origin += 1;
        } else {
            panic!("{scene}: obvhs hits {a:?} and Embree {b:?} for {ray:?}, away from edges, ties and the origin");
        }
    }
}

fn compare_scene(name: &str, scene: &Scene, preset: ObvhsPreset) {
    let embree = &scene.geometry.rebuilt_with(Backend::Embree).unwrap_or_else(|e| panic!("{e}"));
    let obvhs = scene.geometry.rebuilt_with(Backend::Obvhs(preset)).unwrap_or_else(|e| panic!("{e}"));
    let count = embree.triangle_count();
    assert!(count > 0, "{name} has no triangles to compare");

    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for i in 0..count as u32 {
        for v in embree.triangle(i).v {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    let margin = (hi - lo) * 0.1;
    // "Just past the origin": within a thousandth of the scene's size.
    let near = 1e-3 * (hi - lo).max_element();
    let (lo, hi) = (lo - margin, hi + margin);
    let mut rng = Pcg32::seed_from_u64(0x5eed ^ count as u64);
    let mut cmp = Comparison::default();
    let mut occlusion_differs = 0;
    for _ in 0..RAYS {
        // From anywhere in (and around) the scene's box, in every direction.
        let o =
            lo + (hi - lo) * Vec3::new(common::uniform(&mut rng), common::uniform(&mut rng), common::uniform(&mut rng));
        cmp.closest(name, &obvhs, embree, &Ray::new(o, common::direction(&mut rng)), near);

        // Leaving a random triangle from its offset surface point, as the renderer's rays do (the t_min rule).
        let i = (rng.next_u32() as usize % count) as u32;
        let [a, b, c] = embree.triangle(i).v;
        let (mut u, mut v) = (common::uniform(&mut rng), common::uniform(&mut rng));
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        let p = a + (b - a) * u + (c - a) * v;
        let ng = (b - a).cross(c - a).normalize();
        let d = common::direction(&mut rng);
        let from = offset_origin(p, ng, d);
        cmp.closest(name, &obvhs, embree, &Ray::new(from, d), near);

        // Occlusion between that point and a random point of the box.
        let to =
            lo + (hi - lo) * Vec3::new(common::uniform(&mut rng), common::uniform(&mut rng), common::uniform(&mut rng));
        let from = offset_origin(p, ng, to - p);
        if obvhs.unoccluded(from, to) != embree.unoccluded(from, to) {
            occlusion_differs += 1;
        }
    }
    println!(
        "{name}, obvhs {preset:?}: {count} triangles, {} rays, {} hits; {} grazing an edge, {} on coincident \
         surfaces, {} just past the origin; {occlusion_differs} of {RAYS} occlusion answers differ",
        cmp.rays, cmp.hits, cmp.grazing, cmp.coincident, cmp.near_origin
    );
    assert!(cmp.hits * 10 > cmp.rays, "{name}: too few rays hit ({} of {}) to compare", cmp.hits, cmp.rays);
    // A ray lands within 1e-4 of an edge with a probability of about 1e-4 per edge it crosses.
    assert!(cmp.grazing * 1000 <= cmp.rays, "{name}: {} of {} rays differ at edges", cmp.grazing, cmp.rays);
    assert_eq!(cmp.near_origin, 0, "{name}: {} of {} rays differ near the origin", cmp.near_origin, cmp.rays);
    // Both backends' triangle tests are watertight: an occlusion answer that differs is a ray that leaked.
    assert_eq!(occlusion_differs, 0, "{name}: {occlusion_differs} of {RAYS} occlusion answers differ");
}

/// A shipped scene, for its geometry. An RGB-only build (CI runs this test in one, beside the RGB-only checks,
/// to build the library once for both) refuses dispersive glass, which changes no surface: it reads those
/// scenes without their Abbe numbers.
fn load_geometry(name: &str) -> Scene {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let path = dir.join(name);
    if cfg!(feature = "spectral") {
        return Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    }
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let dispersive = |l: &&str| {
        ["abbe", "ext_abbe"]
            .iter()
            .any(|k| l.trim_start().strip_prefix(k).is_some_and(|r| r.trim_start().starts_with('=')))
    };
    let text: String = text.lines().filter(|l| !dispersive(l)).map(|l| format!("{l}\n")).collect();
    Scene::from_toml(&text, &path, &dir).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn embree_and_every_obvhs_preset_agree_on_every_shipped_scene() {
    let mut names: Vec<String> = std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes"))
        .expect("the scenes folder")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 4, "found only {names:?}");
    for name in &names {
        let scene = load_geometry(name);
        if scene.geometry.triangle_count() == 0 {
            println!("{name}: analytic surfaces only, traced by neither backend");
            continue;
        }
        for preset in ObvhsPreset::ALL {
            compare_scene(name, &scene, preset);
        }
    }
}
