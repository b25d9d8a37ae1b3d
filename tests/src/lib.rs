//! Helpers for the end-to-end tests in `tests/tests/`: they start the real programs, built by cargo.

pub mod room;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The repository's root folder.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ lives in the repository").to_path_buf()
}

/// Path of a workspace binary, built once per test process by the cargo that runs the tests, with the profile
/// the tests were built with. `--workspace --bins --tests` resolves the features as `cargo test --workspace`
/// does (dev-dependencies included), so after scripts/test's build this only links the programs: no
/// dependency is built a second time.
pub fn binary(name: &str) -> PathBuf {
    static PROFILE_DIR: OnceLock<PathBuf> = OnceLock::new();
    let dir = PROFILE_DIR.get_or_init(|| {
        // A test program lives in <target dir>/<profile dir>/deps/: `release` for `cargo test --release`,
        // `debug` for the test profile.
        let exe = std::env::current_exe().expect("the test program's own path");
        let profile_dir = exe.parent().and_then(Path::parent).expect("a test program lives in <profile dir>/deps");
        let profile = if profile_dir.ends_with("release") { "release" } else { "test" };
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut build = Command::new(cargo);
        // Cargo gives a test the variables of the package it belongs to; some build scripts (ring's) rerun
        // when those change, so passed on they would rebuild half the workspace under the tests' feet.
        const OF_THE_TEST: [&str; 8] = [
            "CARGO_MANIFEST_DIR",
            "CARGO_MANIFEST_PATH",
            "CARGO_CRATE_NAME",
            "CARGO_PRIMARY_PACKAGE",
            "CARGO_TARGET_TMPDIR",
            "CARGO_BIN_NAME",
            "CARGO_RUSTC_CURRENT_DIR",
            "OUT_DIR",
        ];
        for (name, _) in std::env::vars_os() {
            let name = name.to_string_lossy();
            if name.starts_with("CARGO_PKG_") || name.starts_with("CARGO_BIN_EXE_") || OF_THE_TEST.contains(&&*name) {
                build.env_remove(&*name);
            }
        }
        let status = build
            .args(["build", "--quiet", "--profile", profile, "--workspace", "--bins", "--tests"])
            .current_dir(repo_root())
            .status()
            .expect("cannot run cargo to build the programs under test");
        assert!(status.success(), "building the programs under test failed");
        profile_dir.to_path_buf()
    });
    dir.join(name)
}

/// A fresh, empty folder for one test's outputs, removed when it goes out of scope unless the test is failing:
/// then it stays, and its path is printed, so that the failure's images and records can be looked at.
pub struct Scratch(tempfile::TempDir);

/// A new scratch folder named after `name` in the system's temporary folder.
pub fn scratch_dir(name: &str) -> Scratch {
    let dir = tempfile::Builder::new()
        .prefix(&format!("photonfarm-e2e-{name}-"))
        .tempdir()
        .expect("cannot create a scratch folder");
    Scratch(dir)
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.disable_cleanup(true);
            eprintln!("the failing test's scratch folder is kept: {}", self.0.path().display());
        }
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.path().as_os_str()
    }
}

/// The shipped Cornell box at `size` × `size` pixels, copied with its meshes into `dir`: a scene the tests can
/// resize without touching `scenes/`.
pub fn cornell_at(dir: &Path, size: u32) -> PathBuf {
    let root = repo_root().join("scenes");
    let text = std::fs::read_to_string(root.join("cornell.toml")).expect("scenes/cornell.toml");
    let text =
        text.replace("width = 256", &format!("width = {size}")).replace("height = 256", &format!("height = {size}"));
    std::fs::create_dir_all(dir.join("cornell")).expect("cannot create the scene folder");
    for e in std::fs::read_dir(root.join("cornell")).expect("scenes/cornell/") {
        let e = e.expect("a mesh of scenes/cornell/");
        std::fs::copy(e.path(), dir.join("cornell").join(e.file_name())).expect("cannot copy a mesh");
    }
    let path = dir.join("cornell.toml");
    std::fs::write(&path, text).expect("cannot write the scene");
    path
}

/// Runs `coordinator render SCENE --out OUT --quiet ARGS…` from the repository root and returns its output.
pub fn render_output(scene: &Path, out: &Path, args: &[&str]) -> Output {
    Command::new(binary("coordinator"))
        .arg("render")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .args(args)
        .current_dir(repo_root())
        .output()
        .expect("cannot start the coordinator")
}

/// A user-space network link for tests: a TCP proxy whose two directions are each a delay line behind a rate
/// limit, like a router's queue drained at the link's rate followed by the wire's propagation delay, so that a
/// slow, distant link can be emulated where the kernel has no netem. It can also keep a copy of every byte
/// that crosses it, to check what an eavesdropper would see.
pub mod link {
    use std::net::SocketAddr;
    use std::sync::{Arc, Mutex};
    use std::time::Duration;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio::net::{TcpListener, TcpSocket, TcpStream};
    use tokio::sync::mpsc;
    use tokio::time::Instant;

    /// What the emulated link does to the bytes crossing it, in each direction.
    #[derive(Clone, Copy, Debug)]
    pub struct Shape {
        /// Propagation delay, one way.
        pub delay: Duration,
        /// Link rate in bits per second (None: as fast as the machine goes).
        pub rate_bits_per_s: Option<f64>,
    }

    impl Shape {
        /// No delay, no rate limit: a recording tap only.
        pub const NONE: Shape = Shape { delay: Duration::ZERO, rate_bits_per_s: None };
    }

