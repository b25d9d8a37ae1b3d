//! Every parallel method is the same estimator: each converges to the single-threaded engine's image.

mod common;

use common::{mean_z2, scene, variance_ratio};
use photonfarm::accumulation::{relative_rmse, Accumulator, LitMask};
use photonfarm::color::luminance_f64;
use photonfarm::integrator::Layer;
use photonfarm::render::images::total_image;
use photonfarm::render::session::Progressive;
use photonfarm::render::{Engine, Method, RenderSettings};
use photonfarm::scene::Scene;
use std::sync::atomic::AtomicBool;
use worker::{EngineConfig, ParallelEngine, ParallelMethod, PhaseCap};

/// Luminance of a pixel's sum over phases without its visible-lights layer. That layer comes from the camera
/// pass alone, the same code in every method; in the caustic room it is the light seen through glass, whose rare,
/// huge samples would drown the comparison of what the methods do differently (the forward pass and its maps).
fn lit_by_scene(sums: &Accumulator, i: usize) -> f64 {
    let px = &sums.pixels[i];
    let mut s = [0.0; 3];
    for l in Layer::ALL.into_iter().filter(|&l| l != Layer::VisibleLights) {
        for (total, layer) in s.iter_mut().zip(px.sum[l as usize]) {
            *total += layer;
        }
    }
    luminance_f64(s)
}

/// Per block of block × block pixels: Σ `lit_by_scene` and Σ phases over its pixels.
fn block_sums(sums: &Accumulator, block: u32) -> Vec<(f64, f64)> {
    let (w, h) = (sums.width, sums.height);
    let mut out = Vec::new();
    for by in 0..h / block {
        for bx in 0..w / block {
            let (mut s, mut n) = (0.0, 0.0);
            for y in by * block..(by + 1) * block {
                for x in bx * block..(bx + 1) * block {
                    let i = (y * w + x) as usize;
                    s += lit_by_scene(sums, i);
                    n += sums.pixels[i].phases as f64;
                }
            }
            out.push((s, n));
        }
    }
    out
}

/// Block means of `lit_by_scene` per phase.
fn block_means(sums: &Accumulator, block: u32) -> Vec<f64> {
    block_sums(sums, block).into_iter().map(|(s, n)| s / n).collect()
}

/// What each round adds to every block's sums, so that a block mean's standard error comes from the spread of
/// whole rounds. Pixels of one phase share light paths (with one diffuse camera vertex, a light vertex lands in
/// the discs of neighbouring pixels), so summing pixel SEMs over a block understates its error.
struct BlockRounds {
    block: u32,
    last: Vec<(f64, f64)>,
    added: Vec<Vec<(f64, f64)>>,
}

impl BlockRounds {
    fn new(sums: &Accumulator, block: u32) -> Self {
        let last = block_sums(sums, block);
        BlockRounds { block, added: vec![Vec::new(); last.len()], last }
    }

    /// Records what the round just rendered added to each block.
    fn record(&mut self, sums: &Accumulator) {
        for (b, (s, n)) in block_sums(sums, self.block).into_iter().enumerate() {
            let (s0, n0) = self.last[b];
            if n > n0 {
                self.added[b].push((s - s0, n - n0));
            }
            self.last[b] = (s, n);
        }
    }

    /// Each block's mean per phase and its squared standard error, with the rounds as independent samples of
    /// the ratio Σ s / Σ n. Rounds that draw from one quasi-random sequence are not independent: this overstates
    /// the error of their mean.
    fn means_and_sem2(&self) -> Vec<(f64, f64)> {
        self.added
            .iter()
            .map(|rounds| {
                let (s, n) = rounds.iter().fold((0.0, 0.0), |(s, n), (ds, dn)| (s + ds, n + dn));
                let (mean, r) = (s / n, rounds.len() as f64);
                let spread = rounds.iter().map(|(ds, dn)| (ds - mean * dn).powi(2)).sum::<f64>();
                (mean, spread / (n * n) * r / (r - 1.0))
            })
            .collect()
    }
}

/// The single-threaded engine's sums and its quarter-image blocks round by round (a phase each).
struct Reference {
    sums: Accumulator,
    quarters: BlockRounds,
}

