//! Infinite lights and emitting analytic shapes against closed-form answers: a convex body in a constant
//! environment (a furnace: light leaving it never returns), whose pixels show ρ L for a diffuse surface and the
//! directional albedo times L for a glossy one, in PBPM and the path tracer; the environment itself where paths
//! leave the scene; and the irradiance an emitting sphere or disc and a sun give a plane. Tolerances are 4
//! standard errors of the per-phase region means, with fixed seeds.

use crate::common::{mean_sem, region_phase_means, scene, settings};
use glam::Vec2;
use photonfarm::bsdf::{Reflection, Transport};
use photonfarm::color::luminance_f64;
use photonfarm::integrator::Layer;
use photonfarm::render::{Engine, Method};
use photonfarm::sampling::{Pass, Sampler};
use photonfarm::scene::Scene;

/// A sphere of material `material` (TOML of one `[materials.body]` table) at the origin, radius 1, in a constant
/// environment of radiance `l`, seen from z = 4.
fn furnace(material: &str, l: f32) -> String {
    format!(
        "[camera]\nposition = [0.0, 0.0, 4.0]\nlook_at = [0.0, 0.0, 0.0]\nfov_y_deg = 36\nwidth = 32\nheight = 32\n\
         [materials.body]\n{material}\n\
         [[objects]]\nmaterial = \"body\"\nsphere = {{ center = [0.0, 0.0, 0.0], radius = 1.0 }}\n\
         [[lights]]\ntype = \"environment\"\nradiance = [{l}, {l}, {l}]\n"
    )
}

/// The pixels whose whole footprint sees the sphere (`on` true) or misses it (`on` false): all four corners and
/// the centre agree.
fn pixels_seeing(sc: &Scene, on: bool) -> Vec<usize> {
    let cam = &sc.camera;
    let corners = [(0.001, 0.001), (0.999, 0.001), (0.001, 0.999), (0.999, 0.999), (0.5, 0.5)];
    (0..cam.pixel_count())
        .filter(|&i| {
            let (x, y) = ((i % cam.width as usize) as u32, (i / cam.width as usize) as u32);
            corners.iter().all(|&(a, b)| {
                let r = cam.generate_ray(x, y, Vec2::new(a, b), Vec2::splat(0.5));
                sc.geometry.intersect(&r.ray).is_some() == on
            })
        })
        .collect()
}

/// The region's mean luminance per phase over `phases` phases of `method`, as (mean, SEM).
fn region_estimate(
    sc: &Scene,
    method: Method,
    seed: u64,
    phases: usize,
    pixels: &[usize],
    layer: Option<Layer>,
) -> (f64, f64) {
    let mut engine = Engine::new(sc, settings(sc, method, seed));
    let set: std::collections::HashSet<usize> = pixels.iter().copied().collect();
    let w = sc.camera.width;
    let samples = region_phase_means(&mut engine, phases, layer, &|x, y| set.contains(&((y * w + x) as usize)));
    mean_sem(&samples)
}

fn assert_within(what: &str, (mean, sem): (f64, f64), (expect, expect_sem): (f64, f64)) {
    let bound = 4.0 * (sem * sem + expect_sem * expect_sem).sqrt();
    eprintln!("{what}: {mean:.5} ± {sem:.5} vs {expect:.5} ± {expect_sem:.5} ({:.2} σ)", (mean - expect) / bound * 4.0);
    assert!((mean - expect).abs() <= bound, "{what}: {mean} ± {sem}, expected {expect} ± {expect_sem}");
    assert!(sem < 0.01 * expect, "{what}: the estimate's error {sem} is too large to test anything");
}

#[test]
fn a_diffuse_sphere_in_a_constant_environment_shows_albedo_times_radiance_and_the_background_its_radiance() {
    let (rho, l) = (0.6, 0.8);
    let sc = scene(&furnace(&format!("type = \"diffuse\"\nalbedo = [{rho}, {rho}, {rho}]"), l));
    let (on, off) = (pixels_seeing(&sc, true), pixels_seeing(&sc, false));
    assert!(on.len() > 200 && off.len() > 200, "{} pixels on the sphere, {} off", on.len(), off.len());
    for (method, seed) in [(Method::Pbpm, 3), (Method::Path, 4)] {
        let sphere = region_estimate(&sc, method, seed, 200, &on, None);
        assert_within(&format!("{method:?}, sphere"), sphere, ((rho * l) as f64, 0.0));
        // The background is the environment seen directly: exact in every phase.
        let (bg, _) = region_estimate(&sc, method, seed, 4, &off, Some(Layer::VisibleLights));
        assert!((bg - l as f64).abs() < 1e-5, "{method:?}: background {bg}, environment {l}");
    }
}

