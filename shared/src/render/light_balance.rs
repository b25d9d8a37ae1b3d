//! Choosing the light paths per pixel (L) while the run goes. A phase's variance splits into a part that more
//! light paths shrink, as 1/L, and a part they do not touch (the camera paths' own noise); its cost into the
//! camera paths' and L times the light paths'. Their product, the variance × time that δ² × t measures, is
//! least at L* = √(a C / (V₀ D)) for V(L) = V₀ + a/L and cost C + L D. The run alternates steps a factor
//! `SPREAD` above and below its current L, fits V₀ and a from the two, and moves L toward L*. Every phase is
//! normalised by its own light-path count, so the image is unbiased whatever L each phase had.

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

/// The L a run that chooses its own starts from.
pub const START: f32 = 1.0;

/// The two trial L of a step pair lie this factor above and below the current L.
pub const SPREAD: f64 = std::f64::consts::SQRT_2;

/// Bounds on L.
pub const MIN_LIGHT_PATHS_PER_PIXEL: f64 = 1.0 / 16.0;
pub const MAX_LIGHT_PATHS_PER_PIXEL: f64 = 16.0;

/// Image-phases each trial needs before the fit: fewer make the variance estimates too noisy to compare.
const PHASES_PER_TRIAL: f64 = 4.0;

/// A pixel's phases before its running mean is trusted as the centre of the next phases' spread.
const SETTLED_PHASES: u32 = 4;

/// What the steps of one trial L added up to.
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

/// The per-pixel sums the deviations are measured against: Σ luminance, Σ luminance², phases.
#[derive(Clone, Copy, Debug, Default)]
struct PixelMoments {
    sum: f64,
    sum_sq: f64,
    phases: u32,
}

/// The controller of L: `next` before a step, `observe` after it.
#[derive(Clone, Debug)]
pub struct LightBalance {
    centre: f64,
    trials: [Trial; 2],
    /// Which trial the next step renders: 0 above the centre, 1 below.
    turn: usize,
    previous: Vec<PixelMoments>,
    previous_totals: RayTotals,
}

impl LightBalance {
    /// A controller that starts from `start` light paths per pixel.
    pub fn new(start: f32) -> Self {
        LightBalance {
            centre: (start as f64).clamp(MIN_LIGHT_PATHS_PER_PIXEL, MAX_LIGHT_PATHS_PER_PIXEL),
            trials: [Trial::default(); 2],
            turn: 0,
            previous: Vec::new(),
            previous_totals: RayTotals::default(),
        }
    }

    /// A controller that starts from `start`, measuring its first step against `sums` and `totals` as they are.
    pub fn starting_from(start: f32, sums: &Accumulator, totals: RayTotals) -> Self {
        let mut b = LightBalance::new(start);
        b.observe(sums, totals);
        b
    }

    /// The L the controller is centred on (its best estimate of L*).
    pub fn centre(&self) -> f32 {
        self.centre as f32
    }

    /// The L of the next step.
    pub fn next(&self) -> f32 {
        (if self.turn == 0 { self.centre * SPREAD } else { self.centre / SPREAD }) as f32
    }

    /// Takes in the step just rendered at `next()`: its new phases' spread (around their own mean where a pixel
    /// got two or more, else around the pixel's earlier mean), and its rays. Pixels that have seen a light
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
        let trial = &mut self.trials[self.turn];
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
        self.turn = 1 - self.turn;
        let pixels = sums.pixels.len().max(1) as f64;
        if self.turn == 0 && self.trials.iter().all(|t| t.pixel_phases >= PHASES_PER_TRIAL * pixels) {
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