/// The cornell reference both cornell tests compare with, rendered once for the test process.
fn cornell_reference(sc: &Scene) -> &'static Reference {
    static CORNELL: std::sync::OnceLock<Reference> = std::sync::OnceLock::new();
    CORNELL.get_or_init(|| reference(sc, 1200))
}

fn reference(sc: &Scene, phases: u64) -> Reference {
    let mut e = Engine::new(sc, RenderSettings::for_scene(sc, Method::Pbpm, 99));
    let mut quarters = BlockRounds::new(e.sums(), e.sums().width / 4);
    for _ in 0..phases {
        e.run_phase();
        quarters.record(e.sums());
    }
    Reference { sums: e.sums().clone(), quarters }
}

/// Checks that a method's image is the reference's within their errors. `sum_ratio`: also that the replicate
/// SEMs account for the whole difference summed over unlit pixels, which holds where no pixel carries a bias
/// that differs between the two budgets (a caustic's focus does: its radius at 400 phases blurs it more than
/// at 1600, and a sum over pixels is all focus).
fn check(sc: &Scene, name: &str, reference: &Reference, config: EngineConfig, min_phases: u32, sum_ratio: bool) {
    check_with(sc, name, reference, config, min_phases, sum_ratio, |_, _| ());
}

/// `check`, with `before_round` called with the engine and the round's number before every round; returns the
/// method's sums.
fn check_with(
    sc: &Scene,
    name: &str,
    reference: &Reference,
    config: EngineConfig,
    min_phases: u32,
    sum_ratio: bool,
    mut before_round: impl FnMut(&mut ParallelEngine, u64),
) -> Accumulator {
    let label = format!("{name} {:?} {}×{}", config.method, config.groups, config.threads_per_group);
    let mut engine = ParallelEngine::new(sc, RenderSettings::for_scene(sc, Method::Pbpm, 5), config).unwrap();
    let never = AtomicBool::new(false);
    let mut quarters = BlockRounds::new(engine.sums(), engine.sums().width / 4);
    let mut round = 0;
    while engine.sums().min_phases() < min_phases {
        before_round(&mut engine, round);
        engine.run_round(&never, None);
        quarters.record(engine.sums());
        round += 1;
    }
    let sums = engine.sums();
    let (reference, reference_quarters) = (&reference.sums, &reference.quarters);
    let rmse = relative_rmse(&total_image(sums), &total_image(reference), |_| true);
    let mean_z2 = mean_z2(sums, reference);
    let ratio = variance_ratio(sums, reference, &LitMask::of_scene(sc, engine.settings().max_depth));
    let a = quarters.means_and_sem2();
    let b = reference_quarters.means_and_sem2();
    let (mut worst, mut worst_z): (f64, f64) = (0.0, 0.0);
    for ((ma, sa), (mb, sb)) in a.iter().zip(&b) {
        worst = worst.max((ma - mb).abs() / mb);
        worst_z = worst_z.max((ma - mb).abs() / (sa + sb).sqrt());
    }
    let all = LitMask::none(sums.width, sums.height);
    let combined = (sums.error(&all).delta_all.powi(2) + reference.error(&all).delta_all.powi(2)).sqrt();
    // Relative RMSE of 8×8-block means: the 2% criterion at this budget, with pixel noise averaged down.
    let (fa, fb) = (block_means(sums, 8), block_means(reference, 8));
    let block_rmse = (fa.iter().zip(&fb).map(|(a, b)| (a - b) * (a - b)).sum::<f64>()
        / fb.iter().map(|b| b * b).sum::<f64>())
    .sqrt();
    eprintln!(
        "{label}: {} phases/pixel, RMSE {:.2}% (8×8 blocks {:.2}%), mean z² {mean_z2:.2}, difference² / SEM² {:.3} ± {:.3}, worst quarter-image block {:.2}% (3 × combined δ = {:.2}%), {worst_z:.2} of its SEMs",
        sums.min_phases(),
        100.0 * rmse,
        100.0 * block_rmse,
        ratio.value,
        ratio.standard_error,
        100.0 * worst,
        300.0 * combined
    );
    // Eq. 7's SEMs overstate a quasi-random mean's error: per pixel they bound the disagreement from above;
    // the replicate SEMs, summed over pixels, must account for all of it (`sum_ratio`).
    assert!(mean_z2 <= 1.4, "{label}: mean z² = {mean_z2:.2}");
    if sum_ratio {
        let (r, se) = (ratio.value, ratio.standard_error);
        assert!((r - 1.0).abs() <= 4.0 * se, "{label}: difference² / SEM² = {r:.3} ± {se:.3}, not 1 within 4 SE");
    }
    // Each quarter-image block against its own standard error, from its rounds: the image's δ is held by its
    // bright pixels and says little about a dark block.
    assert!(worst_z <= 4.0, "{label}: a quarter-image block differs by {worst_z:.2} of its SEMs");
    assert!(block_rmse < 0.02, "{label}: relative RMSE of 8×8 blocks {:.2}%", 100.0 * block_rmse);
    sums.clone()
}

