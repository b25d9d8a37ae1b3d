//! A run whose scene leaves `backward_diffuse_depth` open chooses it from its first steps: the Cornell box,
//! a closed room whose light paths land where the camera looks, ends its camera paths at the first diffuse
//! vertex; the head-up display, an open road scene whose light paths mostly land out of view, goes on to the
//! second.

use crate::common::settings;
use photonfarm::accumulation::LitMask;
use photonfarm::render::forecast::Forecast;
use photonfarm::render::session::{self, ErrorOver, StopRule, Tracking};
use photonfarm::render::{Engine, Method};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

/// The depth of every step of a single-threaded run of `phases` phases of a shipped scene, with the depth its
/// file fixes left open.
fn depths(scene_file: &str, phases: u64) -> Vec<u32> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let text = std::fs::read_to_string(dir.join(scene_file)).unwrap();
    let open: String =
        text.lines().filter(|l| !l.starts_with("backward_diffuse_depth")).map(|l| l.to_owned() + "\n").collect();
    let sc = photonfarm::scene::Scene::from_toml(&open, std::path::Path::new(scene_file), &dir).unwrap();
    let s = settings(&sc, Method::Pbpm, 2);
    assert!(s.adaptive_depth, "{scene_file}'s depth is still fixed");
    let lit = LitMask::of_scene(&sc, s.max_depth);
    let mut engine = Engine::new(&sc, s);
    let stop = StopRule { time: None, phases: Some(phases), target_error: None, error_over: ErrorOver::Unlit };
    let mut forecast = Forecast::new(None);
    let mut history = Vec::new();
    let tracking = Tracking { lit: &lit, forecast: &mut forecast, elapsed_before: Duration::ZERO, tiles: None };
    session::run(&mut engine, &stop, &AtomicBool::new(false), &mut history, tracking, |_, _, _| {});
    history.iter().map(|h| h.backward_diffuse_depth.expect("an in-process run records each step's depth")).collect()
}

#[test]
fn a_closed_room_ends_camera_paths_at_the_first_diffuse_vertex_and_an_open_road_scene_at_the_second() {
    // One-phase steps measure a pixel from its fifth phase on, and each depth needs two measured phases per
    // pixel: the comparison ends by step 8 (16 where pixels miss a measured phase).
    let (room, road) = std::thread::scope(|s| {
        let room = s.spawn(|| depths("cornell.toml", 24));
        (room.join().unwrap(), depths("hud.toml", 24))
    });
    assert_eq!(room[..4], [2, 1, 2, 1]);
    assert!(room[16..].iter().all(|&d| d == 1), "cornell: {room:?}");
    assert!(road[16..].iter().all(|&d| d == 2), "hud: {road:?}");
}
