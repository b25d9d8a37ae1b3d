//! The Mitsuba 3 twins in scenes/mitsuba/ are the same scenes as their TOML files: each loads to the same
//! camera, the same lights and the same path depth, and PBPM renders it, small and with fixed seeds, to the
//! TOML scene's image, per pixel and over the image.

use crate::common::{mean_sem, mean_z2, regions_phase_means, settings, shipped_at};
use glam::{Vec2, Vec3};
use photonfarm::accumulation::Accumulator;
use photonfarm::light::Light;
use photonfarm::render::{Engine, Method, RenderSettings};
use photonfarm::scene::{MitsubaOptions, Scene};
use std::path::Path;

fn scenes_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// The Mitsuba twin `name` at `width` × `height` pixels, through its `resx` and `resy` parameters.
fn xml_at(name: &str, width: u32, height: u32) -> Scene {
    let defines = vec![("resx".to_string(), width.to_string()), ("resy".to_string(), height.to_string())];
    let options = MitsubaOptions { defines, approximate: false };
    Scene::load_with_options(&scenes_dir().join("mitsuba").join(name), &options).unwrap_or_else(|e| panic!("{e}"))
}

/// Asserts that both cameras send the same rays through the same pixel positions.
fn assert_same_camera(xml: &Scene, toml: &Scene) {
    let (w, h) = (toml.camera.width, toml.camera.height);
    assert_eq!((xml.camera.width, xml.camera.height), (w, h));
    for (x, y) in [(0, 0), (w - 1, 0), (w / 2, h / 2), (3, h - 1), (w - 1, h - 1)] {
        for jitter in [Vec2::ZERO, Vec2::new(0.5, 0.5), Vec2::new(0.99, 0.01)] {
            let a = xml.camera.generate_ray(x, y, jitter, Vec2::ZERO).ray;
            let b = toml.camera.generate_ray(x, y, jitter, Vec2::ZERO).ray;
            assert!((a.origin - b.origin).length() < 1e-5, "pixel ({x}, {y}): origin {} vs {}", a.origin, b.origin);
            assert!(
                (a.direction - b.direction).length() < 1e-5,
                "pixel ({x}, {y}): direction {} vs {}",
                a.direction,
                b.direction
            );
        }
    }
}

/// Each area light as (its triangle's vertices in a canonical order, radiance, unit normal), sorted, so that
/// two scenes that list their triangles in different orders compare.
fn area_lights(scene: &Scene) -> Vec<([Vec3; 3], Vec3, Vec3)> {
    let mut lights: Vec<_> = scene
        .lights
        .all()
        .iter()
        .map(|light| match light {
            Light::Area { triangle, emission, normal, .. } => {
                let mut v = scene.geometry.triangle(*triangle).v;
                v.sort_by(|a, b| a.to_array().partial_cmp(&b.to_array()).unwrap());
                (v, *emission, *normal)
            }
            other => panic!("the twins have area lights only, found {other:?}"),
        })
        .collect();
    lights.sort_by(|a, b| a.0[0].to_array().partial_cmp(&b.0[0].to_array()).unwrap());
    lights
}

/// Asserts that both scenes have the same emitting triangles with the same radiance facing the same way.
fn assert_same_lights(xml: &Scene, toml: &Scene) {
    let (a, b) = (area_lights(xml), area_lights(toml));
    assert_eq!(a.len(), b.len(), "light triangles");
    for (x, t) in a.iter().zip(&b) {
        for k in 0..3 {
            assert!((x.0[k] - t.0[k]).length() < 1e-6, "light vertex {} vs {}", x.0[k], t.0[k]);
        }
        assert!((x.1 - t.1).length() <= 1e-6 * t.1.length(), "radiance {} vs {}", x.1, t.1);
        assert!((x.2 - t.2).length() < 1e-5, "light normal {} vs {}", x.2, t.2);
    }
}

/// What a twin's render gives: the sums, and the image's mean luminance in each phase.
struct Render {
    sums: Accumulator,
    phase_means: Vec<f64>,
}

