//! The JSON record of a run: enough to reproduce it (scene hash, settings, seed) and to chart its speed against
//! its accuracy (rays and δ after every phase).

use super::forecast::ForecastRecord;
use super::method::Method;
use super::settings::RenderSettings;
use super::totals::RayTotals;
use crate::accumulation::{ErrorEstimate, LitMaskRecord};
use crate::geometry::BvhCacheUse;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::str::FromStr;

/// δ and ray counts after one step (a phase, a round, or a merged snapshot), and the true error when the run
/// has a reference: the points of the error-against-time charts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    pub phase: u64,
    pub time_s: f64,
    pub delta_all: f64,
    pub delta_unlit: f64,
    pub backward_rays: u64,
    pub forward_rays: u64,
    /// The light paths per pixel of the step that ended here; None where a distributed run's workers chose
    /// their own.
    #[serde(default)]
    pub light_paths_per_pixel: Option<f32>,
    /// The camera paths' diffuse depth of the step that ended here; None where a distributed run's workers
    /// chose their own.
    #[serde(default)]
    pub backward_diffuse_depth: Option<u32>,
    /// Relative RMSE against the reference over all pixels and over the pixels the lit mask leaves unlit.
    /// Always serialized (null without a reference): checkpoints keep the history with bincode, which cannot
    /// skip fields.
    #[serde(default)]
    pub true_all: Option<f64>,
    #[serde(default)]
    pub true_unlit: Option<f64>,
    /// Tiles the step rendered, with adaptive tiles (null when every tile rendered every step).
    #[serde(default)]
    pub active_tiles: Option<u32>,
    /// The photon discs' blur's part of `delta_all` and `delta_unlit` (`ErrorEstimate`).
    #[serde(default)]
    pub blur_all: f64,
    #[serde(default)]
    pub blur_unlit: f64,
}

impl HistoryEntry {
    /// The entry of a step that ended `time_s` into the run with the error `e` and the counters `t`; `light`,
    /// `depth` and `active_tiles` are what the step rendered with, where the run knows them. The true error is
    /// the caller's to add, when it has a reference.
    pub fn after_step(
        time_s: f64,
        e: &ErrorEstimate,
        t: &RayTotals,
        light: Option<f32>,
        depth: Option<u32>,
        active_tiles: Option<u32>,
    ) -> Self {
        HistoryEntry {
            phase: t.phases,
            time_s,
            delta_all: e.delta_all,
            delta_unlit: e.delta_unlit,
            backward_rays: t.backward_rays,
            forward_rays: t.forward_rays,
            light_paths_per_pixel: light,
            backward_diffuse_depth: depth,
            true_all: None,
            true_unlit: None,
            active_tiles,
            blur_all: e.blur_all,
            blur_unlit: e.blur_unlit,
        }
    }
}

/// Error against a reference image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrueError {
    /// The reference EXR.
    pub reference: String,
    /// Relative RMSE of luminance over all pixels.
    pub rmse_all: f64,
    /// Relative RMSE over the pixels the lit mask leaves unlit.
    pub rmse_unlit: f64,
    /// The reference's own δ over the same pixels (from its `sem` layer): it adds in quadrature to the error
    /// measured against it, so a true error near it says more about the reference than about the run.
    #[serde(default)]
    pub reference_delta_all: Option<f64>,
    #[serde(default)]
    pub reference_delta_unlit: Option<f64>,
    /// The image's mean luminance relative to the reference's, minus one, over all pixels and over pixels that
    /// do not see a light: the systematic part of the error.
    #[serde(default)]
    pub mean_difference_all: Option<f64>,
    #[serde(default)]
    pub mean_difference_unlit: Option<f64>,
}

/// Thread-seconds spent in each stage of the phases, summed over threads: where a parallel engine's time goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageSeconds {
    /// Camera paths and their backward photons.
    pub backward: f64,
    /// Building the photon map.
    pub build: f64,
    /// Light paths while the map is open.
    pub forward: f64,
    /// The owner's light paths while it waits for other groups to leave its map, and the phase's normalisation.
    pub closing: f64,
    /// Threads idle at the end of a synchronisation round, waiting for the other groups to stop.
    pub waiting: f64,
    /// Forming the whole image and dealing masks between rounds (every thread idle).
    pub between_rounds: f64,
}

