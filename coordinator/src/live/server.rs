//! The thread the live view runs on: a small tokio runtime of its own, so that the page answers and tev is fed
//! whatever the render method (the in-process engines run no runtime, and the cluster's network thread ends
//! before the last outputs are written). Dropping it ends the page and the tev stream.

use anyhow::{Context, Result};
use axum::Router;
use std::net::SocketAddr;
use std::thread::JoinHandle;
use std::time::Duration;
use tokio::runtime::Handle;
use tokio::sync::oneshot;

/// The running live thread.
pub struct LiveThread {
    handle: Handle,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl LiveThread {
    /// Starts the thread and its runtime.
    pub fn start() -> Result<LiveThread> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("cannot start the live page's runtime")?;
        let handle = runtime.handle().clone();
        let (stop, stopped) = oneshot::channel::<()>();
        let thread = std::thread::Builder::new()
            .name("live".into())
            .spawn(move || {
                runtime.block_on(async {
                    let _ = stopped.await;
                });
                // An image being encoded for a client that is gone is not worth waiting for.
                runtime.shutdown_timeout(Duration::from_secs(1));
            })
            .context("cannot start the live page's thread")?;
        Ok(LiveThread { handle, stop: Some(stop), thread: Some(thread) })
    }

    /// The runtime, to spawn the tev stream on.
    pub fn handle(&self) -> &Handle {
        &self.handle
    }

    /// Binds `addr` now (so that a port in use is an error before the render starts) and serves `router` on it;
    /// returns the address bound, with the port the system chose for port 0.
    pub fn serve(&self, addr: SocketAddr, router: Router) -> Result<SocketAddr> {
        let listener =
            std::net::TcpListener::bind(addr).with_context(|| format!("--serve: cannot listen on {addr}"))?;
        listener.set_nonblocking(true).context("--serve: cannot configure the listener")?;
        let bound = listener.local_addr().context("--serve: the listener has no address")?;
        let _guard = self.handle.enter();
        let listener = tokio::net::TcpListener::from_std(listener).context("--serve: cannot adopt the listener")?;
        self.handle.spawn(async move {
            if let Err(e) = axum::serve(listener, router).await {
                tracing::error!("the live page stopped: {e}");
            }
        });
        Ok(bound)
    }
}

impl Drop for LiveThread {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The URL to print for a bound address. A wildcard address (0.0.0.0) is printed as such: browsers on the host
/// reach it, and elsewhere the host's name takes its place.
pub fn url_of(bound: SocketAddr) -> String {
    format!("http://{bound}/")
}
