//! Encrypted links with the real programs: `coordinator keys init` makes the job's keys, a worker with them
//! joins over mutual TLS while a recording proxy between the two sees neither the scene's text nor the
//! snapshots' deltas (which the same proxy does see on a plaintext link), a worker with a certificate of
//! another CA and a plaintext worker are refused with a clear log line, and links off loopback refuse to start
//! without keys unless `--insecure` is given.

use end_to_end::link::{Proxy, Shape};
use end_to_end::{binary, cornell_at, repo_root, scratch_dir, Scratch};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn keys_init(dir: &Path) {
    let o = Command::new(binary("coordinator")).arg("keys").arg("init").arg(dir).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn wait_listening(addr: &str) {
    let start = Instant::now();
    while std::net::TcpStream::connect(addr).is_err() {
        assert!(start.elapsed() < Duration::from_secs(20), "nothing listens on {addr}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A remote-only render that accepts joining workers on `addr` for `seconds`, with `extra` arguments.
fn coordinator(scene: &Path, out: &Path, addr: &str, seconds: &str, extra: &[&str]) -> std::process::Child {
    Command::new(binary("coordinator"))
        .arg("render")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .args(["--quiet", "--method", "three-level", "--remote-only", "--listen", addr, "--time", seconds])
        .args(extra)
        .current_dir(repo_root())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn join(addr: &str, name: &str, tls_dir: Option<&Path>) -> Output {
    let mut c = Command::new(binary("worker"));
    c.args(["join", addr, "--name", name]);
    if let Some(d) = tls_dir {
        c.arg("--tls-dir").arg(d);
    }
    c.output().unwrap()
}

fn record(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap()
}

fn contains(haystack: &[u8], needle: &[u8]) -> bool {
    haystack.windows(needle.len()).any(|w| w == needle)
}

/// Snapshot deltas found in captured bytes: zstd frames (found by their magic number) that decompress to a
/// photonfarm delta. The sums inside a delta are byte-shuffled and compressed, so this, not a search for one
/// f64, is what finds pixel sums on the wire.
fn deltas_in(bytes: &[u8]) -> usize {
    let magic = 0xFD2FB528u32.to_le_bytes();
    let mut found = 0;
    for at in (0..bytes.len().saturating_sub(4)).filter(|&i| bytes[i..i + 4] == magic) {
        let Ok(mut d) = zstd::stream::read::Decoder::new(&bytes[at..]) else { continue };
        let mut head = [0u8; 4];
        let magics = [photonfarm::accumulation::delta::MAGIC, photonfarm::accumulation::delta::SPARSE_MAGIC];
        if std::io::Read::read_exact(&mut d, &mut head).is_ok() && magics.contains(&&head) {
            found += 1;
        }
    }
    found
}

struct Setup {
    dir: Scratch,
    scene: PathBuf,
}

/// A mesh's path as the scene's description names it: the job a plaintext link carries holds it verbatim.
const MESH_PATH: &str = "cornell/floor.obj";

fn setup(name: &str) -> Setup {
    let dir = scratch_dir(name);
    let scene = cornell_at(&dir, 24);
    assert!(dir.join(MESH_PATH).is_file(), "the scene's floor mesh moved");
    Setup { dir, scene }
}

#[test]
fn a_worker_with_the_jobs_keys_renders_over_tls_while_other_cas_and_plaintext_are_refused_and_an_eavesdropper_sees_nothing(
) {
    let s = setup("tls");
    let (keys, other) = (s.dir.join("keys"), s.dir.join("other-keys"));
    keys_init(&keys);
    keys_init(&other);
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let out = s.dir.join("out");
    let keys_arg = keys.to_str().unwrap();
    let child = coordinator(&s.scene, &out, &addr, "6", &["--tls-dir", keys_arg]);
    wait_listening(&addr);
    // A certificate of another job's CA: the TLS handshake fails on both sides.
    let foreign = join(&addr, "foreign", Some(&other));
    assert!(!foreign.status.success());
    let why = String::from_utf8_lossy(&foreign.stderr);
    assert!(why.contains("TLS: the peer's certificate is refused") && why.contains("not of this job's CA"), "{why}");
    // A worker that speaks plaintext to the TLS port.
    let plain = join(&addr, "plain", None);
    assert!(!plain.status.success(), "{}", String::from_utf8_lossy(&plain.stderr));
    // The job's worker, through a proxy that records every byte both ways.
    let tap = Proxy::start("127.0.0.1:0".parse().unwrap(), addr.parse().unwrap(), Shape::NONE, true);
    let good = join(&tap.addr.to_string(), "good", Some(&keys));
    assert!(good.status.success(), "{}", String::from_utf8_lossy(&good.stderr));
    let o = child.wait_with_output().unwrap();
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{log}");
    assert!(log.contains("TLS: the peer refused the TLS handshake"), "{log}");
    assert!(log.contains("does not speak TLS (a plaintext link to a TLS port"), "{log}");
    let r = record(&out);
    let workers = r["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 1, "only the worker with the job's keys joined: {workers:?}");
    assert_eq!(workers[0]["state"], "finished");
    assert!(workers[0]["snapshots"].as_u64().unwrap() >= 2, "{}", workers[0]);
    let wire = tap.captured();
    assert!(wire.len() > 10_000, "the proxy saw only {} bytes", wire.len());
    assert!(!contains(&wire, MESH_PATH.as_bytes()), "the scene's description crossed the link in clear");
    assert_eq!(deltas_in(&wire), 0, "pixel sums crossed the link in clear");

    // The same link without TLS (loopback needs none): the same searches find the description and the sums, so
    // they can fail.
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let out = s.dir.join("plain-out");
    let child = coordinator(&s.scene, &out, &addr, "3", &[]);
    wait_listening(&addr);
    let tap = Proxy::start("127.0.0.1:0".parse().unwrap(), addr.parse().unwrap(), Shape::NONE, true);
    let o = join(&tap.addr.to_string(), "clear", None);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(child.wait_with_output().unwrap().status.success());
    let wire = tap.captured();
    assert!(contains(&wire, MESH_PATH.as_bytes()), "the control run's capture lacks the scene's description");
    assert!(deltas_in(&wire) >= 1, "the control run's capture holds no delta");
}

#[test]
fn links_off_loopback_refuse_to_start_without_keys_unless_insecure() {
    let s = setup("tls-policy");
    let secret = s.dir.join("secret");
    std::fs::write(&secret, "a shared secret, long enough").unwrap();
    let port = free_port().to_string();
    let any = format!("0.0.0.0:{port}");
    let o = Command::new(binary("coordinator"))
        .arg("render")
        .arg(&s.scene)
        .args(["--quiet", "--method", "three-level", "--listen", &any, "--time", "1", "--secret-file"])
        .arg(&secret)
        .arg("--out")
        .arg(s.dir.join("refused"))
        .current_dir(repo_root())
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--tls-dir") && e.contains("--insecure"), "{e}");
    // A documentation address (TEST-NET-1): refused before any connection is tried.
    let o = Command::new(binary("worker"))
        .args(["join", "192.0.2.1:7878", "--name", "w", "--secret-file"])
        .arg(&secret)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--tls-dir") && e.contains("--insecure"), "{e}");
    let o = Command::new(binary("worker"))
        .args(["serve", "--listen", &any, "--name", "w", "--secret-file"])
        .arg(&secret)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--tls-dir"), "{e}");
    // With --insecure the coordinator starts (and renders with its local workers).
    let o = Command::new(binary("coordinator"))
        .arg("render")
        .arg(&s.scene)
        .args(["--quiet", "--method", "three-level", "--listen", &any, "--time", "1", "--insecure"])
        .arg("--out")
        .arg(s.dir.join("insecure"))
        .current_dir(repo_root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // keys init refuses a folder that already holds keys.
    let keys = s.dir.join("keys");
    keys_init(&keys);
    let o = Command::new(binary("coordinator")).arg("keys").arg("init").arg(&keys).output().unwrap();
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("already holds keys"));
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(keys.join("worker.key")).unwrap().permissions().mode();
        assert_eq!(mode & 0o077, 0, "a private key is readable by others: {mode:o}");
    }
}
