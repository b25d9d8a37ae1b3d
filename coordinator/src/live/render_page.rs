//! The live page of `coordinator render --serve`: the page itself, the run's state as JSON, any layer as a PNG,
//! the settings, the run record, and a stop that does what Ctrl-C does.

use super::auth::{self, Access};
use super::feed::{RunState, RunView};
use super::image::{layer_names, layer_png, Exposure};
use axum::extract::{Query, State};
use axum::http::{header, StatusCode};
use axum::response::{Html, IntoResponse, Json, Response};
use axum::routing::{get, post};
use axum::Router;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use tokio::sync::watch;

/// Most points of δ against time sent to the page: plenty for a chart a few hundred pixels wide.
const HISTORY_POINTS: usize = 400;
/// Seconds of history over which the current ray rate is measured.
const RATE_WINDOW_S: f64 = 5.0;

/// What the page's handlers share.
#[derive(Clone)]
pub struct RenderPage {
    pub view: watch::Receiver<Arc<RunView>>,
    /// The run's settings, as `/settings.json` serves them.
    pub settings: Arc<serde_json::Value>,
    /// The output folder, where run.json is.
    pub dir: PathBuf,
    /// The flag Ctrl-C sets: the stop button sets it too.
    pub interrupted: Arc<AtomicBool>,
}

/// The page's routes, behind `access`.
pub fn router(page: RenderPage, access: Access) -> Router {
    Router::new()
        .route("/", get(|| async { Html(include_str!("render.html")) }))
        .route("/state.json", get(state))
        .route("/image.png", get(image))
        .route("/settings.json", get(settings))
        .route("/run.json", get(run_record))
        .route("/stop", post(stop))
        .with_state(page)
        .layer(axum::middleware::from_fn_with_state(access.clone(), auth::require))
        .merge(Router::new().route("/login", post(auth::login)).with_state(access))
}

/// The run's state as `/state.json` gives it.
#[derive(Serialize)]
struct StateJson {
    state: &'static str,
    /// The stop reason once finished.
    stop_reason: Option<String>,
    elapsed_s: f64,
    width: u32,
    height: u32,
    layers: Vec<String>,
    phases: u64,
    min_phases: u32,
    delta_all: Option<f64>,
    delta_unlit: Option<f64>,
    true_all: Option<f64>,
    true_unlit: Option<f64>,
    /// Rays per second over the last few seconds, and over the whole run.
    rays_per_s: f64,
    mean_rays_per_s: f64,
    rays: u64,
    /// With a target error: the estimated seconds still needed, and the estimated end of the run (run time, s).
    remaining_s: Option<f64>,
    predicted_end_s: Option<f64>,
    history: Vec<Point>,
    workers: Vec<WorkerJson>,
}

/// One point of δ (and the true error) against time.
#[derive(Serialize)]
struct Point {
    t: f64,
    delta_all: Option<f64>,
    delta_unlit: Option<f64>,
    true_all: Option<f64>,
    true_unlit: Option<f64>,
}

#[derive(Serialize)]
struct WorkerJson {
    name: String,
    address: String,
    numa_node: Option<u32>,
    cores: Vec<usize>,
    binding: String,
    /// "connecting", "running", "finished" or "lost".
    state: &'static str,
    lost_because: Option<String>,
    phases: u64,
    rays: u64,
    snapshots: u64,
    /// Seconds since its last snapshot was merged.
    last_snapshot_ago_s: Option<f64>,
    /// The link's snapshot interval.
    link_interval_s: f64,
}

/// δ is not a number until pixels have two phases; JSON has no NaN.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

