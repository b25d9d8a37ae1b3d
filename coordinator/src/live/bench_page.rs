//! The live page of `coordinator bench --serve`: the runs done and to do, and every chart as it is redrawn
//! after each run.

use super::auth::{self, Access};
use axum::extract::{Path as UrlPath, State};
use axum::http::{header, StatusCode};
use axum::response::{Html, IntoResponse, Json, Response};
use axum::routing::{get, post};
use axum::Router;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::sync::watch;

/// Where one run of the bench is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BenchRunState {
    Waiting,
    Running,
    Done,
}

/// One run of the bench as the page lists it.
#[derive(Clone, Debug, Serialize)]
pub struct BenchRun {
    /// Scene, method, threads and repeat in words.
    pub label: String,
    pub state: BenchRunState,
    /// The run's figures once done.
    pub result: Option<String>,
}

/// The bench as of its last run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BenchView {
    pub runs: Vec<BenchRun>,
    /// File names of the charts' PNGs in the bench's `charts/` folder, as last drawn.
    pub charts: Vec<String>,
    pub finished: bool,
    /// Why the bench stopped early, if it did.
    pub failed: Option<String>,
}

/// What the page's handlers share.
#[derive(Clone)]
struct BenchPage {
    view: watch::Receiver<Arc<BenchView>>,
    charts: PathBuf,
}

/// The page's routes, behind `access`; `charts` is the folder the bench draws its charts into.
pub fn router(view: watch::Receiver<Arc<BenchView>>, charts: PathBuf, access: Access) -> Router {
    Router::new()
        .route("/", get(|| async { Html(include_str!("bench.html")) }))
        .route("/state.json", get(state))
        .route("/charts/{name}", get(chart))
        .with_state(BenchPage { view, charts })
        .layer(axum::middleware::from_fn_with_state(access.clone(), auth::require))
        .merge(Router::new().route("/login", post(auth::login)).with_state(access))
}

async fn state(State(page): State<BenchPage>) -> Json<BenchView> {
    Json((**page.view.borrow()).clone())
}

/// A chart's PNG, by a name the bench listed (so no other file of the machine can be asked for).
async fn chart(State(page): State<BenchPage>, UrlPath(name): UrlPath<String>) -> Response {
    if !page.view.borrow().charts.contains(&name) {
        return (StatusCode::NOT_FOUND, "no such chart").into_response();
    }
    match tokio::fs::read(page.charts.join(&name)).await {
        Ok(bytes) => {
            ([(header::CONTENT_TYPE, "image/png"), (header::CACHE_CONTROL, "no-store")], bytes).into_response()
        }
        Err(e) => (StatusCode::NOT_FOUND, format!("cannot read the chart {name}: {e}")).into_response(),
    }
}

/// The live page of one bench: its thread and the view it publishes. Every update is cheap; the charts are drawn
/// by the bench itself.
pub struct BenchLive {
    tx: watch::Sender<Arc<BenchView>>,
    pub url: String,
    _thread: super::server::LiveThread,
}

impl BenchLive {
    /// Serves the page on `addr` (loopback, or any address with `secret`) listing `labels` as the runs to do.
    pub fn start(
        addr: std::net::SocketAddr,
        secret: Option<photonfarm::protocol::Secret>,
        labels: Vec<String>,
        charts: PathBuf,
    ) -> anyhow::Result<BenchLive> {
        let access = Access::for_bind(addr, secret)?;
        let runs = labels.into_iter().map(|label| BenchRun { label, state: BenchRunState::Waiting, result: None });
        let (tx, rx) = watch::channel(Arc::new(BenchView { runs: runs.collect(), ..BenchView::default() }));
        let thread = super::server::LiveThread::start()?;
        let url = super::server::url_of(thread.serve(addr, router(rx, charts, access))?);
        Ok(BenchLive { tx, url, _thread: thread })
    }

    fn update(&self, change: impl FnOnce(&mut BenchView)) {
        let mut view = (**self.tx.borrow()).clone();
        change(&mut view);
        self.tx.send_replace(Arc::new(view));
    }

    /// Run `i` (of the labels) has started.
    pub fn running(&self, i: usize) {
        self.update(|v| v.runs[i].state = BenchRunState::Running);
    }

    /// Run `i` is done with `result`; `charts` are the PNG file names now in the charts folder.
    pub fn done(&self, i: usize, result: String, charts: Vec<String>) {
        self.update(|v| {
            v.runs[i].state = BenchRunState::Done;
            v.runs[i].result = Some(result);
            v.charts = charts;
        });
    }

    /// The bench ended: `failed` says why when it did not finish.
    pub fn end(&self, failed: Option<String>) {
        self.update(|v| {
            v.finished = failed.is_none();
            v.failed = failed;
        });
    }
}
