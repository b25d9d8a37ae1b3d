//! Per-phase buffers are reused: memory does not grow with the number of phases (pbrt-v3's SPPM grew past
//! 100 GB on caustic scenes). This file holds one test so that the process's peak RSS is this test's alone.

mod common;

use common::{scene, settings};
use photonfarm::render::memory::peak_rss_bytes;
use photonfarm::render::{Engine, Method};

#[test]
fn peak_memory_after_200_phases_stays_within_5_percent_of_phase_20() {
    let sc = scene(
        r#"
[camera]
position = [0.278, 0.273, -0.8]
look_at = [0.278, 0.273, 0.0]
fov_y_deg = 39.3
width = 96
height = 96
[materials.white]
type = "diffuse"
albedo = [0.8, 0.8, 0.8]
[materials.glass]
type = "dielectric"
ior = 1.5
[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]
[[objects]]
mesh = "caustic/floor.obj"
material = "white"
[[objects]]
mesh = "caustic/backwall.obj"
material = "white"
[[objects]]
mesh = "caustic/sphere.obj"
material = "glass"
[[objects]]
mesh = "caustic/light.obj"
material = "black"
emission = [400.0, 400.0, 400.0]
"#,
    );
    let mut engine = Engine::new(&sc, settings(&sc, Method::Pbpm, 7));
    let Some(_) = peak_rss_bytes() else {
        panic!("this platform does not report peak RSS (/proc/self/status VmHWM)");
    };
    for _ in 0..20 {
        engine.run_phase();
    }
    let at_20 = peak_rss_bytes().unwrap();
    for _ in 20..200 {
        engine.run_phase();
    }
    let at_200 = peak_rss_bytes().unwrap();
    assert!(
        (at_200 as f64) <= 1.05 * at_20 as f64,
        "peak RSS grew from {} KiB after 20 phases to {} KiB after 200",
        at_20 / 1024,
        at_200 / 1024
    );
}
