//! Balancing camera and light work while the run goes: the light paths per pixel (L) and, where the scene
//! leaves it open, the camera paths' diffuse depth.
//!
//! L: a phase's variance splits into a part that more light paths shrink, as 1/L, and a part they do not touch
//! (the camera paths' own noise); its cost into the camera paths' and L times the light paths'. Their product,
//! the variance × time that δ² × t measures, is least at L* = √(a C / (V₀ D)) for V(L) = V₀ + a/L and cost
//! C + L D. The run alternates steps a factor `SPREAD` above and below its current L, fits V₀ and a from the
//! two, and moves L toward L*. Every phase is normalised by its own light-path count, so the image is unbiased
//! whatever L each phase had.
//!
//! The depth: a camera path that stops at its first diffuse vertex leaves all bounced light to the photons
//! there; one that goes on to a second adds that vertex's one random direction. Which is less noisy for its
//! cost depends on the scene (a closed room, whose light paths land where the camera looks, against an open
//! scene, whose light paths mostly land out of view), so a run whose scene does not fix it renders its first
//! steps at depth 2 and 1 in turn, at the centre L, and keeps the depth with the smaller variance × cost. Both
//! depths converge to the same image, so the phases of the comparison count like any other; but the losing
//! depth's phases can hold several times the variance of the winner's, so the comparison is kept short.

use super::settings::{RenderSettings, START_DEPTH};
use super::totals::RayTotals;
use crate::accumulation::Accumulator;
use crate::color::luminance_f64;
use crate::integrator::Layer;

/// What a light-path ray and a light vertex's merge with a photon cost, in camera-path rays (a camera ray also
/// shades, samples a light and stores a photon). Fitted to the times of whole one-thread renders at two L on
/// three scenes (docs/estimator.md); counts, not clocks, so that a seeded run stays reproducible, and L*
/// depends only on the square root of the cost.
pub const LIGHT_RAY_COST: f64 = 0.63;
pub const MERGE_COST: f64 = 0.33;

/// The two trial L of a step pair lie this factor above and below the current L.
pub const SPREAD: f64 = std::f64::consts::SQRT_2;

/// Bounds on L.
pub const MIN_LIGHT_PATHS_PER_PIXEL: f64 = 1.0 / 16.0;
pub const MAX_LIGHT_PATHS_PER_PIXEL: f64 = 16.0;

/// Image-phases each trial needs before the fit: fewer make the variance estimates too noisy to compare.
const PHASES_PER_TRIAL: f64 = 4.0;

/// Measured phases per pixel each depth needs before the choice: the depths' variances differ by several times
/// where the choice matters, which the pixels of two phases already show.
const PHASES_PER_DEPTH: f64 = 2.0;

/// Steps the depths are compared for at most: where most pixels see a light (the lens's lamp) the trials never
/// fill, and the run keeps `START_DEPTH`.
const MAX_DEPTH_STEPS: u32 = 16;

/// A pixel's phases before its running mean is trusted as the centre of the next phases' spread.
const SETTLED_PHASES: u32 = 4;

/// What the steps of one trial (an L, or a depth) added up to.
#[derive(Clone, Copy, Debug, Default)]
struct Trial {
    /// Σ over pixels and new phases of the squared deviations (`observe`), luminance.
    squared_deviation: f64,
    /// Their degrees of freedom.
    pixel_phases: f64,
    /// Every pixel-phase of the steps (the cost's denominator) and their rays.
    all_pixel_phases: f64,
    backward_rays: f64,
    /// Light-path work in camera-ray units.
    light_cost: f64,
}

impl Trial {
    fn add(&mut self, step: &Trial) {
        self.squared_deviation += step.squared_deviation;
        self.pixel_phases += step.pixel_phases;
        self.all_pixel_phases += step.all_pixel_phases;
        self.backward_rays += step.backward_rays;
        self.light_cost += step.light_cost;
    }

    /// At least `per_pixel` measured phases per pixel.
    fn is_measured(&self, per_pixel: f64, pixels: f64) -> bool {
        self.pixel_phases >= per_pixel * pixels
    }

    /// Variance per pixel-phase times cost per pixel-phase (camera-ray units): δ² × t up to a constant.
    fn variance_times_cost(&self) -> f64 {
        (self.squared_deviation / self.pixel_phases) * ((self.backward_rays + self.light_cost) / self.all_pixel_phases)
    }
}