    /// A running proxy; it stops when dropped.
    pub struct Proxy {
        /// Where the proxy listens.
        pub addr: SocketAddr,
        captured: Arc<Mutex<Vec<u8>>>,
        runtime: Option<tokio::runtime::Runtime>,
    }

    /// Bytes read from one side before they are queued: also the granularity of the delay line.
    const CHUNK: usize = 16 << 10;
    /// Chunks in flight per direction: room for the delay line of a fast, distant link (100 Mbit/s × 20 ms is
    /// 250 kB). The reader itself waits for the link's rate, so a sender feels the rate through TCP's flow
    /// control instead of handing everything to the proxy.
    const QUEUE: usize = 64;

    impl Proxy {
        /// Listens on `listen` and relays every connection to `target` through a link of `shape`; with
        /// `record`, keeps both directions' bytes (see `captured`).
        pub fn start(listen: SocketAddr, target: SocketAddr, shape: Shape, record: bool) -> Self {
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .worker_threads(1)
                .enable_all()
                .build()
                .expect("a runtime for the link proxy");
            let captured = Arc::new(Mutex::new(Vec::new()));
            let listener = runtime.block_on(async {
                let socket = if listen.is_ipv4() { TcpSocket::new_v4() } else { TcpSocket::new_v6() }
                    .expect("a socket for the proxy");
                socket.set_reuseaddr(true).expect("SO_REUSEADDR");
                // Small kernel buffers on the proxy's side, so that the queue below is what holds bytes.
                socket.set_recv_buffer_size(64 << 10).expect("SO_RCVBUF");
                socket.bind(listen).unwrap_or_else(|e| panic!("the proxy cannot listen on {listen}: {e}"));
                socket.listen(16).expect("listen")
            });
            let addr = listener.local_addr().expect("the proxy's address");
            let tap = record.then(|| captured.clone());
            runtime.spawn(accept_loop(listener, target, shape, tap));
            Proxy { addr, captured, runtime: Some(runtime) }
        }

        /// Every byte relayed so far, both directions, each chunk as it crossed.
        pub fn captured(&self) -> Vec<u8> {
            self.captured.lock().unwrap().clone()
        }
    }

    impl Drop for Proxy {
        fn drop(&mut self) {
            if let Some(r) = self.runtime.take() {
                r.shutdown_background();
            }
        }
    }

    async fn accept_loop(listener: TcpListener, target: SocketAddr, shape: Shape, tap: Option<Arc<Mutex<Vec<u8>>>>) {
        while let Ok((inbound, _)) = listener.accept().await {
            let tap = tap.clone();
            tokio::spawn(async move {
                let Ok(outbound) = TcpStream::connect(target).await else { return };
                let _ = (inbound.set_nodelay(true), outbound.set_nodelay(true));
                let (ri, wi) = inbound.into_split();
                let (ro, wo) = outbound.into_split();
                tokio::spawn(direction(ri, wo, shape, tap.clone()));
                tokio::spawn(direction(ro, wi, shape, tap));
            });
        }
    }

    /// Relays one direction: chunks leave the queue at the link's rate and arrive `delay` later, in order.
    async fn direction(
        mut from: tokio::net::tcp::OwnedReadHalf,
        mut to: tokio::net::tcp::OwnedWriteHalf,
        shape: Shape,
        tap: Option<Arc<Mutex<Vec<u8>>>>,
    ) {
        let (tx, mut rx) = mpsc::channel::<(Vec<u8>, Instant)>(QUEUE);
        let writer = tokio::spawn(async move {
            while let Some((chunk, due)) = rx.recv().await {
                tokio::time::sleep_until(due).await;
                if to.write_all(&chunk).await.is_err() {
                    return;
                }
            }
            let _ = to.shutdown().await;
        });
        // When the link finishes sending what is queued: the next chunk starts then or on arrival.
        let mut link_free = Instant::now();
        let mut buf = vec![0u8; CHUNK];
        loop {
            let n = match from.read(&mut buf).await {
                Ok(0) | Err(_) => break,
                Ok(n) => n,
            };
            if let Some(tap) = &tap {
                tap.lock().unwrap().extend_from_slice(&buf[..n]);
            }
            let now = Instant::now();
            let start = link_free.max(now);
            let serialise =
                shape.rate_bits_per_s.map_or(Duration::ZERO, |r| Duration::from_secs_f64(n as f64 * 8.0 / r));
            link_free = start + serialise;
            // Hold the reader until the link has sent the chunk: the rate limit is what the sender feels.
            if tx.send((buf[..n].to_vec(), link_free + shape.delay)).await.is_err() {
                break;
            }
            tokio::time::sleep_until(link_free).await;
        }
        drop(tx);
        let _ = writer.await;
    }
}

#[cfg(test)]
mod tests {
    use super::scratch_dir;

    #[test]
    fn a_scratch_folder_is_removed_after_a_passing_test_and_kept_after_a_failing_one() {
        let passed = scratch_dir("scratch-passes");
        std::fs::write(passed.join("image.exr"), b"x").unwrap();
        let path = passed.to_path_buf();
        drop(passed);
        assert!(!path.exists(), "{} outlived its test", path.display());

        let kept = std::thread::spawn(|| {
            let failing = scratch_dir("scratch-fails");
            std::fs::write(failing.join("image.exr"), b"x").unwrap();
            std::panic::panic_any(failing.to_path_buf());
        })
        .join()
        .unwrap_err();
        let kept = kept.downcast_ref::<std::path::PathBuf>().expect("the failing test's folder");
        assert!(kept.join("image.exr").is_file(), "{} was removed with the failing test", kept.display());
        std::fs::remove_dir_all(kept).unwrap();
    }
}
