//! The ghost layer in the parallel engine: `two-level` (random tile masks, maps shared through atomic counters)
//! and `async` (a whole image per group) give the single-threaded engine's ghost layer, both for the lens's
//! ghosts and for ghost light gathered into ghost photons, other groups' maps included.

use photonfarm::accumulation::{Accumulator, AuxLayout, PixelSums};
use photonfarm::color::luminance_f64;
use photonfarm::ghost::GHOST_LAYER;
use photonfarm::render::session::Progressive;
use photonfarm::render::{Engine, Method, RenderSettings};
use photonfarm::scene::Scene;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use worker::{EngineConfig, ParallelEngine, ParallelMethod};

fn scenes_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// The uncoated lens at 72 × 48 pixels, lit by its fill light only: the bright light's ghosts are single rare
/// samples, far too heavy-tailed for an error estimate from a few hundred phases (see shared/tests/suite/lens.rs);
/// the lens's reflections of the lit scene, about 6 % of the image, are not.
fn fill_lit_lens() -> Scene {
    let text = std::fs::read_to_string(scenes_dir().join("lens.toml")).unwrap();
    let bright = "emission = [50000.0, 45000.0, 37500.0]\n";
    assert!(text.contains(bright) && text.contains("width = 360\n") && text.contains("height = 240\n"));
    let text =
        text.replace(bright, "").replace("width = 360\n", "width = 72\n").replace("height = 240\n", "height = 48\n");
    Scene::from_toml(&text, Path::new("lens.toml"), &scenes_dir()).unwrap()
}

/// The uncoated lens at 72 × 48 pixels with its bright light and without its glasses' dispersion: most of its
/// ghost layer is the light's chains through the lens, which light paths register on the sensor
/// (docs/estimator.md, "The ghost layer"), and an RGB scene lets two-level groups share their maps.
fn lamp_lit_lens() -> Scene {
    let text = std::fs::read_to_string(scenes_dir().join("lens.toml")).unwrap();
    assert!(text.contains("width = 360\n") && text.contains("height = 240\n") && text.contains("\nabbe = "));
    let text = text.replace("width = 360\n", "width = 72\n").replace("height = 240\n", "height = 48\n");
    let text: String = text
        .lines()
        .filter(|l| !l.starts_with("abbe = ") && !l.starts_with("ext_abbe = "))
        .map(|l| l.to_owned() + "\n")
        .collect();
    Scene::from_toml(&text, Path::new("lens.toml"), &scenes_dir()).unwrap()
}

/// Σ over pixels of the luminance of the ghost layer's sums and of the total's sums.
fn image_sums(sums: &Accumulator) -> (f64, f64) {
    sums.ghost_luminance_sums().expect("the scene has a ghost layer")
}

/// The ghost fraction of the image's light, Σ ghost / Σ total, with its standard error from the increments of
/// independent batches (phases, or rounds of the parallel engine): the ratio estimator's n/(n−1) Σ (g_i − f
/// t_i)² / T².
fn ghost_fraction(batches: &[(f64, f64)]) -> (f64, f64) {
    let n = batches.len() as f64;
    let (g, t) = batches.iter().fold((0.0, 0.0), |(g, t), b| (g + b.0, t + b.1));
    let f = g / t;
    let s: f64 = batches.iter().map(|(gi, ti)| (gi - f * ti).powi(2)).sum();
    (f, (n / (n - 1.0) * s).sqrt() / t)
}

/// Adds the increment of the image sums since `before` to `batches` and moves `before` on.
fn push_increment(sums: &Accumulator, before: &mut (f64, f64), batches: &mut Vec<(f64, f64)>) {
    let after = image_sums(sums);
    batches.push((after.0 - before.0, after.1 - before.1));
    *before = after;
}

/// Every pixel's ghost layer lies between zero and its total in luminance (f32 rounding allowed): the lens
/// disperses, so one channel of a pure spectral colour may be negative, its ȳ-weighted luminance never.
fn assert_overlay(sums: &Accumulator, what: &str) {
    for p in 0..sums.pixels.len() {
        let (g, t) = (sums.aux_mean(p, GHOST_LAYER).unwrap(), sums.mean_total(p));
        let (lg, lt) = (luminance_f64(g), luminance_f64(t));
        assert!(lg >= 0.0 && lg <= lt * (1.0 + 1e-5), "{what}: pixel {p}: ghost {g:?}, total {t:?}");
    }
}