/// The mean over `pixels` of L times the directional albedo of the surface the pixel sees, by sampling the
/// BSDF (whose weight f cos / pdf has the albedo as its expectation) at random points of the pixels, with its
/// standard error.
fn albedo_reference(sc: &Scene, pixels: &[usize], l: f64, n: usize) -> (f64, f64) {
    let cam = &sc.camera;
    let mut s = Sampler::new(77, Pass::Light, 0, 0);
    let mut values = Vec::with_capacity(n);
    for k in 0..n {
        let i = pixels[k % pixels.len()];
        let (x, y) = ((i % cam.width as usize) as u32, (i / cam.width as usize) as u32);
        let r = cam.generate_ray(x, y, s.next_2d(), s.next_2d());
        let hit = sc.geometry.intersect(&r.ray).expect("the pixel sees the sphere");
        let wo = -r.ray.direction;
        let bsdf = sc.bsdf(&hit, wo);
        let v = match bsdf.sample_reflecting(wo, s.next_2d(), Transport::Radiance, Reflection::Fresnel) {
            Some(b) => luminance_f64([b.weight.x as f64, b.weight.y as f64, b.weight.z as f64]) * l,
            None => 0.0,
        };
        values.push(v * r.weight as f64);
    }
    mean_sem(&values)
}

#[test]
fn a_glossy_sphere_in_a_constant_environment_shows_its_directional_albedo() {
    let l = 1.5;
    // A rough perfect conductor loses energy to masking, more at grazing angles: its albedo is below 1 and
    // varies over the sphere.
    let material = "type = \"conductor\"\nmaterial = \"none\"\nalpha = 0.5\ndistribution = \"ggx\"";
    let sc = scene(&furnace(material, l));
    let on = pixels_seeing(&sc, true);
    let reference = albedo_reference(&sc, &on, l as f64, 400_000);
    assert!(reference.0 < 0.97 * l as f64, "the test needs an albedo visibly below 1: {}", reference.0 / l as f64);
    for (method, seed) in [(Method::Pbpm, 5), (Method::Path, 6)] {
        let sphere = region_estimate(&sc, method, seed, 200, &on, None);
        assert_within(&format!("{method:?}, glossy sphere"), sphere, reference);
    }
}

/// A shipped outdoor scene at `width` × `height` pixels.
fn outdoor(name: &str, width: u32, height: u32) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    let text = text.replace("width = 320\nheight = 240", &format!("width = {width}\nheight = {height}"));
    assert!(text.contains(&format!("width = {width}\n")), "{name} no longer has the 320 × 240 camera");
    scene(&text)
}

/// Per pixel, the mean luminance of the total over `batches` × `per_batch` phases and its standard error from
/// the spread of the batches' means (the batches are independent, unlike the quasi-random phases of a pixel).
fn pixel_estimates(sc: &Scene, method: Method, seed: u64, batches: usize, per_batch: usize) -> Vec<(f64, f64)> {
    let mut engine = Engine::new(sc, settings(sc, method, seed));
    let pixels = sc.camera.pixel_count();
    let total = |e: &Engine| -> Vec<f64> {
        (0..pixels).map(|p| e.sums().pixels[p].sum.iter().map(|l| luminance_f64(*l)).sum()).collect()
    };
    let mut before = vec![0.0; pixels];
    let mut means = vec![Vec::with_capacity(batches); pixels];
    for _ in 0..batches {
        for _ in 0..per_batch {
            engine.run_phase();
        }
        let now = total(&engine);
        for p in 0..pixels {
            means[p].push((now[p] - before[p]) / per_batch as f64);
        }
        before = now;
    }
    means.iter().map(|m| mean_sem(m)).collect()
}