/// One worker process of a distributed run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WorkerRecord {
    pub name: String,
    /// Where its link came from or went to.
    pub address: String,
    pub numa_node: Option<u32>,
    pub cores: Vec<usize>,
    /// The pinning the worker obtained, in its words.
    pub binding: String,
    pub layout: String,
    pub state: WorkerState,
    /// Snapshots merged, and the bytes of their frames.
    pub snapshots: u64,
    pub snapshot_bytes: u64,
    /// What its merged snapshots contributed.
    pub totals: RayTotals,
    /// Pixel-phases merged (Σ over pixels of the phases it added).
    pub pixel_phases: u64,
    /// The worker's snapshot interval at its last snapshot, and how long it took to send the one before, until
    /// its acknowledgement (s): the interval grows on slow links so that sending stays under 5% of it.
    pub snapshot_interval_s: f64,
    pub last_send_s: f64,
    /// Seconds from the launch of the workers to the worker's start of rendering (process start, link, job,
    /// meshes, scene and engine set-up): the distribution's fixed cost.
    #[serde(default)]
    pub started_after_s: f64,
    /// Of those, the seconds the worker took to build the scene from the files received (meshes read, their
    /// BVH built).
    #[serde(default)]
    pub scene_load_s: f64,
    /// What the BVH cache did for the worker's scene; None until the worker has started.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bvh_cache: Option<BvhCacheUse>,
    /// The worker process's peak resident memory at its last snapshot.
    #[serde(default)]
    pub peak_memory_bytes: Option<u64>,
    /// The worker's estimate of its peak memory, made before its engine allocated (`RunRecord`'s field).
    #[serde(default)]
    pub memory_estimate_bytes: Option<u64>,
    /// Phase values with a NaN or an infinity the worker dropped (any is a bug, and flagged in the record).
    #[serde(default)]
    pub non_finite_dropped: u64,
    /// Lost links of workers from this worker's host so far in the job (0 for the workers the coordinator
    /// starts itself): at `--max-worker-failures` the host is refused for the rest of the job.
    #[serde(default)]
    pub failures: u32,
}

/// Where a worker of a distributed run is in its life: "connecting", "running", "finished" or "lost: why" in
/// the record.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum WorkerState {
    #[default]
    Connecting,
    Running,
    Finished,
    /// Dropped from the run (its link broke, it failed, hung or sent a bad snapshot): why, in words.
    Lost(String),
}

impl WorkerState {
    /// The worker will send nothing more: it finished or was lost.
    pub fn ended(&self) -> bool {
        matches!(self, WorkerState::Finished | WorkerState::Lost(_))
    }
}

impl fmt::Display for WorkerState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WorkerState::Connecting => f.write_str("connecting"),
            WorkerState::Running => f.write_str("running"),
            WorkerState::Finished => f.write_str("finished"),
            WorkerState::Lost(why) => write!(f, "lost: {why}"),
        }
    }
}

/// Text that is not a worker state.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is not a worker state (connecting, running, finished or lost: why)")]
pub struct UnknownWorkerState(pub String);

impl FromStr for WorkerState {
    type Err = UnknownWorkerState;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "connecting" => Ok(WorkerState::Connecting),
            "running" => Ok(WorkerState::Running),
            "finished" => Ok(WorkerState::Finished),
            _ => match s.strip_prefix("lost: ") {
                Some(why) => Ok(WorkerState::Lost(why.to_string())),
                None => Err(UnknownWorkerState(s.to_string())),
            },
        }
    }
}

// The record keeps the state as one string, the reason of a lost worker included.
impl Serialize for WorkerState {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for WorkerState {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        String::deserialize(deserializer)?.parse().map_err(serde::de::Error::custom)
    }
}

fn first_session() -> u32 {
    1
}

/// Why a run ended, written in the record as the words "time", "phases", "target-error", "interrupted",
/// "no-workers", or "running" in the records written while it renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// The `--time` rule.
    Time,
    /// The `--phases` rule.
    Phases,
    /// The `--target-error` rule.
    TargetError,
    /// Ctrl-C, or the live page's stop.
    Interrupted,
    /// Every worker of a distributed run was lost.
    NoWorkers,
    /// The run goes on: a record written on the way.
    Running,
}

