//! The boxes that spare rays the analytic surfaces they cannot hit never change an answer: on every shipped scene
//! with analytic surfaces, rays aimed at random points on each surface (from the room, from near the surface,
//! from the other analytic surfaces, and grazing the surface at that point) get bit for bit the hit they get when
//! every surface is solved, and the same occlusion answers. `cargo test --release -p photonfarm --test
//! analytic_bounds`.

use glam::Vec3;
use photonfarm::geometry::{ray::offset_origin, Analytic, Ray, SceneGeometry, SurfaceHit};
use photonfarm::scene::Scene;
use rand_core::{RngCore, SeedableRng};
use rand_pcg::Pcg32;
use std::path::{Path, PathBuf};

/// Rays per surface and kind of origin.
const RAYS: usize = 4_000;

/// A random radius in [inner, outer], uniform over the ring's area, exactly on a rim one time in four (where
/// the boxes are tightest).
fn ring_radius(rng: &mut Pcg32, inner: f32, outer: f32) -> f32 {
    match rng.next_u32() % 8 {
        0 => outer,
        1 => inner,
        _ => (inner * inner + (outer * outer - inner * inner) * crate::common::uniform(rng)).sqrt(),
    }
}

/// A random point on the surface and its unit normal.
fn point_on(surface: &Analytic, rng: &mut Pcg32) -> (Vec3, Vec3) {
    let disc = |rng: &mut Pcg32, axis: Vec3, radius: f32| {
        let (u, v) = axis.any_orthonormal_pair();
        let phi = std::f32::consts::TAU * crate::common::uniform(rng);
        (u * phi.cos() + v * phi.sin()) * radius
    };
    match surface {
        Analytic::Sphere(s) => {
            let n = crate::common::direction(rng);
            (s.center + n * s.radius, n)
        }
        Analytic::Annulus(a) => {
            let rho = ring_radius(rng, a.inner_radius, a.outer_radius);
            (a.center + disc(rng, a.axis, rho), a.axis)
        }
        Analytic::Lens(l) => {
            let r = l.curvature_radius;
            let rho = ring_radius(rng, 0.0, if r == 0.0 { l.aperture_radius } else { l.aperture_radius.min(r.abs()) });
            let off_axis = disc(rng, l.axis, rho);
            if r == 0.0 {
                return (l.vertex + off_axis, l.axis);
            }
            let sag = r - r.signum() * (r * r - rho * rho).max(0.0).sqrt();
            let p = l.vertex + off_axis + l.axis * sag;
            (p, (p - (l.vertex + l.axis * r)).normalize())
        }
    }
}

fn same(a: &Option<SurfaceHit>, b: &Option<SurfaceHit>) -> bool {
    let key =
        |h: &Option<SurfaceHit>| h.map(|h| (h.t.to_bits(), h.object, h.triangle, h.p.to_array().map(f32::to_bits)));
    key(a) == key(b)
}

/// Counts of what the rays met, to show the test asks the hard questions.
#[derive(Default)]
struct Tally {
    rays: usize,
    on_target: usize,
    occluded: usize,
}

fn check(name: &str, culled: &SceneGeometry, every: &SceneGeometry, ray: &Ray, object: u32, tally: &mut Tally) {
    let (a, b) = (culled.intersect(ray), every.intersect(ray));
    assert!(same(&a, &b), "{name}: with the boxes {a:?}, solving every surface {b:?}, for {ray:?}");
    tally.rays += 1;
    tally.on_target += usize::from(b.is_some_and(|h| h.object == object && h.triangle == u32::MAX));
}

fn check_occlusion(name: &str, culled: &SceneGeometry, every: &SceneGeometry, from: Vec3, to: Vec3, t: &mut Tally) {
    let (a, b) = (culled.unoccluded(from, to), every.unoccluded(from, to));
    assert_eq!(a, b, "{name}: unoccluded({from:?}, {to:?}) is {a} with the boxes, {b} solving every surface");
    t.occluded += usize::from(!b);
}

fn scene_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut files = Vec::new();
    for dir in [root.clone(), root.join("stress")] {
        for e in std::fs::read_dir(&dir).expect("the scenes folder").flatten() {
            if e.path().extension().is_some_and(|x| x == "toml") {
                files.push(e.path());
            }
        }
    }
    files.sort();
    files
}