/// PBPM and the path tracer agree per pixel on `sc`: the mean over pixels of z² = (a − b)² / (SEM_a² + SEM_b²)
/// lies within 4 standard deviations of its expectation 1 (z² has variance 2), and the image sums agree within
/// 4 standard errors.
fn assert_pbpm_converges_to_the_path_tracer(sc: &Scene, batches: usize, pbpm_per_batch: usize, path_per_batch: usize) {
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| pixel_estimates(sc, Method::Pbpm, 21, batches, pbpm_per_batch));
        let b = pixel_estimates(sc, Method::Path, 22, batches, path_per_batch);
        (a.join().unwrap(), b)
    });
    let z2: Vec<f64> = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| x.1 > 0.0 || y.1 > 0.0)
        .map(|(x, y)| (x.0 - y.0).powi(2) / (x.1 * x.1 + y.1 * y.1))
        .collect();
    let n = z2.len() as f64;
    let mean_z2 = z2.iter().sum::<f64>() / n;
    let bound = 1.0 + 4.0 * (2.0 / n).sqrt();
    let sum = |e: &[(f64, f64)]| (e.iter().map(|p| p.0).sum::<f64>(), e.iter().map(|p| p.1 * p.1).sum::<f64>().sqrt());
    let (sa, sb) = (sum(&a), sum(&b));
    eprintln!(
        "{}: mean z² {mean_z2:.3} over {n} pixels (bound {bound:.3}); image PBPM {:.3} ± {:.3}, path {:.3} ± {:.3}",
        sc.path.display(),
        sa.0,
        sa.1,
        sb.0,
        sb.1
    );
    assert!(n > 0.9 * sc.camera.pixel_count() as f64, "only {n} pixels have light");
    assert!(mean_z2 < bound, "mean z² {mean_z2} exceeds {bound}");
    assert!((sa.0 - sb.0).abs() < 4.0 * (sa.1 * sa.1 + sb.1 * sb.1).sqrt(), "the image sums differ");
}

#[test]
fn pbpm_converges_per_pixel_to_the_path_tracer_on_the_outdoor_scene_lit_by_a_sky_map() {
    assert_pbpm_converges_to_the_path_tracer(&outdoor("outdoor.toml", 32, 24), 40, 25, 25);
}

#[test]
fn pbpm_converges_per_pixel_to_the_path_tracer_on_the_outdoor_scene_lit_by_a_sun_and_a_constant_sky() {
    assert_pbpm_converges_to_the_path_tracer(&outdoor("outdoor-sun.toml", 32, 24), 40, 25, 25);
}

/// A grey floor (albedo `RHO`) at y = 0 seen from above and lit by `light` alone (TOML: a black emitting object
/// or a `[[lights]]` table).
fn lit_floor(light: &str) -> Scene {
    scene(&format!(
        "[camera]\nposition = [0.0, 3.0, 3.0]\nlook_at = [0.0, 0.0, 0.0]\nfov_y_deg = 40\nwidth = 24\nheight = 24\n\
         [materials.floor]\ntype = \"diffuse\"\nalbedo = [{RHO}, {RHO}, {RHO}]\n\
         [materials.black]\ntype = \"diffuse\"\nalbedo = [0.0, 0.0, 0.0]\n\
         [[objects]]\nmaterial = \"floor\"\nquad = {{ corner = [-5.0, 0.0, -5.0], edge1 = [0.0, 0.0, 10.0], edge2 = [10.0, 0.0, 0.0] }}\n\
         {light}\n"
    ))
}

const RHO: f32 = 0.7;

/// The pixels whose whole footprint sees object 0 (the floor).
fn floor_pixels(sc: &Scene) -> Vec<usize> {
    let cam = &sc.camera;
    let corners = [(0.001, 0.001), (0.999, 0.001), (0.001, 0.999), (0.999, 0.999), (0.5, 0.5)];
    (0..cam.pixel_count())
        .filter(|&i| {
            let (x, y) = ((i % cam.width as usize) as u32, (i / cam.width as usize) as u32);
            corners.iter().all(|&(a, b)| {
                let r = cam.generate_ray(x, y, Vec2::new(a, b), Vec2::splat(0.5));
                sc.geometry.intersect(&r.ray).is_some_and(|h| h.object == 0)
            })
        })
        .collect()
}