/// Where a run stands on the camera paths' diffuse depth (`backward_diffuse_depth`).
#[derive(Clone, Copy, Debug)]
enum Depth {
    /// Fixed by the scene or the command line.
    Fixed,
    /// Comparing the two depths: `trials[d − 1]` holds depth d's steps, and `step` counts the comparison's
    /// steps, at depth 2 and 1 in turn.
    Trying { trials: [Trial; 2], step: u32 },
    /// Chosen.
    Chosen(u32),
}

impl Depth {
    /// The depth of the next step, or None where the settings keep theirs.
    fn next(&self) -> Option<u32> {
        match *self {
            Depth::Fixed => None,
            Depth::Trying { step, .. } => Some(if step % 2 == 0 { 2 } else { 1 }),
            Depth::Chosen(d) => Some(d),
        }
    }
}

/// The per-pixel sums the deviations are measured against: Σ luminance, Σ luminance², phases.
#[derive(Clone, Copy, Debug, Default)]
struct PixelMoments {
    sum: f64,
    sum_sq: f64,
    phases: u32,
}

/// The controller of L and the depth: `next` and `depth` before a step, `observe` after it.
#[derive(Clone, Debug)]
pub struct LightBalance {
    /// False where L is fixed: every step then renders the centre.
    light: bool,
    depth: Depth,
    centre: f64,
    trials: [Trial; 2],
    /// Which trial the next step renders: 0 above the centre, 1 below.
    turn: usize,
    previous: Vec<PixelMoments>,
    previous_totals: RayTotals,
}

impl LightBalance {
    /// Bytes a run's light balance holds per image pixel: each pixel's sums at its previous step.
    pub const BYTES_PER_PIXEL: usize = std::mem::size_of::<PixelMoments>();

    /// A controller of L alone that starts from `start` light paths per pixel.
    pub fn new(start: f32) -> Self {
        LightBalance {
            light: true,
            depth: Depth::Fixed,
            centre: (start as f64).clamp(MIN_LIGHT_PATHS_PER_PIXEL, MAX_LIGHT_PATHS_PER_PIXEL),
            trials: [Trial::default(); 2],
            turn: 0,
            previous: Vec::new(),
            previous_totals: RayTotals::default(),
        }
    }

    /// The controller of a run with `settings`, measuring its first step against `sums` and `totals` as they
    /// are; None when the settings fix both L and the depth.
    pub fn for_run(settings: &RenderSettings, sums: &Accumulator, totals: RayTotals) -> Option<Self> {
        let (light, depth) = (settings.adaptive_light, settings.adaptive_depth);
        (light || depth).then(|| {
            let mut b = LightBalance::new(settings.light_paths_per_pixel);
            if !light {
                b.light = false;
                b.centre = settings.light_paths_per_pixel as f64;
            }
            if depth {
                b.depth = Depth::Trying { trials: [Trial::default(); 2], step: 0 };
            }
            b.observe(sums, totals);
            b
        })
    }

    /// The L the controller is centred on (its best estimate of L*).
    pub fn centre(&self) -> f32 {
        self.centre as f32
    }

    /// The L of the next step: the centre while L is fixed or the depths are compared.
    pub fn next(&self) -> f32 {
        if !self.light || self.is_comparing_depths() {
            return self.centre as f32;
        }
        (if self.turn == 0 { self.centre * SPREAD } else { self.centre / SPREAD }) as f32
    }

    /// The camera paths' diffuse depth of the next step, or None where the settings fix it.
    pub fn depth(&self) -> Option<u32> {
        self.depth.next()
    }

    /// True while the run is still comparing the two depths.
    pub fn is_comparing_depths(&self) -> bool {
        matches!(self.depth, Depth::Trying { .. })
    }