/// Renders `phases` PBPM phases of `scene` with the TOML twin's estimator settings: its backward depth, photon
/// radius and light paths per pixel, fixed, so that both twins are estimated alike and only the scene differs.
fn render(scene: &Scene, like: &RenderSettings, seed: u64, phases: usize) -> Render {
    let mut engine = Engine::new(scene, RenderSettings { seed, ..*like });
    let all: Vec<usize> = (0..(scene.camera.width * scene.camera.height) as usize).collect();
    let phase_means = regions_phase_means(&mut engine, phases, &[(&all, None)]).remove(0);
    Render { sums: engine.sums().clone(), phase_means }
}

/// Renders both twins side by side and asserts that they converge to the same image: the mean over pixels of
/// z² = (a − b)² / (SEM_a² + SEM_b²) with eq. 7's per-pixel SEMs is within 4 standard deviations of 1 or below
/// (z² of one pixel has variance 2; below 1 is expected, as eq. 7 overstates the error of quasi-random phases),
/// and the image means agree within 4 combined standard errors from their phases.
fn assert_twins_converge(name: &str, xml: &Scene, toml: &Scene, phases: usize) {
    let mut like = settings(toml, Method::Pbpm, 0);
    like.adaptive_light = false;
    like.adaptive_depth = false;
    let (a, b) = std::thread::scope(|s| {
        let xml_render = s.spawn(|| render(xml, &like, 101, phases));
        let toml_render = render(toml, &like, 202, phases);
        (xml_render.join().unwrap(), toml_render)
    });

    let (w, h) = (toml.camera.width, toml.camera.height);
    let (z2, n) = mean_z2(&a.sums, &b.sums);
    assert!(n > 0.9 * (w * h) as f64, "{name}: only {n} of {} pixels have light", w * h);
    let bound = 1.0 + 4.0 * (2.0 / n).sqrt();
    eprintln!("{name}: mean z² {z2:.3} over {n} pixels, {phases} phases each (bound {bound:.3})");
    assert!(z2 < bound, "{name}: mean z² {z2:.3} above {bound:.3}: the twins render different images");

    let ((ma, sa), (mb, sb)) = (mean_sem(&a.phase_means), mean_sem(&b.phase_means));
    let z = (ma - mb) / (sa * sa + sb * sb).sqrt();
    eprintln!("{name}: image mean XML {ma:.5} ± {sa:.5}, TOML {mb:.5} ± {sb:.5} (z = {z:.2})");
    assert!(z.abs() < 4.0, "{name}: image means {ma} ± {sa} (XML) and {mb} ± {sb} (TOML) differ");
}

/// Loads both twins at the test size and checks everything but the image.
fn twins(xml_name: &str, toml_name: &str, width: u32, height: u32) -> (Scene, Scene) {
    let (xml, toml) = (xml_at(xml_name, width, height), shipped_at(toml_name, width, height));
    assert_same_camera(&xml, &toml);
    assert_same_lights(&xml, &toml);
    assert_eq!(xml.render.max_depth, toml.render.max_depth, "max_depth");
    (xml, toml)
}

#[test]
fn the_mitsuba_cornell_box_has_the_camera_and_light_of_its_toml_twin_and_converges_to_its_image() {
    let (xml, toml) = twins("cornell.xml", "cornell.toml", 32, 32);
    assert_twins_converge("cornell", &xml, &toml, 400);
}

#[test]
fn the_mitsuba_caustic_scene_has_the_camera_and_light_of_its_toml_twin_and_converges_to_its_image() {
    let (xml, toml) = twins("caustic.xml", "caustic.toml", 32, 32);
    assert_twins_converge("caustic", &xml, &toml, 400);
}

#[test]
fn the_mitsuba_glossy_room_has_the_camera_and_light_of_its_toml_twin_and_converges_to_its_image() {
    let (xml, toml) = twins("glossy-room.xml", "glossy-room.toml", 32, 24);
    assert_twins_converge("glossy room", &xml, &toml, 400);
}