/// The mean over `pixels` of the floor's radiance ρ/π · E(x), E the irradiance `irradiance` gives at the floor
/// point x, from uniform points of the pixels (a quadrature of far smaller error than the renders').
fn floor_reference(sc: &Scene, pixels: &[usize], irradiance: impl Fn(glam::Vec3) -> f64) -> f64 {
    let cam = &sc.camera;
    let n = 64;
    let mut sum = 0.0;
    for &i in pixels {
        let (x, y) = ((i % cam.width as usize) as u32, (i / cam.width as usize) as u32);
        for k in 0..n {
            let jitter = Vec2::new(((k % 8) as f32 + 0.5) / 8.0, ((k / 8) as f32 + 0.5) / 8.0);
            let r = cam.generate_ray(x, y, jitter, Vec2::splat(0.5));
            let hit = sc.geometry.intersect(&r.ray).unwrap();
            sum += RHO as f64 / std::f64::consts::PI * irradiance(hit.p);
        }
    }
    sum / (n * pixels.len()) as f64
}

fn check_floor(sc: &Scene, irradiance: impl Fn(glam::Vec3) -> f64, what: &str) {
    let pixels = floor_pixels(sc);
    assert!(pixels.len() > 300, "{what}: {} floor pixels", pixels.len());
    let expect = floor_reference(sc, &pixels, irradiance);
    for (method, seed) in [(Method::Pbpm, 7), (Method::Path, 8)] {
        let got = region_estimate(sc, method, seed, 150, &pixels, None);
        assert_within(&format!("{method:?}, {what}"), got, (expect, 0.0));
    }
}

#[test]
fn an_emitting_sphere_lights_a_floor_as_a_point_of_intensity_pi_r2_l() {
    // Outside a uniformly bright sphere (radius R, radiance L) wholly above the horizon, E = π L R² cos θ / D².
    let (c, r, l) = (glam::Vec3::new(0.8, 1.2, -0.5), 0.4f32, 6.0f32);
    let sc = lit_floor(&format!(
        "[[objects]]\nmaterial = \"black\"\nemission = [{l}, {l}, {l}]\nsphere = {{ center = {:?}, radius = {r} }}",
        c.to_array()
    ));
    check_floor(
        &sc,
        |p| {
            let d = c - p;
            (std::f32::consts::PI * l * r * r * d.y / d.length().powi(3)) as f64
        },
        "sphere",
    );
}

#[test]
fn an_emitting_disc_lights_a_floor_as_the_integral_over_its_area() {
    // A disc facing down (its normal, −axis, is −y) at height h: E = ∫ L cos θ_x cos θ_l / d² dA, by quadrature.
    let (c, radius, l) = (glam::Vec3::new(-0.6, 1.0, 0.3), 0.5f32, 4.0f32);
    let sc = lit_floor(&format!(
        "[[objects]]\nmaterial = \"black\"\nemission = [{l}, {l}, {l}]\n\
         annulus = {{ center = {:?}, axis = [0.0, 1.0, 0.0], inner_radius = 0.0, outer_radius = {radius} }}",
        c.to_array()
    ));
    check_floor(
        &sc,
        |p| {
            let (nr, nphi) = (48, 96);
            let mut e = 0.0f64;
            for i in 0..nr {
                for j in 0..nphi {
                    // Equal-area cells: r = R √((i + ½)/n).
                    let rr = radius * ((i as f32 + 0.5) / nr as f32).sqrt();
                    let phi = std::f32::consts::TAU * (j as f32 + 0.5) / nphi as f32;
                    let q = c + glam::Vec3::new(rr * phi.cos(), 0.0, rr * phi.sin());
                    let d = q - p;
                    let cos2 = (d.y / d.length()).powi(2);
                    e += (l * cos2 / d.length_squared()) as f64;
                }
            }
            e * (std::f32::consts::PI * radius * radius) as f64 / (nr * nphi) as f64
        },
        "disc",
    );
}

#[test]
fn a_sun_with_an_angular_radius_gives_its_irradiance_times_the_cosine() {
    // A uniform cone of directions wholly above the horizon gives E_sun cos θ_sun: ∫ ω dω over it is π sin²α
    // along its axis.
    let direction = glam::Vec3::new(-0.3, -1.0, -0.2);
    let e = 2.5f32;
    let sc = lit_floor(&format!(
        "[[lights]]\ntype = \"sun\"\ndirection = {:?}\nirradiance = [{e}, {e}, {e}]\nangular_radius_deg = 3",
        direction.to_array()
    ));
    let cos = (-direction.normalize()).y as f64;
    check_floor(&sc, |_| e as f64 * cos, "sun");
}