    /// Takes in the step just rendered at `next()` and `depth()`: its new phases' spread (around their own mean
    /// where a pixel got two or more, else around the pixel's earlier mean), and its rays. Pixels that have seen a light
    /// directly are left out: their camera-side noise is no part of δ over unlit pixels and does not depend on L.
    pub fn observe(&mut self, sums: &Accumulator, totals: RayTotals) {
        let moments = |i: usize| {
            let p = &sums.pixels[i];
            let n = p.phases as f64;
            PixelMoments { sum: luminance_f64(sums.mean_total(i)) * n, sum_sq: p.sum_sq[4], phases: p.phases }
        };
        if self.previous.len() != sums.pixels.len() {
            self.previous = (0..sums.pixels.len()).map(moments).collect();
            self.previous_totals = totals;
            return;
        }
        let mut step = Trial::default();
        let trial = &mut step;
        for i in 0..sums.pixels.len() {
            let now = moments(i);
            let before = std::mem::replace(&mut self.previous[i], now);
            let new = now.phases.saturating_sub(before.phases) as f64;
            trial.all_pixel_phases += new;
            if new == 0.0 || luminance_f64(sums.mean(i, Layer::VisibleLights)) > 0.0 {
                continue;
            }
            let (sum, sum_sq) = (now.sum - before.sum, now.sum_sq - before.sum_sq);
            if new >= 2.0 {
                // The new phases' spread around their own mean: no earlier phases needed, and neither the noise
                // of an earlier mean nor the image's drift as the radius shrinks adds to it.
                // Σ_new (y − ȳ)² = Σ_new y² − (Σ_new y)² / n_new, with n_new − 1 degrees of freedom.
                trial.squared_deviation += (sum_sq - sum * sum / new).max(0.0);
                trial.pixel_phases += new - 1.0;
            } else if before.phases >= SETTLED_PHASES {
                let m = before.sum / before.phases as f64;
                // Σ_new (y − m)² = Σ_new y² − 2 m Σ_new y + n_new m².
                trial.squared_deviation += (sum_sq - 2.0 * m * sum + new * m * m).max(0.0);
                trial.pixel_phases += new;
            }
        }
        trial.backward_rays += totals.backward_rays.saturating_sub(self.previous_totals.backward_rays) as f64;
        let (t, p) = (totals, self.previous_totals);
        trial.light_cost += LIGHT_RAY_COST * t.forward_rays.saturating_sub(p.forward_rays) as f64
            + MERGE_COST * t.merges.saturating_sub(p.merges) as f64;
        self.previous_totals = totals;
        let pixels = sums.pixels.len().max(1) as f64;
        let depth = self.depth.next();
        if let Depth::Trying { trials, step: n } = &mut self.depth {
            // The comparison's steps are at the centre L: no trial of L.
            trials[depth.unwrap_or(START_DEPTH) as usize - 1].add(&step);
            *n += 1;
            if *n % 2 == 0 && trials.iter().all(|t| t.is_measured(PHASES_PER_DEPTH, pixels)) {
                let [one, two] = *trials;
                self.depth = Depth::Chosen(if one.variance_times_cost() < two.variance_times_cost() { 1 } else { 2 });
            } else if *n >= MAX_DEPTH_STEPS {
                self.depth = Depth::Chosen(START_DEPTH);
            }
            return;
        }
        self.trials[self.turn].add(&step);
        self.turn = 1 - self.turn;
        if self.light && self.turn == 0 && self.trials.iter().all(|t| t.is_measured(PHASES_PER_TRIAL, pixels)) {
            self.centre = self.refit();
            self.trials = [Trial::default(); 2];
        }
    }