fn configs(group_variants: bool) -> Vec<EngineConfig> {
    let cores = vec![0, 1];
    let mut configs = vec![
        EngineConfig::for_method(ParallelMethod::Sync, 2, 2, cores.clone()).unwrap(),
        EngineConfig::for_method(ParallelMethod::Async, 2, 1, cores.clone()).unwrap(),
        EngineConfig::for_method(ParallelMethod::TwoLevel, 2, 1, cores.clone()).unwrap(),
    ];
    if group_variants {
        // Groups of 2 and of 4 threads: two of two, and one of each by hand (the layout rule never makes one
        // group of several threads, but its synchronous stages must stay exact on their own).
        let two_by_two = EngineConfig::for_method(ParallelMethod::TwoLevel, 4, 2, cores.clone()).unwrap();
        assert_eq!((two_by_two.groups, two_by_two.threads_per_group), (2, 2));
        configs.push(EngineConfig { groups: 1, threads_per_group: 2, ..two_by_two.clone() });
        configs.push(EngineConfig { groups: 1, threads_per_group: 4, ..two_by_two.clone() });
        configs.push(two_by_two);
        // Where sync fails (Amdahl: many threads, one map, barriers), it must stay slow but exact.
        configs.push(EngineConfig::for_method(ParallelMethod::Sync, 8, 8, cores.clone()).unwrap());
    }
    // Tiny tiles force many groups onto two cores.
    let mut many = EngineConfig::for_method(ParallelMethod::TwoLevel, 8, 1, cores).unwrap();
    many.tile_size = 8;
    configs.push(many);
    configs
}

#[test]
fn every_method_and_group_size_converges_to_the_single_thread_image_on_cornell() {
    let sc = scene("cornell.toml", 64);
    let reference = cornell_reference(&sc);
    for c in configs(true) {
        check(&sc, "cornell", reference, c, 300, true);
    }
    // Each phase is normalised by its own light paths, so rounds at 16 times fewer and 4 times more light paths
    // per pixel than the reference's 1 (as a run that chooses them while it goes) estimate the same image. At
    // 1/16 a pixel's phase values are skewed (most gather no light path), and eq. 7's SEM from a few hundred of
    // them is too often small: even the single-threaded engine at a constant 1/16 has a mean z² above 1 against
    // its own L = 1 image at a few hundred phases, falling toward 1 as the phases grow, which a bias would not
    // do. Hence 600 phases.
    let two_level = EngineConfig::for_method(ParallelMethod::TwoLevel, 2, 1, vec![0, 1]).unwrap();
    check_with(&sc, "cornell, light per pixel 1/16 and 4 in turn,", reference, two_level, 600, true, |e, round| {
        e.set_light_paths_per_pixel(if round % 2 == 0 { 1.0 / 16.0 } else { 4.0 });
    });
}