/// Renders `scene` with the single-threaded engine for `phases` phases, then with two-level (2 groups of 1
/// thread, `tile`-pixel masks, shared maps) and async (2 groups) until every pixel has as many, and asserts that
/// both give the reference's ghost fraction within four combined standard errors.
fn check(scene: &Scene, phases: u32, tile: u32, what: &str) {
    let settings = |seed| RenderSettings::for_scene(scene, Method::Pbpm, seed);
    let mut reference = Engine::new(scene, settings(21));
    let (mut before, mut batches) = ((0.0, 0.0), Vec::new());
    for _ in 0..phases {
        reference.run_phase();
        push_increment(reference.sums(), &mut before, &mut batches);
    }
    let reference_fraction = ghost_fraction(&batches);
    println!(
        "{what}, single thread, {phases} phases: ghost {:.3} % ± {:.3} % of the image's light",
        100.0 * reference_fraction.0,
        100.0 * reference_fraction.1
    );
    for (method, seed) in [(ParallelMethod::TwoLevel, 22), (ParallelMethod::Async, 23)] {
        let mut config = EngineConfig::for_method(method, 2, 1, vec![0, 1]).unwrap();
        config.tile_size = tile;
        let mut engine = ParallelEngine::new(scene, settings(seed), config).unwrap();
        let never = AtomicBool::new(false);
        let (mut before, mut batches) = ((0.0, 0.0), Vec::new());
        while engine.sums().min_phases() < phases {
            engine.run_round(&never, None);
            push_increment(engine.sums(), &mut before, &mut batches);
        }
        let fraction = ghost_fraction(&batches);
        let bound = 4.0 * (fraction.1.powi(2) + reference_fraction.1.powi(2)).sqrt();
        println!(
            "{what}, {method:?}, {} rounds, {} phases: ghost {:.3} % ± {:.3} % (bound {:.3} %)",
            batches.len(),
            engine.totals().phases,
            100.0 * fraction.0,
            100.0 * fraction.1,
            100.0 * bound
        );
        assert!(fraction.0 > 0.0, "{what}, {method:?}: no ghost light");
        assert!(
            (fraction.0 - reference_fraction.0).abs() <= bound,
            "{what}, {method:?}: ghost fraction {} against the single thread's {}, beyond 4 combined SEM ({bound})",
            fraction.0,
            reference_fraction.0
        );
        assert_overlay(engine.sums(), what);
    }
}

#[test]
fn two_level_and_async_give_the_single_threaded_ghost_fraction_of_the_uncoated_lens() {
    check(&fill_lit_lens(), 200, 16, "lens lit by its fill light");
}

#[test]
fn ghost_chains_registered_on_the_sensor_by_other_groups_light_paths_give_the_single_threaded_ghost_fraction() {
    // With 16-pixel tiles a light path registers its ghost on whichever group's mask holds the pixel, its own
    // or, through that group's open map, the other's; async groups register on their own whole image.
    check(&lamp_lit_lens(), 100, 16, "lens lit by its bright light");
}

#[test]
fn ghost_light_gathered_also_into_other_groups_maps_gives_the_single_threaded_ghost_fraction() {
    // Most of this room's ghost reaches the camera paths through their photons (scenes/ghost-room.toml); with
    // 4-pixel tiles every group's light paths gather into the other group's open map as well.
    let scene = Scene::load(&scenes_dir().join("ghost-room.toml")).unwrap();
    check(&scene, 600, 4, "room behind a window");
}

/// Buffers of gathered light a group holds per pixel it covers: a plain one per thread, and its map's atomic
/// one when other groups add into the map.
fn gather_buffers(config: &EngineConfig) -> usize {
    config.threads_per_group + config.shared_maps as usize
}

