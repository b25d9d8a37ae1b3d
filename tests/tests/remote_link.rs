//! A remote worker behind a slow link: a `worker serve` daemon in its own network namespace, reached over a
//! veth pair shaped by `tc netem` to 100 Mbit/s with 20 ms delay each way, authenticated by a shared secret.
//! Needs root (CI runs as root) and iproute2 (scripts/system-packages installs it).

use end_to_end::{binary, repo_root, scratch_dir};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn ip(args: &[&str]) {
    let o = Command::new("ip").args(args).output().expect("the `ip` command (iproute2) is needed");
    assert!(o.status.success(), "ip {}: {}", args.join(" "), String::from_utf8_lossy(&o.stderr));
}

/// A network namespace with a shaped veth link to the host; removed on drop.
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
        // netem gives rate and delay; kernels without it (this sandbox's) still have tbf for the rate.
        let netem = ["root", "netem", "rate", "100mbit", "delay", "20ms"];
        let tbf = ["root", "tbf", "rate", "100mbit", "burst", "64kb", "latency", "50ms"];
        let tc = |prefix: Vec<&str>| {
            let run = |shape: &[&str]| Command::new(prefix[0]).args(&prefix[1..]).args(shape).output().unwrap();
            let o = run(&netem);
            if o.status.success() {
                return;
            }
            eprintln!(
                "netem unavailable ({}): shaping with tbf to 100 Mbit/s, no added delay",
                String::from_utf8_lossy(&o.stderr).trim()
            );
            let o = run(&tbf);
            assert!(o.status.success(), "{}: {}", prefix.join(" "), String::from_utf8_lossy(&o.stderr));
        };
        tc(vec!["tc", "qdisc", "add", "dev", &host_if]);
        tc(vec!["ip", "netns", "exec", &ns, "tc", "qdisc", "add", "dev", &remote_if]);
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

#[test]
fn a_remote_worker_behind_a_slow_link_completes_the_run_and_its_snapshot_interval_adapts() {
    assert!(is_root(), "this test builds a network namespace and needs root (CI runs as root)");
    let dir = scratch_dir("remote");
    let secret = dir.join("secret");
    std::fs::write(&secret, "a secret shared by the coordinator and the server\n").unwrap();
    let mut host = RemoteHost::new(std::process::id() % 100_000);
    let log = std::fs::File::create(dir.join("daemon.log")).unwrap();
    host.daemon = Some(
        Command::new("ip")
            .args(["netns", "exec", &host.ns])
            .arg(binary("worker"))
            .args(["serve", "--listen", "10.213.0.2:7879", "--name", "server", "--secret-file"])
            .arg(&secret)
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
    );
    // Wait until the daemon listens (a probe connection is logged by it as a failed handshake).
    let start = Instant::now();
    while TcpStream::connect_timeout(&"10.213.0.2:7879".parse().unwrap(), Duration::from_millis(500)).is_err() {
        assert!(start.elapsed() < Duration::from_secs(15), "the worker daemon did not start listening");
        std::thread::sleep(Duration::from_millis(100));
    }
    let out = dir.join("out");
    let o = Command::new(binary("coordinator"))
        .args(["render", "scenes/cornell.toml", "--method", "three-level", "--remote-only", "--quiet"])
        .args(["--worker", "10.213.0.2:7879", "--time", "14", "--reference", "scenes/references/cornell-path.exr"])
        .arg("--secret-file")
        .arg(&secret)
        .arg("--out")
        .arg(&out)
        .current_dir(repo_root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    let w = &r["workers"][0];
    assert_eq!(w["state"], "finished", "{w}");
    assert_eq!(w["address"], "10.213.0.2:7879");
    assert!(w["snapshots"].as_u64().unwrap() >= 2, "{w}");
    // A 256×256 snapshot takes a noticeable time on 100 Mbit/s: the interval grows past its 1 s start so that
    // sending stays under 5% of it.
    let (interval, send) = (w["snapshot_interval_s"].as_f64().unwrap(), w["last_send_s"].as_f64().unwrap());
    eprintln!(
        "remote worker: {} snapshots, {:.2} MB each, last send {send:.3} s, interval {interval:.2} s",
        w["snapshots"],
        w["snapshot_bytes"].as_f64().unwrap() / w["snapshots"].as_f64().unwrap() / 1e6
    );
    assert!(send > 0.05 && interval > 1.0 && send <= 0.05 * interval + 1e-3, "interval {interval} s, send {send} s");
    // The image is right: its true error agrees with its own error estimate.
    let (truth, delta) = (r["true_error"]["rmse_unlit"].as_f64().unwrap(), r["error"]["delta_unlit"].as_f64().unwrap());
    assert!(truth < 1.5 * delta, "true error {truth} against δ {delta}");
}
