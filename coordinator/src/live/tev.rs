//! `--display tev[=HOST:PORT]`: every layer of the sums, streamed to a running tev viewer after each published
//! view, over tev's TCP protocol (one CreateImage with every layer's channels, then an UpdateImage per layer).
//! tev is a convenience: one that is not running, or goes away, is a warning and the render goes on; the stream
//! reconnects when tev comes back.

use super::feed::RunView;
use photonfarm::render::images::{layer_images, lit_layer, phases_layer};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::Arc;
use std::time::Duration;
use tev_client::{PacketCreateImage, PacketUpdateImage, TevClient};
use tokio::runtime::Handle;
use tokio::sync::watch;

/// Where tev listens unless told otherwise.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:14158";
/// A tev that takes longer than this to take one layer is treated as gone.
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
const CONNECT_TIMEOUT: Duration = Duration::from_secs(1);

/// The link to tev: connected or not, and whether the user was told it is not.
struct TevLink {
    address: String,
    image: String,
    client: Option<TevClient>,
    /// The image's size and layers as created in tev: a change (none so far) would need a new CreateImage.
    created: Option<(u32, u32, Vec<String>)>,
    warned: bool,
}

/// Streams every view `views` publishes to tev at `address` as the image `image`, on `runtime`'s blocking
/// threads, until the render loop drops its end of the feed.
pub fn spawn(runtime: &Handle, address: String, image: String, mut views: watch::Receiver<Arc<RunView>>) {
    let mut link = TevLink { address, image, client: None, created: None, warned: false };
    runtime.spawn(async move {
        while views.changed().await.is_ok() {
            let view = views.borrow_and_update().clone();
            match tokio::task::spawn_blocking(move || {
                link.send(&view);
                link
            })
            .await
            {
                Ok(l) => link = l,
                Err(_) => return,
            }
        }
    });
}

impl TevLink {
    fn send(&mut self, view: &RunView) {
        if self.client.is_none() {
            match connect(&self.address) {
                Ok(stream) => {
                    if self.warned {
                        tracing::info!("connected to tev at {}", self.address);
                    }
                    self.client = Some(TevClient::wrap(stream));
                    self.created = None;
                    self.warned = false;
                }
                Err(e) => {
                    if !self.warned {
                        tracing::warn!(
                            "no tev at {} ({e}); the render goes on, and the layers go to tev once it listens there",
                            self.address
                        );
                        self.warned = true;
                    }
                    return;
                }
            }
        }
        if let Err(e) = self.send_layers(view) {
            tracing::warn!("tev at {} went away ({e}); the render goes on", self.address);
            self.client = None;
            self.warned = true;
        }
    }

    fn send_layers(&mut self, view: &RunView) -> std::io::Result<()> {
        let Some(client) = self.client.as_mut() else { return Ok(()) };
        let mut layers = layer_images(&view.sums);
        layers.push(lit_layer(&view.lit));
        layers.push(phases_layer(&view.sums));
        let (width, height) = (view.sums.width, view.sums.height);
        let names: Vec<String> = layers.iter().map(|l| l.name.clone()).collect();
        if self.created.as_ref() != Some(&(width, height, names.clone())) {
            let channels: Vec<String> =
                names.iter().flat_map(|n| ["R", "G", "B"].map(|c| format!("{n}.{c}"))).collect();
            client.send(PacketCreateImage {
                image_name: &self.image,
                grab_focus: false,
                width,
                height,
                channel_names: &channels,
            })?;
            self.created = Some((width, height, names));
        }
        for layer in &layers {
            let channels = ["R", "G", "B"].map(|c| format!("{}.{c}", layer.name));
            let data: Vec<f32> = layer.rgb.iter().flatten().copied().collect();
            client.send(PacketUpdateImage {
                image_name: &self.image,
                grab_focus: false,
                channel_names: &channels,
                channel_offsets: &[0, 1, 2],
                channel_strides: &[3, 3, 3],
                x: 0,
                y: 0,
                width,
                height,
                data: &data,
            })?;
        }
        Ok(())
    }
}

fn connect(address: &str) -> std::io::Result<TcpStream> {
    let addrs: Vec<SocketAddr> = address.to_socket_addrs()?.collect();
    let mut last = std::io::Error::new(std::io::ErrorKind::NotFound, "the address resolves to nothing");
    for a in addrs {
        match TcpStream::connect_timeout(&a, CONNECT_TIMEOUT) {
            Ok(s) => {
                s.set_write_timeout(Some(WRITE_TIMEOUT))?;
                s.set_nodelay(true)?;
                return Ok(s);
            }
            Err(e) => last = e,
        }
    }
    Err(last)
}
