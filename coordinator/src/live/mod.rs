//! Watching a run as it converges: the live page of `render --serve` and `bench --serve`, and the stream of
//! layers to the tev viewer of `--display tev`. The render loop publishes a [`feed::RunView`] after a merge;
//! everything here reads those views on its own thread, so a slow client never slows the render.

pub mod auth;
pub mod bench_page;
pub mod feed;
pub mod image;
pub mod render_page;
pub mod server;
pub mod session;
pub mod tev;