#[test]
fn rounds_capped_to_part_of_the_tiles_give_every_tile_its_phases_and_converge_to_the_single_thread_image() {
    let sc = scene("cornell.toml", 64);
    let reference = cornell_reference(&sc);
    // Two groups of 8-pixel tiles, at most 512 pixels per group phase: a round renders 16 of the 64 tiles, 8 per
    // group, whole (a deal quarters tiles only when there are fewer than four per group), so that every pixel
    // of a tile has its phases.
    let mut config = EngineConfig::for_method(ParallelMethod::TwoLevel, 2, 1, vec![0, 1]).unwrap();
    config.tile_size = 8;
    let cap = 512;
    let tiles = photonfarm::render::ActiveTiles::all(64, 64, 8).unwrap();
    let mut previous: Option<Vec<u32>> = None;
    let (mut rounds, mut most_in_a_round, mut widest_spread) = (0, 0, 0);
    let sums = check_with(&sc, "cornell, 512 pixels per group phase,", reference, config, 300, true, |e, round| {
        if round == 0 {
            e.set_phase_cap(PhaseCap::Pixels(cap));
        }
        let now: Vec<u32> = e.sums().pixels.iter().map(|p| p.phases).collect();
        if let Some(before) = previous.replace(now.clone()) {
            let added: Vec<u32> = now.iter().zip(&before).map(|(a, b)| a - b).collect();
            // Whole tiles, each group's share of the cap: every group renders at least one phase a round.
            let rendered: Vec<usize> = (0..tiles.len())
                .filter(|&t| tiles.pixels_of(t).any(|p| added[p as usize] > 0))
                .inspect(|&t| {
                    assert!(tiles.pixels_of(t).all(|p| added[p as usize] > 0), "round {round}: part of tile {t}")
                })
                .collect();
            assert_eq!(rendered.len(), 16, "round {round}: tiles {rendered:?}");
            most_in_a_round = most_in_a_round.max(*added.iter().max().unwrap());
            rounds += 1;
        }
        if round >= 8 {
            let (lo, hi) = (now.iter().min().unwrap(), now.iter().max().unwrap());
            widest_spread = widest_spread.max(hi - lo);
        }
    });
    let (lo, hi) = (sums.min_phases(), sums.pixels.iter().map(|p| p.phases).max().unwrap());
    eprintln!(
        "{rounds} capped rounds, at most {most_in_a_round} phases a round, {lo}..={hi} phases per pixel at the end, widest spread {widest_spread}"
    );
    // Every tile waits for the tiles with fewer phases, so none runs far ahead. A round that takes tiles of two
    // phase counts can give the lower ones fewer phases (their group stopped early) than the higher ones: the
    // spread can pass one round's most, but not two (a simulation of such rounds peaks near 1.4).
    assert!(hi - lo <= 2 * most_in_a_round, "{lo}..={hi} phases per pixel, at most {most_in_a_round} a round");
    assert!(widest_spread <= 2 * most_in_a_round, "spread {widest_spread}, at most {most_in_a_round} a round");
}

#[test]
fn every_method_converges_to_the_single_thread_image_on_caustic() {
    // The caustic room is far noisier per phase (a small light focused by glass): a longer budget.
    let sc = scene("caustic.toml", 64);
    let reference = reference(&sc, 1600);
    for c in configs(false) {
        check(&sc, "caustic", &reference, c, 400, false);
    }
}

#[test]
fn every_method_converges_to_the_single_thread_image_on_a_dispersive_caustic() {
    // The caustic room's sphere made of dispersive glass: every group phase has its own wavelengths, so
    // two-level groups must not gather into each other's maps, and each method must still be the same
    // estimator, as strictly as in RGB.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let text = std::fs::read_to_string(dir.join("caustic.toml"))
        .unwrap()
        .replace("width = 256", "width = 64")
        .replace("height = 256", "height = 64")
        .replace("ior = 1.5", "ior = 1.5\nabbe = 30.0");
    let sc = Scene::from_toml(&text, std::path::Path::new("caustic.toml"), &dir).unwrap();
    assert!(sc.is_spectral());
    let reference = reference(&sc, 1600);
    for c in configs(false) {
        let engine = ParallelEngine::new(&sc, RenderSettings::for_scene(&sc, Method::Pbpm, 5), c.clone()).unwrap();
        assert!(!engine.config().shared_maps, "{:?}: maps shared in a spectral scene", c.method);
        drop(engine);
        check(&sc, "dispersive caustic", &reference, c, 400, false);
    }
}