/// `EngineConfig::bytes_per_pixel` without auxiliary layers or snapshots: the merged sums, the announced share of
/// the phases, the light balance, the held-back light vertices, and per pixel a group
/// covers its phase values, sums, mask and phase count entries, gathered light, and its photons (held twice,
/// eight grid entries each in buffers with room to double, half a hash bucket, a u32 of its place in grid order).
fn estimate_without_auxiliary_layers(config: &EngineConfig, pixels: usize, backward_diffuse_depth: u32) -> f64 {
    let coverage = if config.masks { 1 } else { config.groups };
    let photon = 2 * std::mem::size_of::<photonfarm::pbpm::BackwardPhoton>() + 2 * 8 * (4 + 8) + 2 + 4;
    // The camera pass's values and replicate, the sums, the mask and the phases before the deal (over every
    // process and this one's own).
    let per_pixel = std::mem::size_of::<photonfarm::integrator::LayerValues>()
        + 1
        + std::mem::size_of::<PixelSums>()
        + 12
        + 24 * gather_buffers(config)
        + backward_diffuse_depth as usize * photon;
    // The light vertices held back for sorted gathers, at most one per image pixel.
    let held_back = worker::parallel::thread_gathers::held_back_bytes_per_pixel(pixels);
    // The share of the pixels' phases the coordinator announces to a worker process, and the run's light
    // balance.
    let share = photonfarm::pbpm::ProcessShare::BYTES_PER_PIXEL;
    let balance = photonfarm::render::light_balance::LightBalance::BYTES_PER_PIXEL;
    (std::mem::size_of::<PixelSums>() + share + balance + coverage * per_pixel) as f64 + held_back
}

#[test]
fn the_memory_estimate_adds_exactly_the_ghost_planes_and_covers_what_an_engine_with_them_holds() {
    let cornell = Scene::load(&scenes_dir().join("cornell.toml")).unwrap();
    let lens = fill_lit_lens();
    let settings = RenderSettings::for_scene(&lens, Method::Pbpm, 4);
    let bdd = settings.backward_diffuse_depth;
    for method in [ParallelMethod::Sync, ParallelMethod::Async, ParallelMethod::TwoLevel] {
        let config = EngineConfig::for_method(method, 2, 1, vec![0, 1]).unwrap();
        // Per pixel of an image of the lens's size, for both scenes.
        let pixels = 72 * 48;
        let coverage = if config.masks { 1 } else { config.groups } as f64;
        // The two grey blur layers every image keeps: f64 sums in the merged image, and per pixel a group covers
        // f64 sums and f32 buffers of the camera pass and of each buffer of gathered light.
        let blur = 2.0 * (8.0 + coverage * (8.0 + 4.0 + 4.0 * gather_buffers(&config) as f64));
        let before = estimate_without_auxiliary_layers(&config, pixels, bdd) + blur;
        // No ghost planes: the estimate is the one without auxiliary layers and the blur layers.
        assert_eq!(
            config.bytes_per_pixel(pixels, pixels, bdd, &AuxLayout::for_scene(&cornell, 0)),
            before,
            "{method:?}"
        );
        // Ghost planes: 3 f64 sums in the merged image, and per pixel a group covers 3 f64 sums and f32 buffers
        // of the camera pass and of each buffer of gathered light, twice there (the ghost layer and the visible
        // light registered on the sensor); a group with a mask holds a u32 per image pixel for the sensor.
        let estimate = config.bytes_per_pixel(pixels, pixels, bdd, &AuxLayout::for_scene(&lens, 0));
        let gathered = 2.0 * 4.0 * gather_buffers(&config) as f64;
        let tables = if config.masks { 4.0 * config.groups as f64 } else { 0.0 };
        assert_eq!(estimate, before + tables + 3.0 * (8.0 + coverage * (8.0 + 4.0 + gathered)), "{method:?}");
        let mut engine = ParallelEngine::new(&lens, settings, config).unwrap();
        engine.run_round(&AtomicBool::new(false), None);
        let held = engine.capacity_bytes() as f64 / (72.0 * 48.0);
        println!(
            "{method:?}: estimate {estimate:.1} bytes per pixel, held {held:.1} (without ghost planes {before:.1})"
        );
        // --memory-limit trusts the estimate made before allocating: it must not fall short of what is held.
        assert!(estimate >= held, "{method:?}: estimated {estimate} bytes per pixel, holds {held}");
    }
}