#[test]
fn analytic_culling_returns_every_hit_and_occlusion_that_solving_every_surface_returns() {
    let mut scenes = 0;
    for path in scene_files() {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let g = &scene.geometry;
        let surfaces = g.analytic_surfaces().to_vec();
        if surfaces.is_empty() {
            continue;
        }
        scenes += 1;
        let culled = g.rebuilt_with(g.backend()).unwrap();
        let every = g.rebuilt_with(g.backend()).unwrap().without_analytic_culling();

        // The room: every triangle and analytic surface, and a tenth more around them.
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for i in 0..g.triangle_count() as u32 {
            for v in g.triangle(i).v {
                (lo, hi) = (lo.min(v), hi.max(v));
            }
        }
        for (_, s) in &surfaces {
            let b = s.bounds();
            (lo, hi) = (lo.min(b.min), hi.max(b.max));
        }
        let (lo, hi) = (lo - (hi - lo) * 0.1, hi + (hi - lo) * 0.1);
        let size = (hi - lo).length();
        let mut rng = Pcg32::seed_from_u64(0xb0c5 ^ surfaces.len() as u64);
        let mut tally = Tally::default();
        for (object, surface) in &surfaces {
            let b = surface.bounds();
            let (near_lo, near_hi) = (b.min - (b.max - b.min), b.max + (b.max - b.min));
            for _ in 0..RAYS {
                let (target, n) = point_on(surface, &mut rng);
                let room = lo
                    + (hi - lo)
                        * Vec3::new(
                            crate::common::uniform(&mut rng),
                            crate::common::uniform(&mut rng),
                            crate::common::uniform(&mut rng),
                        );
                let near = near_lo
                    + (near_hi - near_lo)
                        * Vec3::new(
                            crate::common::uniform(&mut rng),
                            crate::common::uniform(&mut rng),
                            crate::common::uniform(&mut rng),
                        );
                // Leaving another analytic surface as the renderer's rays do, from its offset point.
                let (other, other_n) = point_on(&surfaces[rng.next_u32() as usize % surfaces.len()].1, &mut rng);
                let other = offset_origin(other, other_n, target - other);
                for from in [room, near, other] {
                    let d = (target - from).normalize();
                    if !d.is_finite() {
                        continue;
                    }
                    check(&name, &culled, &every, &Ray::new(from, d), *object, &mut tally);
                    // Ending just before and just past the target, as a ray does behind a triangle it hit.
                    let dist = (target - from).length();
                    for t_max in [dist * (1.0 - 1e-6), dist * (1.0 + 1e-6)] {
                        check(&name, &culled, &every, &Ray { t_max, ..Ray::new(from, d) }, *object, &mut tally);
                    }
                    check_occlusion(&name, &culled, &every, from, target + d * 1e-4 * size, &mut tally);
                }
                // Grazing the surface at the target: along its tangent plane, from near and from across the room.
                let tangent = (crate::common::direction(&mut rng).cross(n)).normalize();
                if tangent.is_finite() {
                    for back in
                        [1e-3 * size * crate::common::uniform(&mut rng), size * crate::common::uniform(&mut rng)]
                    {
                        let from = target - tangent * back;
                        check(&name, &culled, &every, &Ray::new(from, tangent), *object, &mut tally);
                        check_occlusion(&name, &culled, &every, from, target + tangent * back, &mut tally);
                    }
                }
                // Along the axes, whose zero components (−0 in −axis) make 0 × ∞ in a careless slab test.
                let axis = [Vec3::X, Vec3::Y, Vec3::Z][rng.next_u32() as usize % 3];
                for d in [axis, -axis] {
                    let back = size * crate::common::uniform(&mut rng);
                    check(&name, &culled, &every, &Ray::new(target - d * back, d), *object, &mut tally);
                }
                // From the surface itself, as a reflected or refracted ray leaves it.
                let d = crate::common::direction(&mut rng);
                let from = offset_origin(target, n, d);
                check(&name, &culled, &every, &Ray::new(from, d), *object, &mut tally);
                check_occlusion(&name, &culled, &every, from, room, &mut tally);
            }
        }
        println!(
            "{name}: {} analytic surfaces, {} rays, {} of them hit the surface aimed at, {} occluded segments",
            surfaces.len(),
            tally.rays,
            tally.on_target,
            tally.occluded
        );
        assert!(
            tally.on_target * 10 > tally.rays,
            "{name}: only {} of {} rays hit their target",
            tally.on_target,
            tally.rays
        );
    }
    assert!(scenes >= 4, "only {scenes} shipped scenes have analytic surfaces");
}
