//! A progressive run: phases until a time, phase or error target is met, or the user interrupts.

use super::active_tiles::ActiveTiles;
use super::engine::Engine;
use super::forecast::Forecast;
use super::light_balance::LightBalance;
use super::record::HistoryEntry;
pub use super::record::StopReason;
use super::settings::RenderSettings;
use super::totals::RayTotals;
pub use crate::accumulation::ErrorOver;
use crate::accumulation::{Accumulator, LitMask};
use crate::pbpm::RadiusSchedule;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// When a timed run stops: at `at`, and no phase that would end more than `slack` later is started. A phase
/// lasts as long as the renderer's previous one, so on a large image a phase is seconds to minutes: one started
/// just before the deadline would end that much late.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Deadline {
    pub at: Instant,
    pub slack: Duration,
}

impl Deadline {
    /// The share of `--time` a run may end late by, besides the remainder of a phase cut at the deadline.
    pub const SLACK_FRACTION: f64 = 0.02;

    /// True when a phase of `duration` started now would end after the deadline's slack.
    pub fn too_late_for(&self, duration: Duration) -> bool {
        Instant::now() + duration > self.at + self.slack
    }

    /// Waits until the deadline or until `interrupted` is set.
    pub fn wait(&self, interrupted: &AtomicBool) {
        while !interrupted.load(Ordering::Relaxed) {
            let left = self.at.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return;
            }
            std::thread::sleep(left.min(Duration::from_millis(20)));
        }
    }
}

/// A renderer that improves its running sums step by step: the single-threaded engine (a step is a phase) or a
/// parallel engine (a step is a synchronisation round).
pub trait Progressive {
    /// Renders one more step; a parallel step ends early when `interrupted` is set or the deadline passes,
    /// always closing the phases it started. A phase expected to end past the deadline's slack is not started.
    fn step(&mut self, interrupted: &AtomicBool, deadline: Option<Deadline>);
    /// The running sums.
    fn sums(&self) -> &Accumulator;
    /// The running sums as a value a save can read on a thread of its own while the renderer goes on, for
    /// renderers that add nothing to them while it is held (a distributed one defers its merges); None for the
    /// others, whose saves run between their steps.
    fn shared_sums(&self) -> Option<std::sync::Arc<Accumulator>> {
        None
    }
    /// Counts so far.
    fn totals(&self) -> RayTotals;
    /// The settings.
    fn settings(&self) -> &RenderSettings;
    /// Bytes the renderer holds per pixel (sums, phase buffers, photon maps).
    fn bytes_per_pixel(&self) -> f64;
    /// Threads it renders with.
    fn threads(&self) -> usize;
    /// Threads whose pinning to a core the OS accepted (0 when the renderer does not pin).
    fn pinned_threads(&self) -> usize {
        0
    }
    /// Thread-seconds per stage, for renderers that measure them.
    fn stage_seconds(&self) -> Option<super::record::StageSeconds> {
        None
    }
    /// The worker processes, for distributed renderers.
    fn workers(&self) -> Option<Vec<super::record::WorkerRecord>> {
        None
    }
    /// False when the renderer can make no more progress (every worker is gone).
    fn active(&self) -> bool {
        true
    }
    /// Collects the work still in flight once the run has stopped (a distributed renderer's last snapshots).
    fn finish(&mut self) {}
    /// Sets the light paths per pixel of the steps to come; false for a renderer whose workers choose their own.
    fn set_light_paths_per_pixel(&mut self, _l: f32) -> bool {
        false
    }
    /// Sets the camera paths' diffuse depth of the steps to come; false for a renderer whose workers choose
    /// their own.
    fn set_backward_diffuse_depth(&mut self, _depth: u32) -> bool {
        false
    }
    /// Renders only `tiles`' active tiles from the next step on.
    fn set_active_tiles(&mut self, tiles: &ActiveTiles);
    /// Returns once the renderer renders: at once for one that renders in this process; for a distributed one
    /// when its first worker has loaded the scene and runs its engine (or every worker has ended, or on
    /// interruption), so that a run's clock and its `--time` count rendering, not the workers' loading.
    fn wait_until_rendering(&mut self, _interrupted: &AtomicBool) {}
    /// The lit mask a worker decided and the seconds it took, once: for a distributed renderer whose workers
    /// decide it (`protocol::Job::decide_lit_mask`), after `wait_until_rendering`; None for the others.
    fn take_lit_mask(&mut self) -> Option<(LitMask, f64)> {
        None
    }
}

impl Progressive for Engine<'_> {
    fn step(&mut self, interrupted: &AtomicBool, deadline: Option<Deadline>) {
        match (deadline, self.last_phase_duration()) {
            (Some(d), Some(last)) if d.too_late_for(last) => d.wait(interrupted),
            _ => {
                self.run_phase();
            }
        }
    }
    fn sums(&self) -> &Accumulator {
        Engine::sums(self)
    }
    fn totals(&self) -> RayTotals {
        Engine::totals(self)
    }
    fn settings(&self) -> &RenderSettings {
        Engine::settings(self)
    }
    fn bytes_per_pixel(&self) -> f64 {
        Engine::bytes_per_pixel(self)
    }
    fn threads(&self) -> usize {
        1
    }
    fn set_light_paths_per_pixel(&mut self, l: f32) -> bool {
        Engine::set_light_paths_per_pixel(self, l);
        true
    }
    fn set_backward_diffuse_depth(&mut self, depth: u32) -> bool {
        Engine::set_backward_diffuse_depth(self, depth);
        true
    }
    fn set_active_tiles(&mut self, tiles: &ActiveTiles) {
        Engine::set_active_tiles(self, tiles);
    }
}

