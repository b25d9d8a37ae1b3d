//! A remote worker behind a slow, distant link: a `worker serve` daemon in its own network namespace, reached
//! over a veth pair through the test harness's link emulator (`end_to_end::link`: 20 ms each way, 100 Mbit/s;
//! the kernel here has no netem), over TLS with the job's keys. The run completes, the worker's snapshot
//! interval adapts to the link, and its throughput matches a run over the same path without the emulator.
//! Needs root (CI runs as root) and iproute2 (scripts/system-packages installs it).

use end_to_end::link::{Proxy, Shape};
use end_to_end::{binary, repo_root, scratch_dir};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn ip(args: &[&str]) {
    let o = Command::new("ip").args(args).output().expect("the `ip` command (iproute2) is needed");
    assert!(o.status.success(), "ip {}: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
}

/// A network namespace with a veth link to the host; removed on drop.
struct RemoteHost {
    ns: String,
    host_if: String,
    daemon: Option<Child>,
}

impl RemoteHost {
    fn new(tag: u32) -> Self {
        let (ns, host_if, remote_if) = (format!("pf-remote-{tag}"), format!("pfh{tag}"), format!("pfr{tag}"));
        let _ = Command::new("ip").args(["netns", "del", &ns]).stderr(Stdio::null()).status();
        let _ = Command::new("ip").args(["link", "del", &host_if]).stderr(Stdio::null()).status();
        ip(&["netns", "add", &ns]);
        let host = RemoteHost { ns: ns.clone(), host_if: host_if.clone(), daemon: None };
        ip(&["link", "add", &host_if, "type", "veth", "peer", "name", &remote_if]);
        ip(&["link", "set", &remote_if, "netns", &ns]);
        ip(&["addr", "add", "10.213.0.1/24", "dev", &host_if]);
        ip(&["link", "set", &host_if, "up"]);
        ip(&["netns", "exec", &ns, "ip", "addr", "add", "10.213.0.2/24", "dev", &remote_if]);
        ip(&["netns", "exec", &ns, "ip", "link", "set", &remote_if, "up"]);
        ip(&["netns", "exec", &ns, "ip", "link", "set", "lo", "up"]);
        host
    }
}

impl Drop for RemoteHost {
    fn drop(&mut self) {
        if let Some(d) = &mut self.daemon {
            let _ = d.kill();
            let _ = d.wait();
        }
        let _ = Command::new("ip").args(["link", "del", &self.host_if]).stderr(Stdio::null()).status();
        let _ = Command::new("ip").args(["netns", "del", &self.ns]).stderr(Stdio::null()).status();
    }
}

fn is_root() -> bool {
    Command::new("id").arg("-u").output().map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0").unwrap_or(false)
}

/// Renders cornell for `seconds` on the remote daemon only, dialled at `address` over TLS; returns the record.
fn remote_render(dir: &Path, name: &str, address: &str, keys: &Path, seconds: &str) -> serde_json::Value {
    let out = dir.join(name);
    let o = Command::new(binary("coordinator"))
        .args(["render", "scenes/cornell.toml", "--method", "three-level", "--remote-only", "--quiet"])
        .args(["--worker", address, "--time", seconds, "--reference", "scenes/references/cornell-path.exr"])
        // Fixed, so that runs compared by rays per second trace the same mix of camera and light rays.
        .args(["--light-paths-per-pixel", "1"])
        .arg("--tls-dir")
        .arg(keys)
        .arg("--out")
        .arg(&out)
        .current_dir(repo_root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap()
}

/// Rays per second of wall time, from the start of the render to the last merged snapshot.
fn rays_per_second(r: &serde_json::Value) -> f64 {
    let t = &r["totals"];
    (t["backward_rays"].as_f64().unwrap() + t["forward_rays"].as_f64().unwrap()) / r["wall_time_s"].as_f64().unwrap()
}

#[test]
fn a_remote_worker_behind_a_slow_distant_link_adapts_its_snapshot_interval_and_keeps_its_throughput() {
    assert!(is_root(), "this test builds a network namespace and needs root (CI runs as root)");
    let dir = scratch_dir("remote");
    let keys = dir.join("keys");
    let o = Command::new(binary("coordinator")).arg("keys").arg("init").arg(&keys).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut host = RemoteHost::new(std::process::id() % 100_000);
    let log = std::fs::File::create(dir.join("daemon.log")).unwrap();
    host.daemon = Some(
        Command::new("ip")
            .args(["netns", "exec", &host.ns])
            .arg(binary("worker"))
            .args(["serve", "--listen", "10.213.0.2:7879", "--name", "server", "--tls-dir"])
            .arg(&keys)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
    );
    // Wait until the daemon listens (a probe connection is logged by it as a refused link).
    let start = Instant::now();
    while TcpStream::connect_timeout(&"10.213.0.2:7879".parse().unwrap(), Duration::from_millis(500)).is_err() {
        assert!(start.elapsed() < Duration::from_secs(15), "the worker daemon did not start listening");
        std::thread::sleep(Duration::from_millis(100));
    }
    // The same daemon, path and keys twice: straight over the veth pair, then through the emulated link.
    let direct = remote_render(&dir, "direct", "10.213.0.2:7879", &keys, "12");
    let shape = Shape { delay: Duration::from_millis(20), rate_bits_per_s: Some(100e6) };
    let slow_link = Proxy::start("10.213.0.1:0".parse().unwrap(), "10.213.0.2:7879".parse().unwrap(), shape, false);
    let r = remote_render(&dir, "slow", &slow_link.addr.to_string(), &keys, "12");
    let w = &r["workers"][0];
    assert_eq!(w["state"], "finished", "{w}");
    assert_eq!(w["address"], slow_link.addr.to_string());
    assert!(w["snapshots"].as_u64().unwrap() >= 2, "{w}");
    // A 256×256 snapshot takes a noticeable time on 100 Mbit/s: the interval grows past its 1 s start so that
    // sending (until the acknowledgement) stays under 5% of it.
    let (interval, send) = (w["snapshot_interval_s"].as_f64().unwrap(), w["last_send_s"].as_f64().unwrap());
    let (fast, slow) = (rays_per_second(&direct), rays_per_second(&r));
    eprintln!(
        "remote worker: {} snapshots, {:.2} MB each, last send {send:.3} s, interval {interval:.2} s; \
         {:.3} Mrays/s over the emulated link against {:.3} direct ({:.3})",
        w["snapshots"],
        w["snapshot_bytes"].as_f64().unwrap() / w["snapshots"].as_f64().unwrap() / 1e6,
        slow / 1e6,
        fast / 1e6,
        slow / fast
    );
    assert!(send > 0.05 && interval > 1.0 && send <= 0.05 * interval + 1e-3, "interval {interval} s, send {send} s");
    // The link costs only the set-up's round trips and the last snapshot's transfer, well under 5% of a 12 s
    // run, but two runs in a row on this shared 2-core machine differ by more than that (docs/distribution.md
    // gives measured ratios from 0.80 to 1.70), so the bound here only catches a worker that the link stalls.
    assert!(slow >= 0.7 * fast, "{slow:.0} rays/s over the slow link, {fast:.0} direct");
    // The image is right: its true error agrees with its own error estimate.
    let (truth, delta) = (r["true_error"]["rmse_unlit"].as_f64().unwrap(), r["error"]["delta_unlit"].as_f64().unwrap());
    assert!(truth < 1.5 * delta, "true error {truth} against δ {delta}");
}
