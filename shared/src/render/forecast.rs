//! How long a run with `--target-error` still needs: δ's variance part falls as 1/√work, so 1/δ² grows linearly
//! in the work done, and a straight line through the recent steps' 1/δ² says when it reaches 1/target².
//!
//! Work is counted in image phases (phases per pixel, averaged over the image): the estimator's own clock,
//! which does not slow down when the machine is loaded, so the prediction of how much work is left holds on a
//! busy machine; the recent rate of image phases per second turns it into seconds.

use serde::{Deserialize, Serialize};

/// The share of the work done so far that the fit looks back over: early steps, with their fixed costs and
/// larger photon radii, would bend the line.
const RECENT: f64 = 0.5;

/// Steps a fit needs at least.
const MIN_POINTS: usize = 3;

/// One step of the run: wall seconds, image phases and δ.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Step {
    time_s: f64,
    work: f64,
    delta: f64,
}

/// An estimate of the rest of the run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Wall seconds of the run when the estimate was made.
    pub at_s: f64,
    /// Image phases done then.
    pub at_phases: f64,
    /// δ then.
    pub delta: f64,
    /// Image phases at which δ is predicted to reach the target.
    pub end_phases: f64,
    /// Seconds still needed, at the recent rate of image phases per second.
    pub remaining_s: f64,
}

impl Estimate {
    /// Predicted wall seconds of the run when it reaches the target.
    pub fn end_s(&self) -> f64 {
        self.at_s + self.remaining_s
    }
}

/// The record of a run with a target error: the latest estimate, the one made when δ first came within twice
/// the target, and, once the run has ended, what happened.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ForecastRecord {
    pub target: f64,
    /// The latest estimate (None until enough steps were seen).
    pub latest: Option<Estimate>,
    /// The estimate made at the first step whose δ was within 2× of the target.
    pub within_2x: Option<Estimate>,
    /// Wall seconds and image phases at which δ met the target (None while running, or when the run stopped
    /// for another reason).
    pub reached_s: Option<f64>,
    pub reached_phases: Option<f64>,
}

/// Fits δ's trend step by step and predicts when it reaches the target.
#[derive(Clone, Debug, Default)]
pub struct Forecast {
    target: Option<f64>,
    steps: Vec<Step>,
    record: ForecastRecord,
}

impl Forecast {
    /// A forecast towards `target` (none without a target error: it then estimates nothing).
    pub fn new(target: Option<f64>) -> Self {
        Forecast {
            target,
            steps: Vec::new(),
            record: ForecastRecord { target: target.unwrap_or(0.0), ..Default::default() },
        }
    }

    /// Takes one step: `time_s` wall seconds and `work` image phases into the run, δ `delta` (the δ the
    /// target refers to). Returns the new estimate, if there is one.
    pub fn step(&mut self, time_s: f64, work: f64, delta: f64) -> Option<Estimate> {
        let target = self.target?;
        if !(delta.is_finite() && delta > 0.0 && work > 0.0) {
            return None;
        }
        self.steps.push(Step { time_s, work, delta });
        if delta <= target && self.record.reached_s.is_none() {
            self.record.reached_s = Some(time_s);
            self.record.reached_phases = Some(work);
        }
        let estimate = self.fit(target);
        if let Some(e) = estimate {
            self.record.latest = Some(e);
            if delta <= 2.0 * target && self.record.within_2x.is_none() {
                self.record.within_2x = Some(e);
            }
        }
        estimate
    }

    /// The latest estimate.
    pub fn latest(&self) -> Option<Estimate> {
        self.record.latest
    }

    /// What the run record keeps (None without a target error).
    pub fn record(&self) -> Option<ForecastRecord> {
        self.target.map(|_| self.record.clone())
    }

    /// Least squares of 1/δ² against image phases over the recent steps, and the recent phase rate.
    fn fit(&self, target: f64) -> Option<Estimate> {
        let last = *self.steps.last()?;
        let from = last.work * (1.0 - RECENT);
        let recent: Vec<&Step> = self.steps.iter().filter(|s| s.work >= from).collect();
        if recent.len() < MIN_POINTS {
            return None;
        }
        let n = recent.len() as f64;
        let (mx, my) = recent.iter().fold((0.0, 0.0), |(x, y), s| (x + s.work / n, y + s.delta.powi(-2) / n));
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for s in &recent {
            let dx = s.work - mx;
            sxy += dx * (s.delta.powi(-2) - my);
            sxx += dx * dx;
        }
        if sxx <= 0.0 {
            return None;
        }
        let slope = sxy / sxx;
        // A δ that does not fall (noise, or a bias floor) gives no estimate rather than a negative one.
        if slope.is_nan() || slope <= 0.0 {
            return None;
        }
        // 1/δ² = my + slope (work − mx) reaches 1/target² at:
        let end_phases = (mx + (target.powi(-2) - my) / slope).max(last.work);
        let first = recent[0];
        let rate = (last.work - first.work) / (last.time_s - first.time_s);
        if !(rate.is_finite() && rate > 0.0) {
            return None;
        }
        Some(Estimate {
            at_s: last.time_s,
            at_phases: last.work,
            delta: last.delta,
            end_phases,
            remaining_s: (end_phases - last.work) / rate,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_delta_falling_as_one_over_root_work_is_predicted_to_the_phase() {
        // δ = 0.2 / √(work), one image phase per 0.5 s: the target 0.01 is met at 400 phases, 200 s.
        let mut f = Forecast::new(Some(0.01));
        let mut e = None;
        for k in 1..=99 {
            let work = k as f64;
            e = f.step(0.5 * work, work, 0.2 / work.sqrt()).or(e);
        }
        let e = e.expect("an estimate after 99 steps");
        assert!((e.end_phases - 400.0).abs() < 1e-6, "{}", e.end_phases);
        assert!((e.end_s() - 200.0).abs() < 1e-6, "{}", e.end_s());
        assert!(f.record().unwrap().within_2x.is_none(), "δ is still above 2% at 99 phases");
        // At 100 phases δ is 2%, twice the target: the estimate made then is kept.
        f.step(50.0, 100.0, 0.02);
        let kept = f.record().unwrap().within_2x.expect("kept within 2× of the target");
        assert!((kept.end_phases - 400.0).abs() < 1e-6 && kept.at_phases == 100.0);
    }

    #[test]
    fn without_a_target_there_is_no_estimate_and_no_record() {
        let mut f = Forecast::new(None);
        assert_eq!(f.step(1.0, 1.0, 0.1), None);
        assert_eq!(f.record(), None);
    }

    #[test]
    fn a_delta_that_does_not_fall_gives_no_estimate() {
        let mut f = Forecast::new(Some(0.01));
        for k in 1..=10 {
            assert_eq!(f.step(k as f64, k as f64, 0.05), None);
        }
    }
}