/// Gives the renderer the balance's L and depth for its next step; false for a renderer whose workers choose
/// their own.
pub fn set_balance<R: Progressive + ?Sized>(engine: &mut R, balance: &LightBalance) -> bool {
    let light = engine.set_light_paths_per_pixel(balance.next());
    light && balance.depth().is_none_or(|d| engine.set_backward_diffuse_depth(d))
}

/// When to stop; the first rule met wins. `phases` counts the phases every pixel has received, or with adaptive
/// tiles the pixels' mean phases (`phases_done`). With no rule at all the run would never end, so callers set one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopRule {
    pub time: Option<Duration>,
    pub phases: Option<u64>,
    pub target_error: Option<f64>,
    pub error_over: ErrorOver,
}

/// What a run measures its error over and forecasts with, besides the stop rule.
pub struct Tracking<'a> {
    /// The pixels that see a light, left out of δ unlit.
    pub lit: &'a LitMask,
    /// The forecast of the time to the target error (it estimates nothing without one).
    pub forecast: &'a mut Forecast,
    /// Wall time spent in earlier sessions of the same run (resume).
    pub elapsed_before: Duration,
    /// Adaptive tiles: the tiles still above the target error, decided after every step from the merged sums
    /// (None renders every tile every step).
    pub tiles: Option<&'a mut ActiveTiles>,
}

impl StopRule {
    /// What the `phases` rule counts: the fewest phases of any pixel, or with adaptive tiles, whose retired
    /// pixels stop gaining phases, the pixels' mean (the work of that many phases over the whole image).
    pub fn phases_done(&self, sums: &Accumulator, adaptive_tiles: bool) -> f64 {
        if adaptive_tiles {
            sums.image_phases()
        } else {
            sums.min_phases() as f64
        }
    }

    /// The δ of `e` that the target error refers to.
    pub fn delta_of(&self, e: &crate::accumulation::ErrorEstimate) -> f64 {
        match self.error_over {
            ErrorOver::Unlit => e.delta_unlit,
            ErrorOver::All => e.delta_all,
        }
    }
}

/// Runs phases until `stop` or `interrupted`; `on_phase` sees the engine, the history and the forecast after
/// every phase.
pub fn run<R: Progressive + ?Sized>(
    engine: &mut R,
    stop: &StopRule,
    interrupted: &AtomicBool,
    history: &mut Vec<HistoryEntry>,
    tracking: Tracking,
    mut on_phase: impl FnMut(&R, &mut [HistoryEntry], &Forecast),
) -> StopReason {
    let Tracking { lit, forecast, elapsed_before, mut tiles } = tracking;
    let start = Instant::now();
    // The light paths per pixel and the camera paths' diffuse depth, chosen as the run goes unless they were
    // fixed; a distributed renderer's workers choose their own.
    let mut balance = LightBalance::for_run(engine.settings(), engine.sums(), engine.totals());
    if balance.as_ref().is_some_and(|b| !set_balance(engine, b)) {
        balance = None;
    }
    // Tiles only retire towards a target; a resumed run starts from what its sums already say.
    let target = stop.target_error.filter(|_| tiles.is_some());
    let adaptive = target.is_some();
    let decide = |engine: &mut R, tiles: &mut Option<&mut ActiveTiles>| {
        if let (Some(t), Some(target)) = (tiles.as_deref_mut(), target) {
            let decay = RadiusSchedule::blur_decay(engine.settings().radius_alpha);
            if t.update(engine.sums(), lit, stop.error_over, target, decay) {
                engine.set_active_tiles(t);
            }
        }
    };
    decide(engine, &mut tiles);
    loop {
        if interrupted.load(Ordering::Relaxed) {
            return StopReason::Interrupted;
        }
        if stop.phases.is_some_and(|n| stop.phases_done(engine.sums(), adaptive) >= n as f64) {
            return StopReason::Phases;
        }
        let deadline = stop.time.map(|t| Deadline {
            at: start + t.saturating_sub(elapsed_before),
            slack: t.mul_f64(Deadline::SLACK_FRACTION),
        });
        if let Some(b) = &balance {
            set_balance(engine, b);
        }
        let s = engine.settings();
        let light = (balance.is_some() || !s.adaptive_light).then_some(s.light_paths_per_pixel);
        let depth = (balance.is_some() || !s.adaptive_depth).then_some(s.backward_diffuse_depth);
        let active_tiles = tiles.as_deref().filter(|_| target.is_some()).map(|t| t.active_count() as u32);
        engine.step(interrupted, deadline);
        if let Some(b) = &mut balance {
            b.observe(engine.sums(), engine.totals());
        }
        // The step's time is when its sums were complete, not when their error was worked out.
        let time_s = (elapsed_before + start.elapsed()).as_secs_f64();
        let e = engine.sums().error(lit);
        let entry = HistoryEntry::after_step(time_s, &e, &engine.totals(), light, depth, active_tiles);
        history.push(entry);
        forecast.step(entry.time_s, engine.sums().image_phases(), stop.delta_of(&e));
        on_phase(engine, history, forecast);
        if !engine.active() {
            return StopReason::NoWorkers;
        }
        if let Some(target) = stop.target_error {
            if stop.delta_of(&e) <= target {
                return StopReason::TargetError;
            }
        }
        if let Some(limit) = stop.time {
            if start.elapsed() + elapsed_before >= limit {
                return StopReason::Time;
            }
        }
        if stop.phases.is_some_and(|n| stop.phases_done(engine.sums(), adaptive) >= n as f64) {
            return StopReason::Phases;
        }
        decide(engine, &mut tiles);
    }
}
