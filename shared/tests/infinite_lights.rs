//! Infinite lights and emitting analytic shapes against closed-form answers: a convex body in a constant
//! environment (a furnace: light leaving it never returns), whose pixels show ρ L for a diffuse surface and the
//! directional albedo times L for a glossy one, in PBPM and the path tracer; the environment itself where paths
//! leave the scene; and the irradiance an emitting sphere or disc and a sun give a plane. Tolerances are 4
//! standard errors of the per-phase region means, with fixed seeds.

mod common;

use common::{mean_sem, region_phase_means, scene, settings};
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