impl StopReason {
    /// The word the record uses.
    pub fn name(self) -> &'static str {
        match self {
            StopReason::Time => "time",
            StopReason::Phases => "phases",
            StopReason::TargetError => "target-error",
            StopReason::Interrupted => "interrupted",
            StopReason::NoWorkers => "no-workers",
            StopReason::Running => "running",
        }
    }
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The record written as `run.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    pub photonfarm_version: String,
    pub scene: String,
    pub scene_hash: String,
    pub width: u32,
    pub height: u32,
    /// The method the user asked for.
    pub method: Method,
    /// How the threads were laid out, e.g. "2 groups × 1 thread, tile masks, shared maps".
    pub layout: String,
    /// Threads whose pinning to a core the OS accepted.
    pub pinned_threads: usize,
    pub settings: RenderSettings,
    /// Photon radius of a phase-1 photon at 1 m camera-path length (m): the footprint-derived scale.
    pub radius_at_1m: f32,
    pub threads: u32,
    /// Why the run stopped, or `running` in the records written while it renders.
    pub stop_reason: StopReason,
    pub totals: RayTotals,
    /// Where the threads' time went (parallel engines only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage_seconds: Option<StageSeconds>,
    pub wall_time_s: f64,
    /// Seconds from the command's start to the start of rendering (reading the scene, deciding what the run
    /// needs before it, starting its engine): the command's wall time is this plus this session's share of
    /// `wall_time_s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub started_s: Option<f64>,
    /// Of those, the seconds this process took to read the scene and build it (meshes read, their BVH built).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_load_s: Option<f64>,
    /// What the BVH cache did for this process's scene, when it built one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bvh_cache: Option<BvhCacheUse>,
    pub peak_memory_bytes: Option<u64>,
    /// This process's peak memory as estimated before it allocated what the image's size scales (the scene
    /// loaded, plus the engine's buffers or, in a distributed run's coordinator, the merged sums, the copy a save
    /// writes from, its checkpoint encoding and a snapshot being merged): the estimate `--memory-limit` and the
    /// machine's available memory are checked against.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub memory_estimate_bytes: Option<u64>,
    pub bytes_per_pixel: f64,
    pub error: ErrorEstimate,
    /// The pixels that see a light, decided before the render: δ unlit and the true error over unlit pixels
    /// leave them out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lit_mask: Option<LitMaskRecord>,
    /// The edge in pixels of the tiles a run with a target error retires (none for a run without adaptive tiles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive_tile: Option<u32>,
    /// With a target error: the estimate of the time still needed, and the one made when δ first came within
    /// twice the target next to when the target was actually met.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub forecast: Option<ForecastRecord>,
    /// Phases summed over pixels: what the image holds, whichever process rendered them.
    #[serde(default)]
    pub pixel_phases: u64,
    /// The session of a resumed run (1 for a run that was never resumed).
    #[serde(default = "first_session")]
    pub session: u32,
    pub true_error: Option<TrueError>,
    pub history: Vec<HistoryEntry>,
    /// The worker processes of a distributed run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub workers: Option<Vec<WorkerRecord>>,
    /// Whatever the run clamped, capped, dropped or lost, in words: empty for a run that estimated everything
    /// it was asked to.
    #[serde(default)]
    pub flags: Vec<String>,
}

/// The flags of a run record: light paths capped by `max_depth`, non-finite values dropped, workers lost.
pub fn flags_of(totals: &RayTotals, non_finite_dropped: u64, workers: Option<&[WorkerRecord]>) -> Vec<String> {
    let mut flags = Vec::new();
    if totals.capped_light_paths > 0 {
        flags.push(format!(
            "{} light paths ({:.3}%) were stopped by max_depth while still carrying flux: the image lacks their \
             light (raise [render] max_depth to include it)",
            totals.capped_light_paths,
            100.0 * totals.capped_light_paths as f64 / totals.light_paths.max(1) as f64
        ));
    }
    if non_finite_dropped > 0 {
        flags.push(format!(
            "{non_finite_dropped} phase values with a NaN or an infinity were dropped (a renderer bug: please \
             report it with this scene)"
        ));
    }
    for w in workers.unwrap_or_default() {
        if let WorkerState::Lost(_) = w.state {
            flags.push(format!("worker {} {}; its merged phases stay in the image", w.name, w.state));
        }
    }
    flags
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stop_reasons_are_the_words_of_the_record() {
        let reasons = [
            (StopReason::Time, "time"),
            (StopReason::Phases, "phases"),
            (StopReason::TargetError, "target-error"),
            (StopReason::Interrupted, "interrupted"),
            (StopReason::NoWorkers, "no-workers"),
            (StopReason::Running, "running"),
        ];
        for (reason, text) in reasons {
            assert_eq!(serde_json::to_value(reason).unwrap(), serde_json::Value::String(text.into()));
            assert_eq!(serde_json::from_value::<StopReason>(text.into()).unwrap(), reason);
            assert_eq!(reason.to_string(), text);
        }
        assert!(serde_json::from_value::<StopReason>("timeout".into()).is_err());
    }

    #[test]
    fn worker_states_are_the_words_of_the_record() {
        let states = [
            (WorkerState::Connecting, "connecting"),
            (WorkerState::Running, "running"),
            (WorkerState::Finished, "finished"),
            (WorkerState::Lost("presumed hung".into()), "lost: presumed hung"),
        ];
        for (state, text) in states {
            assert_eq!(serde_json::to_value(&state).unwrap(), serde_json::Value::String(text.into()));
            assert_eq!(serde_json::from_value::<WorkerState>(text.into()).unwrap(), state);
            assert_eq!(state.ended(), matches!(state, WorkerState::Finished | WorkerState::Lost(_)));
        }
        assert!("stopped".parse::<WorkerState>().is_err());
    }

    #[test]
    fn a_lost_worker_is_flagged_with_why() {
        let lost = WorkerRecord {
            name: "node1".into(),
            state: WorkerState::Lost("its link broke".into()),
            ..WorkerRecord::default()
        };
        let finished = WorkerRecord { name: "node0".into(), state: WorkerState::Finished, ..WorkerRecord::default() };
        let flags = flags_of(&RayTotals::default(), 0, Some(&[finished, lost]));
        assert_eq!(flags, ["worker node1 lost: its link broke; its merged phases stay in the image"]);
    }
}
