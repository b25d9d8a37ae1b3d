//! A worker's snapshots hold only the pixels its rounds rendered: with the phase cap a round renders a part of
//! the image, the engine names exactly the pixels whose sums changed with the sums they had before, and deltas
//! of those pixels alone merge at the coordinator to the sums that deltas of the whole image give.

mod common;

use common::scene;
use photonfarm::accumulation::delta::{apply_delta, encode_changes, encode_delta, encode_delta_of, Compression};
use photonfarm::accumulation::Accumulator;
use photonfarm::render::session::Progressive;
use photonfarm::render::{Method, RenderSettings};
use std::sync::atomic::AtomicBool;
use worker::{EngineConfig, ParallelEngine, ParallelMethod, PhaseCap};

#[test]
fn snapshots_of_the_changed_pixels_merge_to_the_sums_of_whole_image_snapshots() {
    let sc = scene("cornell.toml", 64);
    let mut config = EngineConfig::for_method(ParallelMethod::TwoLevel, 2, 1, vec![0, 1]).unwrap();
    config.tile_size = 8;
    // As a worker's engine, which keeps the changed pixels' earlier sums for its snapshots.
    config.snapshots = true;
    let mut engine = ParallelEngine::new(&sc, RenderSettings::for_scene(&sc, Method::Pbpm, 5), config).unwrap();
    // 512 pixels per group phase: a round renders 16 of the 64 tiles.
    engine.set_phase_cap(PhaseCap::Pixels(512));
    let never = AtomicBool::new(false);
    let mut base = engine.sums().clone();
    let (mut whole, mut sparse) = (base.clone(), base.clone());
    let n = base.pixels.len();
    let (mut sent_pixels, mut snapshots) = (0, 0);
    for round in 0..12 {
        engine.run_round(&never, None);
        // A snapshot every other round, as a worker sends one when its interval has passed.
        if round % 2 == 0 {
            continue;
        }
        let changes = engine.take_changed();
        let changed = changes.runs();
        let current = engine.sums();
        let mut flags = vec![false; n];
        changed.indices().for_each(|i| flags[i] = true);
        for (i, (c, b)) in current.pixels.iter().zip(&base.pixels).enumerate() {
            assert!(c == b || flags[i], "snapshot {snapshots}: pixel {i} changed but is not named");
        }
        assert!(changed.pixel_count() > 0 && changed.pixel_count() < n, "{} of {n} pixels", changed.pixel_count());
        let full = encode_delta(current, &base, Compression::Fast);
        let part = encode_delta_of(current, &base, &changed, Compression::Fast);
        // The sums the engine kept of the changed pixels alone give the same delta as a copy of the image.
        assert_eq!(encode_changes(current, &changes, Compression::Fast), part);
        assert!(part.len() < full.len(), "{} bytes for the changed pixels, {} for all", part.len(), full.len());
        let a = apply_delta(&full, &mut whole).unwrap();
        let b = apply_delta(&part, &mut sparse).unwrap();
        assert_eq!(a.pixel_phases, b.pixel_phases);
        assert_eq!(b.pixels, changed);
        sent_pixels += changed.pixel_count();
        snapshots += 1;
        base = current.clone();
    }
    // Bit for bit: a whole-image delta adds exact zeros to the pixels a sparse one leaves out.
    assert_eq!(sparse, whole);
    assert!(sparse.pixels.iter().all(|p| p.phases > 0), "every tile rendered by the end");
    // Nothing rendered since the last call: nothing named.
    assert!(engine.take_changed().is_empty());
    let merged: &Accumulator = &sparse;
    let phases = |s: &Accumulator| s.pixels.iter().map(|p| p.phases as u64).sum::<u64>();
    assert_eq!(phases(merged), phases(engine.sums()));
    eprintln!(
        "{snapshots} snapshots held {sent_pixels} pixels, {:.2} of the image each",
        sent_pixels as f64 / (snapshots * n) as f64
    );
}