    /// The new centre from the two trials: toward L*.
    fn refit(&self) -> f64 {
        let l = [self.centre * SPREAD, self.centre / SPREAD];
        let [hi, lo] = self.trials;
        let (v_hi, v_lo) = (hi.squared_deviation / hi.pixel_phases, lo.squared_deviation / lo.pixel_phases);
        // V(L) = V₀ + a / L through both trials.
        let a = (v_lo - v_hi) / (1.0 / l[1] - 1.0 / l[0]);
        let v0 = v_hi - a / l[0];
        // Cost per pixel-phase C + L D, in camera-ray units.
        let phases = hi.all_pixel_phases + lo.all_pixel_phases;
        let c = (hi.backward_rays + lo.backward_rays) / phases;
        let d = (hi.light_cost / l[0] + lo.light_cost / l[1]) / phases;
        let target = if a.is_nan() || a <= 0.0 {
            // More light did not lower the variance: spend less on it.
            self.centre / 2.0
        } else if v0.is_nan() || v0 <= 0.0 || d <= 0.0 {
            // All of the variance is the light paths': spend more on them.
            self.centre * 2.0
        } else {
            (a * c / (v0 * d)).sqrt() // L* = √(a C / (V₀ D))
        };
        // Half-way in log L, and a factor 2 at most: a noisy fit moves L a little.
        let moved = (self.centre * target).sqrt().clamp(self.centre / 2.0, self.centre * 2.0);
        moved.clamp(MIN_LIGHT_PATHS_PER_PIXEL, MAX_LIGHT_PATHS_PER_PIXEL)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::Rgb;
    use rand_core::{RngCore, SeedableRng};

    /// Feeds the controller steps of `per_step` phases of a synthetic renderer whose phase values have variance
    /// V₀ + a/L and whose phases cost `c` camera rays and `d` L light rays per pixel; returns the centre after
    /// each step.
    fn centres(v0: f64, a: f64, c: f64, d: f64, start: f32, steps: usize, per_step: usize) -> Vec<f32> {
        let pixels = 1024;
        let mut sums = Accumulator::new(32, 32);
        let mut centres = Vec::with_capacity(steps);
        let mut totals = RayTotals::default();
        let mut balance = LightBalance::new(start);
        let mut rng = rand_pcg::Pcg32::seed_from_u64(3);
        balance.observe(&sums, totals);
        for _ in 0..steps {
            let l = balance.next() as f64;
            let sd = (v0 + a / l).sqrt();
            for _ in 0..per_step {
                for i in 0..pixels {
                    // Uniform with that standard deviation around 1 (a diffuse layer, no visible light).
                    let y = 1.0 + sd * 3f64.sqrt() * (2.0 * (rng.next_u32() as f64 / 4294967296.0) - 1.0);
                    let v = [Rgb::ZERO, Rgb::splat(y as f32), Rgb::ZERO, Rgb::ZERO];
                    sums.add_phase(i, &v, 1, 0);
                }
                totals.phases += 1;
                totals.backward_rays += (c * pixels as f64) as u64;
                totals.forward_rays += (d * l * pixels as f64 / LIGHT_RAY_COST) as u64;
            }
            balance.observe(&sums, totals);
            centres.push(balance.centre());
        }
        centres
    }

    /// The geometric mean of the centre over the second half of `steps` one-phase steps.
    fn run(v0: f64, a: f64, c: f64, d: f64, start: f32, steps: usize) -> f32 {
        let c = centres(v0, a, c, d, start, steps, 1);
        let half = &c[steps / 2..];
        (half.iter().map(|&l| (l as f64).ln()).sum::<f64>() / half.len() as f64).exp() as f32
    }

    #[test]
    fn the_centre_settles_at_the_l_that_minimises_variance_times_cost() {
        // L* = √(a C / (V₀ D)): 4 for a = 0.16, V₀ = 0.01, C = D; 0.25 for a = 0.01, V₀ = 0.16.
        let many = run(0.01, 0.16, 10.0, 10.0, 1.0, 400);
        assert!((3.0..=5.4).contains(&many), "wanted about 4, got {many}");
        let few = run(0.16, 0.01, 10.0, 10.0, 1.0, 400);
        assert!((0.18..=0.34).contains(&few), "wanted about 0.25, got {few}");
        // Costly light paths (D = 16 C) call for a quarter of the light: √16.
        let costly = run(0.01, 0.16, 10.0, 160.0, 1.0, 400);
        assert!((0.75..=1.35).contains(&costly), "wanted about 1, got {costly}");
    }

    #[test]
    fn steps_of_several_phases_reach_l_star_within_a_few_steps_and_stay() {
        // A parallel round gives each pixel several phases: their own spread measures the trial from the first
        // step on, so every pair of steps ends in a fit. From L = 1, moving half-way to L* = 0.25 (or 4) each
        // time, three fits come within 20% of it.
        let c = centres(0.16, 0.01, 10.0, 10.0, 1.0, 40, 6);
        assert!(c[5..].iter().all(|l| (0.2..=0.31).contains(l)), "not near 0.25 after 6 steps: {c:?}");
        let c = centres(0.01, 0.16, 10.0, 10.0, 1.0, 40, 6);
        assert!(c[5..].iter().all(|l| (3.2..=5.0).contains(l)), "not near 4 after 6 steps: {c:?}");
    }

    #[test]
    fn light_that_does_not_lower_the_variance_is_cut_to_the_floor() {
        let l = run(0.1, 0.0, 10.0, 10.0, 1.0, 600);
        assert!(l <= 2.0 * MIN_LIGHT_PATHS_PER_PIXEL as f32, "got {l}");
    }

    fn settings(adaptive_light: bool, adaptive_depth: bool) -> RenderSettings {
        RenderSettings {
            estimator: crate::render::Estimator::Pbpm,
            seed: 1,
            max_depth: 12,
            backward_diffuse_depth: START_DEPTH,
            radius_scale: 3.0,
            radius_alpha: 2.0 / 3.0,
            light_paths_per_pixel: 1.0,
            adaptive_light,
            adaptive_depth,
            spectral_bands: 0,
        }
    }

    /// Feeds a controller that chooses the depth one-phase steps of a synthetic renderer whose phase variance
    /// and camera cost per pixel are `variance[d − 1]` and `cost[d − 1]` at depth d (light costs nothing and
    /// changes nothing); returns the depth of every step.
    fn depths(variance: [f64; 2], cost: [f64; 2], steps: usize) -> Vec<u32> {
        let pixels = 1024;
        let mut sums = Accumulator::new(32, 32);
        let mut totals = RayTotals::default();
        let mut rng = rand_pcg::Pcg32::seed_from_u64(5);
        let mut balance = LightBalance::for_run(&settings(true, true), &sums, totals).unwrap();
        let mut depths = Vec::with_capacity(steps);
        for _ in 0..steps {
            let d = balance.depth().expect("a depth while the run chooses it") as usize;
            depths.push(d as u32);
            let sd = variance[d - 1].sqrt();
            for i in 0..pixels {
                let y = 1.0 + sd * 3f64.sqrt() * (2.0 * (rng.next_u32() as f64 / 4294967296.0) - 1.0);
                sums.add_phase(i, &[Rgb::ZERO, Rgb::splat(y as f32), Rgb::ZERO, Rgb::ZERO], 1, 0);
            }
            totals.phases += 1;
            totals.backward_rays += (cost[d - 1] * pixels as f64) as u64;
            balance.observe(&sums, totals);
        }
        depths
    }

    #[test]
    fn a_run_keeps_the_depth_with_the_smaller_variance_times_cost() {
        // Depth 2 and 1 in turn until both have two measured phases per pixel (one-phase steps measure from a
        // pixel's fifth phase on: by step 8); then the choice holds.
        let noisier_second_vertex = depths([0.1, 0.4], [1.0, 1.5], 40);
        assert_eq!(noisier_second_vertex[..8], [2, 1, 2, 1, 2, 1, 2, 1]);
        assert!(noisier_second_vertex[8..].iter().all(|&d| d == 1), "{noisier_second_vertex:?}");
        // The same variance: the shallower depth wins on cost alone.
        let cheaper = depths([0.2, 0.2], [1.0, 1.5], 40);
        assert!(cheaper[8..].iter().all(|&d| d == 1), "{cheaper:?}");
        // Photons too few to carry the bounced light: the second vertex pays for itself.
        let photon_poor = depths([1.0, 0.2], [1.0, 1.5], 40);
        assert!(photon_poor[8..].iter().all(|&d| d == 2), "{photon_poor:?}");
    }

    #[test]
    fn settings_that_fix_both_need_no_controller_and_a_fixed_l_is_kept_while_the_depth_is_chosen() {
        let sums = Accumulator::new(4, 4);
        assert!(LightBalance::for_run(&settings(false, false), &sums, RayTotals::default()).is_none());
        let mut b = LightBalance::for_run(&settings(false, true), &sums, RayTotals::default()).unwrap();
        for _ in 0..MAX_DEPTH_STEPS {
            assert!(b.is_comparing_depths());
            assert_eq!(b.next(), 1.0);
            b.observe(&sums, RayTotals::default());
        }
        // Steps that measured nothing cannot tell the depths apart: the run keeps the deeper one.
        assert!(!b.is_comparing_depths());
        assert_eq!(b.depth(), Some(START_DEPTH));
        let light_only = LightBalance::for_run(&settings(true, false), &sums, RayTotals::default()).unwrap();
        assert_eq!(light_only.depth(), None);
    }

    #[test]
    fn trials_alternate_a_spread_above_and_below_the_centre() {
        let mut b = LightBalance::new(2.0);
        let sums = Accumulator::new(4, 4);
        b.observe(&sums, RayTotals::default());
        let hi = b.next();
        b.observe(&sums, RayTotals::default());
        let lo = b.next();
        assert!((hi as f64 - 2.0 * SPREAD).abs() < 1e-6 && (lo as f64 - 2.0 / SPREAD).abs() < 1e-6);
        assert_eq!(LightBalance::new(100.0).centre(), MAX_LIGHT_PATHS_PER_PIXEL as f32);
    }
}
