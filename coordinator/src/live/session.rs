//! The live view of one `coordinator render`: the thread, the page (`--serve`) and the tev stream (`--display
//! tev`), fed by the render loop through a [`LiveFeed`].

use super::auth::Access;
use super::feed::LiveFeed;
use super::render_page::{self, RenderPage};
use super::server::{url_of, LiveThread};
use super::tev;
use anyhow::Result;
use photonfarm::accumulation::{Accumulator, AuxLayout, LitMask};
use photonfarm::protocol::Secret;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// What to show the run on.
pub struct LiveOptions {
    /// `--serve`: the address of the page, and the job's secret if there is one.
    pub serve: Option<(SocketAddr, Option<Secret>)>,
    /// `--display tev`: where tev listens.
    pub tev: Option<String>,
    /// The run's image size and layers, whose empty sums the page shows before the first merge (made only when
    /// a live view is asked for: a large image's sums are gigabytes).
    pub image: (u32, u32, AuxLayout),
    /// The run's lit pixels, which δ unlit leaves out.
    pub lit: Arc<LitMask>,
    /// The run's settings as the page serves them.
    pub settings: serde_json::Value,
    pub dir: PathBuf,
    pub interrupted: Arc<AtomicBool>,
}

/// A running live view; dropping it ends the page and the stream.
pub struct LiveSession {
    pub feed: LiveFeed,
    /// The page's URL, when served.
    pub url: Option<String>,
    // Dropped last: the feed's end closes the tev stream first.
    _thread: LiveThread,
}

impl LiveSession {
    /// Starts what `options` asks for, or nothing (None) when it asks for neither a page nor tev. A page on a
    /// non-loopback address without a secret, or on an address that cannot be bound, is an error.
    pub fn start(options: LiveOptions) -> Result<Option<LiveSession>> {
        if options.serve.is_none() && options.tev.is_none() {
            return Ok(None);
        }
        let access = match &options.serve {
            Some((addr, secret)) => Some((*addr, Access::for_bind(*addr, secret.clone())?)),
            None => None,
        };
        let thread = LiveThread::start()?;
        let (width, height, aux) = options.image;
        let (feed, views) = LiveFeed::new(Accumulator::with_aux(width, height, aux), options.lit);
        let mut url = None;
        if let Some((addr, access)) = access {
            let page = RenderPage {
                view: views.clone(),
                settings: Arc::new(options.settings),
                dir: options.dir.clone(),
                interrupted: options.interrupted,
            };
            url = Some(url_of(thread.serve(addr, render_page::router(page, access))?));
        }
        if let Some(address) = options.tev {
            let name = options.dir.file_name().map_or("photonfarm".into(), |n| n.to_string_lossy().into_owned());
            tev::spawn(thread.handle(), address, name, views);
        }
        Ok(Some(LiveSession { feed, url, _thread: thread }))
    }
}