fn state_json(view: &RunView) -> StateJson {
    use photonfarm::render::record::WorkerState;
    let (state, stop_reason) = match &view.state {
        RunState::Running => ("running", None),
        RunState::Stopping => ("stopping", None),
        RunState::Finished(reason) => ("finished", Some(reason.clone())),
    };
    let rays_of = |t: &photonfarm::render::RayTotals| t.backward_rays + t.forward_rays;
    let rays = rays_of(&view.totals);
    let h = &view.history;
    let rays_per_s = match h.last() {
        Some(last) => {
            let from = h.iter().rev().find(|e| last.time_s - e.time_s >= RATE_WINDOW_S).or(h.first());
            from.filter(|f| last.time_s > f.time_s).map_or(0.0, |f| {
                let d = (last.backward_rays + last.forward_rays).saturating_sub(f.backward_rays + f.forward_rays);
                d as f64 / (last.time_s - f.time_s)
            })
        }
        None => 0.0,
    };
    let every = h.len().div_ceil(HISTORY_POINTS).max(1);
    let mut points: Vec<usize> = (0..h.len()).step_by(every).collect();
    if h.len() > 1 && points.last() != Some(&(h.len() - 1)) {
        points.push(h.len() - 1);
    }
    let history = points
        .into_iter()
        .map(|i| Point {
            t: h[i].time_s,
            delta_all: finite(h[i].delta_all),
            delta_unlit: finite(h[i].delta_unlit),
            true_all: h[i].true_all,
            true_unlit: h[i].true_unlit,
        })
        .collect();
    let workers = view
        .workers
        .iter()
        .map(|w| {
            let r = &w.record;
            let (state, lost_because) = match &r.state {
                WorkerState::Connecting => ("connecting", None),
                WorkerState::Running => ("running", None),
                WorkerState::Finished => ("finished", None),
                WorkerState::Lost(why) => ("lost", Some(why.clone())),
            };
            WorkerJson {
                name: r.name.clone(),
                address: r.address.clone(),
                numa_node: r.numa_node,
                cores: r.cores.clone(),
                binding: r.binding.clone(),
                state,
                lost_because,
                phases: r.totals.phases,
                rays: rays_of(&r.totals),
                snapshots: r.snapshots,
                last_snapshot_ago_s: w.last_snapshot_s.map(|t| (view.elapsed_s - t).max(0.0)),
                link_interval_s: r.snapshot_interval_s,
            }
        })
        .collect();
    StateJson {
        state,
        stop_reason,
        elapsed_s: view.elapsed_s,
        width: view.sums.width,
        height: view.sums.height,
        layers: layer_names(&view.sums),
        phases: view.totals.phases,
        min_phases: view.error.min_phases,
        delta_all: finite(view.error.delta_all),
        delta_unlit: finite(view.error.delta_unlit),
        true_all: view.true_error.map(|t| t.0),
        true_unlit: view.true_error.map(|t| t.1),
        rays_per_s,
        mean_rays_per_s: if view.elapsed_s > 0.0 { rays as f64 / view.elapsed_s } else { 0.0 },
        rays,
        remaining_s: view.forecast.and_then(|f| finite(f.remaining_s)),
        predicted_end_s: view.forecast.and_then(|f| finite(f.end_s())),
        history,
        workers,
    }
}

async fn state(State(page): State<RenderPage>) -> Json<StateJson> {
    let view = page.view.borrow().clone();
    Json(state_json(&view))
}

/// `/image.png`'s query: `layer` (default total), and `exposure` (a linear factor) or `ev` (stops above the
/// automatic exposure, default 0).
#[derive(Deserialize)]
struct ImageQuery {
    layer: Option<String>,
    exposure: Option<f32>,
    ev: Option<f32>,
}

async fn image(State(page): State<RenderPage>, Query(q): Query<ImageQuery>) -> Response {
    let view = page.view.borrow().clone();
    let layer = q.layer.unwrap_or_else(|| "total".into());
    let exposure = match q.exposure {
        Some(f) => Exposure::Factor(f),
        None => Exposure::Auto { ev: q.ev.unwrap_or(0.0) },
    };
    // Encoding takes milliseconds to tens of them: off the thread that answers the other requests.
    let encoded = tokio::task::spawn_blocking(move || layer_png(&view.sums, &layer, exposure)).await;
    match encoded {
        Ok(Ok(png)) => {
            ([(header::CONTENT_TYPE, "image/png"), (header::CACHE_CONTROL, "no-store")], png).into_response()
        }
        Ok(Err(e)) => (StatusCode::BAD_REQUEST, e.to_string()).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("the image could not be made: {e}")).into_response(),
    }
}

async fn settings(State(page): State<RenderPage>) -> Json<serde_json::Value> {
    Json((*page.settings).clone())
}

async fn run_record(State(page): State<RenderPage>) -> Response {
    let path = page.dir.join("run.json");
    match tokio::fs::read(&path).await {
        Ok(bytes) => (
            [
                (header::CONTENT_TYPE, "application/json"),
                (header::CONTENT_DISPOSITION, "attachment; filename=\"run.json\""),
            ],
            bytes,
        )
            .into_response(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            (StatusCode::NOT_FOUND, "run.json is written every --save-interval seconds and at the end: not yet written")
                .into_response()
        }
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot read {}: {e}", path.display())).into_response(),
    }
}

/// Ends the run as Ctrl-C does: the engine stops after its current phase and every output is written.
async fn stop(State(page): State<RenderPage>) -> Response {
    let already = page.interrupted.swap(true, Ordering::SeqCst);
    let text = if already { "already stopping" } else { "stopping: the last completed phases are being written" };
    (StatusCode::ACCEPTED, text).into_response()
}
