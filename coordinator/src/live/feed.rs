//! The render loop's side of the live view: after a merge it publishes the merged sums and the run's progress
//! as one immutable [`RunView`] on a `tokio::sync::watch` channel, which the page and tev read when they like.

use photonfarm::accumulation::{Accumulator, ErrorEstimate, LitMask};
use photonfarm::render::forecast::Estimate;
use photonfarm::render::record::{HistoryEntry, RunRecord, WorkerRecord};
use photonfarm::render::session::Progressive;
use photonfarm::render::RayTotals;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// Fewest milliseconds between two published views: the page polls about once a second, and tev redraws no
/// faster than a person can look.
const MIN_INTERVAL: Duration = Duration::from_millis(250);
/// A view costs a copy of the sums; publishing waits this many times as long as the last copy took, so that
/// copying never takes more than 2% of the render loop's time on a large image.
const COPY_COST_FACTOR: u32 = 50;

/// Where the run is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RunState {
    Running,
    /// Stopped by its stop rule, Ctrl-C or the page: the last phases are being collected and written.
    Stopping,
    /// Every output is written; the string is the record's stop reason.
    Finished(String),
}

/// One worker of a distributed run as the page lists it.
#[derive(Clone, Debug)]
pub struct WorkerRow {
    pub record: WorkerRecord,
    /// Run time (s) at which its last snapshot was merged, to the view's publishing interval.
    pub last_snapshot_s: Option<f64>,
}

/// The run as of one merge: what the page and tev show. Immutable once published.
#[derive(Clone, Debug)]
pub struct RunView {
    pub sums: Arc<Accumulator>,
    pub error: ErrorEstimate,
    /// Relative RMSE against the reference (all pixels, unlit pixels), when the run has one.
    pub true_error: Option<(f64, f64)>,
    pub totals: RayTotals,
    pub history: Vec<HistoryEntry>,
    /// Empty for the in-process methods.
    pub workers: Vec<WorkerRow>,
    pub state: RunState,
    /// Rendering time so far, seconds.
    pub elapsed_s: f64,
    /// With a target error: the latest estimate of the time still needed.
    pub forecast: Option<Estimate>,
    /// The run's lit pixels, shown as a layer beside the image's.
    pub lit: Arc<LitMask>,
}

impl RunView {
    /// The view before the first merge: a black image of the scene's size.
    fn empty(sums: Accumulator, lit: Arc<LitMask>) -> RunView {
        RunView {
            error: sums.error(&lit),
            sums: Arc::new(sums),
            true_error: None,
            totals: RayTotals::default(),
            history: Vec::new(),
            workers: Vec::new(),
            state: RunState::Running,
            elapsed_s: 0.0,
            forecast: None,
            lit,
        }
    }
}

/// The publishing end, owned by the render loop.
pub struct LiveFeed {
    tx: watch::Sender<Arc<RunView>>,
    last_publish: Option<Instant>,
    last_copy: Duration,
    /// Per worker: snapshots merged when last seen, and when the count last grew.
    seen: Vec<(u64, Option<f64>)>,
    /// The run's lit pixels, which δ unlit leaves out.
    lit: Arc<LitMask>,
    /// The latest estimate of the time still needed.
    forecast: Option<Estimate>,
}

impl LiveFeed {
    /// A feed whose first view is `blank` (empty sums of the scene's size and layers), and a receiver of it;
    /// δ unlit leaves out the pixels of `lit`.
    pub fn new(blank: Accumulator, lit: Arc<LitMask>) -> (LiveFeed, watch::Receiver<Arc<RunView>>) {
        let (tx, rx) = watch::channel(Arc::new(RunView::empty(blank, lit.clone())));
        (LiveFeed { tx, last_publish: None, last_copy: Duration::ZERO, seen: Vec::new(), lit, forecast: None }, rx)
    }

    /// Called after every step of the render loop with the latest forecast: notes the workers' snapshots, and
    /// publishes a view unless one was published too recently.
    pub fn after_merge(
        &mut self,
        engine: &dyn Progressive,
        history: &[HistoryEntry],
        elapsed_s: f64,
        forecast: Option<Estimate>,
    ) {
        self.forecast = forecast.or(self.forecast);
        let workers = self.worker_rows(engine, elapsed_s);
        let wait = MIN_INTERVAL.max(self.last_copy * COPY_COST_FACTOR);
        if self.last_publish.is_some_and(|t| t.elapsed() < wait) {
            return;
        }
        let true_error = history.last().and_then(|h| Some((h.true_all?, h.true_unlit?)));
        let view = self.view(engine, history, workers, true_error, RunState::Running, elapsed_s);
        self.send(view);
    }

    /// Publishes that the run is stopping: its last phases are being collected.
    pub fn stopping(&mut self, engine: &dyn Progressive, history: &[HistoryEntry], elapsed_s: f64) {
        let workers = self.worker_rows(engine, elapsed_s);
        let true_error = self.tx.borrow().true_error;
        let view = self.view(engine, history, workers, true_error, RunState::Stopping, elapsed_s);
        self.send(view);
    }

    /// Publishes the final sums with the figures of the record written, so the page ends on what run.json says.
    pub fn finished(&mut self, engine: &dyn Progressive, record: &RunRecord) {
        let workers = self.worker_rows(engine, record.wall_time_s);
        let true_error = record.true_error.as_ref().map(|t| (t.rmse_all, t.rmse_unlit));
        let state = RunState::Finished(record.stop_reason.to_string());
        let mut view = self.view(engine, &record.history, workers, true_error, state, record.wall_time_s);
        (view.error, view.totals) = (record.error, record.totals);
        view.forecast = record.forecast.as_ref().and_then(|f| f.latest);
        self.send(view);
    }

    fn worker_rows(&mut self, engine: &dyn Progressive, elapsed_s: f64) -> Vec<WorkerRow> {
        let records = engine.workers().unwrap_or_default();
        self.seen.resize(records.len(), (0, None));
        records
            .into_iter()
            .zip(&mut self.seen)
            .map(|(record, (snapshots, at))| {
                if record.snapshots > *snapshots {
                    (*snapshots, *at) = (record.snapshots, Some(elapsed_s));
                }
                WorkerRow { record, last_snapshot_s: *at }
            })
            .collect()
    }

    /// A view of the engine now: the copy of its sums is the cost of publishing, and is timed.
    fn view(
        &mut self,
        engine: &dyn Progressive,
        history: &[HistoryEntry],
        workers: Vec<WorkerRow>,
        true_error: Option<(f64, f64)>,
        state: RunState,
        elapsed_s: f64,
    ) -> RunView {
        let copying = Instant::now();
        let sums = Arc::new(engine.sums().clone());
        self.last_copy = copying.elapsed();
        RunView {
            error: sums.error(&self.lit),
            sums,
            true_error,
            totals: engine.totals(),
            history: history.to_vec(),
            workers,
            state,
            elapsed_s,
            forecast: self.forecast,
            lit: self.lit.clone(),
        }
    }

    fn send(&mut self, view: RunView) {
        self.last_publish = Some(Instant::now());
        // Nobody watching is not an error: the page may not be open.
        self.tx.send_replace(Arc::new(view));
    }
}
