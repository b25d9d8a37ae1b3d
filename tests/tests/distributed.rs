//! The distributed methods with real processes: three-level on a synthetic two-node topology agrees with the
//! single-process engine, a worker killed or frozen mid-run is reported and the run completes with the rest,
//! and hostile connections to the coordinator are refused without disturbing the job.

mod common;

use common::{assert_same_image, record};
use end_to_end::{binary, cornell_at, repo_root, scratch_dir};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TWO_NODES: &str = "pack:1 numa:2 core:1 pu:1";

fn coordinator(scene: &Path, out: &Path, args: &[&str]) -> Command {
    let mut c = Command::new(binary("coordinator"));
    c.arg("render").arg(scene).arg("--out").arg(out).arg("--quiet").args(args).current_dir(repo_root());
    c
}

fn run_ok(mut c: Command) -> std::process::Output {
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

#[test]
fn workers_on_this_machines_nodes_bind_their_memory_to_their_node() {
    let dir = scratch_dir("memory-binding");
    let scene = cornell_at(&dir, 32);
    let out = dir.join("run");
    run_ok(coordinator(&scene, &out, &["--method", "three-level", "--phases", "8"]));
    let r = record(&out);
    let workers = r["workers"].as_array().unwrap();
    assert!(!workers.is_empty());
    for w in workers {
        let binding = w["binding"].as_str().unwrap();
        let node = w["numa_node"].as_u64().unwrap();
        // Bound on any Linux that lets a thread set its memory policy; a container that forbids it must say so.
        assert!(
            binding.contains(&format!("bound to NUMA node {node}")) || binding.contains("first touch (the OS refused"),
            "{w}"
        );
    }
}

/// Worker processes whose parent is `pid`.
fn worker_children(pid: u32) -> Vec<u32> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(child) = e.file_name().to_string_lossy().parse::<u32>() else { continue };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{child}/stat")) else { continue };
        // pid (comm) state ppid …
        let Some(close) = stat.rfind(')') else { continue };
        let comm = &stat[stat.find('(').unwrap() + 1..close];
        let ppid: u32 = stat[close + 2..].split_whitespace().nth(1).and_then(|p| p.parse().ok()).unwrap_or(0);
        if ppid == pid && comm == "worker" {
            found.push(child);
        }
    }
    found
}

fn wait_for_workers(pid: u32, n: usize) -> Vec<u32> {
    let start = Instant::now();
    loop {
        let w = worker_children(pid);
        if w.len() >= n || start.elapsed() > Duration::from_secs(20) {
            return w;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn three_level_and_combination_on_two_synthetic_nodes_converge_to_the_single_process_image() {
    let dir = scratch_dir("three-level");
    let scene = cornell_at(&dir, 40);
    let (single, three) = (dir.join("single"), dir.join("three"));
    run_ok(coordinator(&scene, &single, &["--method", "pbpm", "--phases", "500", "--seed", "11"]));
    run_ok(coordinator(
        &scene,
        &three,
        &["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1", "--phases", "500", "--seed", "12"],
    ));
    let r = record(&three);
    assert_eq!(r["method"], "three-level");
    let workers = r["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 2, "{workers:?}");
    for w in workers {
        assert_eq!(w["state"], "finished", "{w}");
        assert!(w["snapshots"].as_u64().unwrap() >= 1 && w["pixel_phases"].as_u64().unwrap() > 0, "{w}");
        assert!(w["binding"].as_str().unwrap().contains("synthetic"), "{w}");
        let started = w["started_after_s"].as_f64().unwrap();
        assert!(started > 0.0 && started < r["wall_time_s"].as_f64().unwrap(), "{w}");
        let loaded = w["scene_load_s"].as_f64().unwrap();
        assert!(loaded > 0.0 && loaded < started, "a worker builds the scene before it renders: {w}");
    }
    let loaded = r["scene_load_s"].as_f64().unwrap();
    assert!(loaded > 0.0 && loaded < r["started_s"].as_f64().unwrap(), "{r}");
    assert_ne!(workers[0]["numa_node"], workers[1]["numa_node"]);
    assert!(r["error"]["min_phases"].as_u64().unwrap() >= 500);
    assert_same_image(&single, &three, "three-level against one process");
    // combination: one synchronous group per process.
    let combination = dir.join("combination");
    run_ok(coordinator(
        &scene,
        &combination,
        &["--method", "combination", "--topology", TWO_NODES, "--phases", "500", "--seed", "13"],
    ));
    let r = record(&combination);
    assert!(r["workers"].as_array().unwrap().iter().all(|w| w["state"] == "finished"), "{}", r["workers"]);
    assert_same_image(&single, &combination, "combination against one process");
}

#[test]
fn a_worker_killed_mid_run_is_reported_and_the_run_completes_with_the_others() {
    let dir = scratch_dir("kill-worker");
    let scene = cornell_at(&dir, 40);
    let (single, out) = (dir.join("single"), dir.join("killed"));
    // Equal phase counts, so that both images carry the same radius bias.
    run_ok(coordinator(&scene, &single, &["--method", "pbpm", "--phases", "1500", "--seed", "21"]));
    let mut c = coordinator(
        &scene,
        &out,
        &["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1", "--phases", "1500", "--seed", "22"],
    );
    let child = c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let workers = wait_for_workers(child.id(), 2);
    assert_eq!(workers.len(), 2, "the coordinator did not start two workers");
    std::thread::sleep(Duration::from_millis(2500));
    assert!(Command::new("kill").args(["-9", &workers[0].to_string()]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("lost"), "{stderr}");
    let r = record(&out);
    let w = r["workers"].as_array().unwrap();
    let lost: Vec<_> = w.iter().filter(|w| w["state"].as_str().unwrap().starts_with("lost")).collect();
    let finished: Vec<_> = w.iter().filter(|w| w["state"] == "finished").collect();
    assert_eq!((lost.len(), finished.len()), (1, 1), "{w:?}");
    // What the lost worker sent before it died stays in the image.
    assert!(lost[0]["pixel_phases"].as_u64().unwrap() > 0, "{}", lost[0]);
    assert_same_image(&single, &out, "killed run against one process");
}

#[test]
fn a_frozen_worker_is_dropped_after_the_heartbeat_timeout() {
    let dir = scratch_dir("frozen-worker");
    let scene = cornell_at(&dir, 32);
    let out = dir.join("frozen");
    let mut c = coordinator(
        &scene,
        &out,
        &[
            "--method",
            "three-level",
            "--topology",
            TWO_NODES,
            "--group-size",
            "1",
            "--time",
            "8",
            "--worker-timeout",
            "3",
        ],
    );
    let child = c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let workers = wait_for_workers(child.id(), 2);
    assert_eq!(workers.len(), 2);
    std::thread::sleep(Duration::from_secs(2));
    assert!(Command::new("kill").args(["-STOP", &workers[1].to_string()]).status().unwrap().success());
    // Make sure the process really is stopped (state T) before relying on it.
    let state = |pid: u32| {
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        stat.rfind(')').and_then(|c| stat[c + 2..].chars().next()).unwrap_or('?')
    };
    let start = Instant::now();
    while state(workers[1]) != 'T' {
        assert!(
            start.elapsed() < Duration::from_secs(2),
            "worker {} is in state {}, not stopped",
            workers[1],
            state(workers[1])
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    // The coordinator has killed it already; make sure, quietly.
    let _ = Command::new("kill").args(["-9", &workers[1].to_string()]).stderr(Stdio::null()).status();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = record(&out);
    let states: Vec<String> =
        r["workers"].as_array().unwrap().iter().map(|w| w["state"].as_str().unwrap().to_string()).collect();
    assert!(
        states.iter().any(|s| s.contains("presumed hung")),
        "{states:?}; stopped pid {} of {workers:?}, coordinator log: {}",
        workers[1],
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(states.iter().any(|s| s == "finished"), "{states:?}");
}

#[test]
fn a_coordinator_killed_mid_run_resumes_without_losing_or_recounting_a_checkpointed_phase() {
    let dir = scratch_dir("resume");
    let scene = cornell_at(&dir, 40);
    let (single, out) = (dir.join("single"), dir.join("resumed"));
    let three = ["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1", "--phases", "1200"];
    let mut c = coordinator(&scene, &out, &three);
    c.args(["--save-interval", "0.5", "--seed", "31"]);
    let mut child = c.stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let workers = wait_for_workers(child.id(), 2);
    // Kill the coordinator once a checkpoint with some phases exists, well before the run could end.
    let start = Instant::now();
    while !out.join("checkpoint.bin").exists() && start.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(700));
    child.kill().unwrap();
    child.wait().unwrap();
    let loaded = photonfarm::scene::Scene::load(&scene).unwrap();
    let (_, sums) = photonfarm::render::checkpoint::Checkpoint::load(&out.join("checkpoint.bin"), &loaded).unwrap();
    let before: u64 = sums.pixels.iter().map(|p| p.phases as u64).sum();
    assert!(before > 0, "the checkpoint holds no phase");
    assert!(before < 1200 * 1600, "the first session finished before it was killed");
    // Its workers notice the coordinator is gone and exit.
    let start = Instant::now();
    while workers.iter().any(|w| Path::new(&format!("/proc/{w}")).exists()) {
        assert!(start.elapsed() < Duration::from_secs(30), "workers outlived their coordinator");
        std::thread::sleep(Duration::from_millis(100));
    }
    // Another method cannot continue it: refused before any worker starts, naming both methods.
    let mut c = coordinator(&scene, &out, &["--method", "combination", "--topology", TWO_NODES, "--phases", "1200"]);
    let o = c.arg("--resume").arg(&out).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--method three-level") && e.contains("--method combination"), "{e}");
    let mut c = coordinator(&scene, &out, &three);
    c.arg("--resume").arg(&out);
    run_ok(c);
    let r = record(&out);
    assert_eq!(r["session"], 2);
    assert!(r["error"]["min_phases"].as_u64().unwrap() >= 1200);
    let added: u64 = r["workers"].as_array().unwrap().iter().map(|w| w["pixel_phases"].as_u64().unwrap()).sum();
    // Every checkpointed phase is in the final image once, with every phase merged after the resume.
    assert_eq!(r["pixel_phases"].as_u64().unwrap(), before + added);
    run_ok(coordinator(&scene, &single, &["--method", "pbpm", "--phases", "1200", "--seed", "32"]));
    assert_same_image(&single, &out, "resumed run against one process");
}

#[test]
fn hostile_connections_are_refused_and_a_late_worker_joins_without_disturbing_the_job() {
    use std::io::Write;
    let dir = scratch_dir("hostile");
    let scene = cornell_at(&dir, 40);
    let out = dir.join("out");
    let (secret, wrong) = (dir.join("secret"), dir.join("wrong"));
    std::fs::write(&secret, "the right secret, long enough").unwrap();
    std::fs::write(&wrong, "a wrong secret, also long enough").unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let mut c = coordinator(&scene, &out, &["--method", "three-level", "--time", "9", "--listen", &addr]);
    c.arg("--secret-file").arg(&secret);
    let child = c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let start = Instant::now();
    let connect = || loop {
        match std::net::TcpStream::connect(&addr) {
            Ok(s) => break s,
            Err(_) if start.elapsed() < Duration::from_secs(15) => std::thread::sleep(Duration::from_millis(50)),
            Err(e) => panic!("the coordinator does not listen on {addr}: {e}"),
        }
    };
    // Random bytes, a 4 GB length prefix, a truncated frame, a Hello of another protocol version.
    connect().write_all(&[0x13, 0x37, 0xde, 0xad, 0xbe, 0xef, 0x00, 0x42, 0x99]).unwrap();
    connect().write_all(&u32::MAX.to_be_bytes()).unwrap();
    connect().write_all(&[0, 0, 0, 200, 1, 2, 3]).unwrap();
    let hello = photonfarm::protocol::message::encode(&photonfarm::protocol::Message::Hello {
        version: photonfarm::protocol::PROTOCOL_VERSION + 7,
        role: photonfarm::protocol::Role::Worker,
        nonce: [1; 32],
        name: "from the future".into(),
    })
    .unwrap();
    let mut s = connect();
    s.write_all(&(hello.len() as u32).to_be_bytes()).unwrap();
    s.write_all(&hello).unwrap();
    // A worker with the wrong secret is refused and says why.
    let refused = Command::new(binary("worker"))
        .args(["join", &addr, "--name", "intruder", "--secret-file"])
        .arg(&wrong)
        .output()
        .unwrap();
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("authentication failed"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
    // A worker with the right secret joins the running job.
    let joined = Command::new(binary("worker"))
        .args(["join", &addr, "--name", "late", "--secret-file"])
        .arg(&secret)
        .output()
        .unwrap();
    assert!(joined.status.success(), "{}", String::from_utf8_lossy(&joined.stderr));
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.matches("refused a connection").count() >= 5, "{stderr}");
    let r = record(&out);
    assert_eq!(r["stop_reason"], "time");
    let workers = r["workers"].as_array().unwrap();
    let late = workers.iter().find(|w| w["name"] == "late").expect("the late worker is in the record");
    assert_eq!(late["state"], "finished", "{late}");
    assert!(late["pixel_phases"].as_u64().unwrap() > 0, "{late}");
    assert!(workers.iter().all(|w| w["state"] == "finished"), "{workers:?}");
}

#[test]
fn a_straggling_worker_contributes_less_and_the_image_stays_correct() {
    let dir = scratch_dir("straggler");
    let scene = cornell_at(&dir, 40);
    let (single, out) = (dir.join("single"), dir.join("straggled"));
    let secret = dir.join("secret");
    std::fs::write(&secret, "a secret for the straggler test").unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let one_node = "pack:1 numa:1 core:1 pu:1";
    let mut c = coordinator(&scene, &out, &["--method", "three-level", "--topology", one_node, "--phases", "1500"]);
    c.args(["--group-size", "1", "--seed", "41", "--listen", &addr]).arg("--secret-file").arg(&secret);
    let child = c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    // A worker four times slower than its machine joins the run.
    let straggler = Command::new(binary("worker"))
        .args(["join", &addr, "--name", "straggler", "--slowdown", "4", "--secret-file"])
        .arg(&secret)
        .output()
        .unwrap();
    assert!(straggler.status.success(), "{}", String::from_utf8_lossy(&straggler.stderr));
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = record(&out);
    let workers = r["workers"].as_array().unwrap();
    let by_name = |n: &str| workers.iter().find(|w| w["name"] == n).unwrap_or_else(|| panic!("no {n} in {workers:?}"));
    let (fast, slow) = (by_name("node0"), by_name("straggler"));
    assert!(slow["binding"].as_str().unwrap().contains("slowed down 4×"), "{slow}");
    assert!(workers.iter().all(|w| w["state"] == "finished"), "{workers:?}");
    let (pf, ps) = (fast["pixel_phases"].as_u64().unwrap(), slow["pixel_phases"].as_u64().unwrap());
    eprintln!("pixel-phases: full-speed worker {pf}, straggler {ps}");
    // It added what it could, a fraction of the other's, and never held the run back.
    assert!(ps > 0 && (ps as f64) < 0.6 * pf as f64, "straggler {ps} against {pf} pixel-phases");
    run_ok(coordinator(&scene, &single, &["--method", "pbpm", "--phases", "1500", "--seed", "42"]));
    assert_same_image(&single, &out, "a run with a straggler against one process");
}

/// A small scene with an emission texture on a quad and an albedo texture on an OBJ floor with `vt`, in its own
/// folder (the HUD slide as both textures).
fn textured_scene(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir.join("tex")).unwrap();
    std::fs::copy(repo_root().join("scenes/hud/slide.png"), dir.join("tex/slide.png")).unwrap();
    std::fs::write(
        dir.join("tex/floor.obj"),
        "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 0\nvt 2 0\nvt 2 2\nvt 0 2\nf 1/1 4/4 3/3\nf 1/1 3/3 2/2\n",
    )
    .unwrap();
    let text = r#"
[camera]
position = [0.0, 0.9, -1.6]
look_at = [0.0, 0.3, 0.0]
fov_y_deg = 50
width = 40
height = 40

[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]

[materials.printed]
type = "diffuse"
albedo = [0.9, 0.9, 0.9]
albedo_texture = "tex/slide.png"

[[objects]]
name = "slide"
material = "black"
emission = [4.0, 4.0, 4.0]
emission_texture = "tex/slide.png"
quad = { corner = [0.6, 0.05, 0.6], edge1 = [-1.2, 0.0, 0.0], edge2 = [0.0, 0.6, 0.0] }

[[objects]]
name = "floor"
material = "printed"
mesh = "tex/floor.obj"

[[lights]]
type = "point"
position = [0.0, 1.0, -0.5]
intensity = [0.5, 0.5, 0.5]
"#;
    let path = dir.join("textured.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_textured_scene_renders_the_same_through_three_level_workers_that_received_its_textures() {
    let dir = scratch_dir("textured");
    let scene = textured_scene(&dir);
    let (single, three) = (dir.join("single"), dir.join("three"));
    run_ok(coordinator(&scene, &single, &["--method", "pbpm", "--phases", "300", "--seed", "41"]));
    run_ok(coordinator(
        &scene,
        &three,
        &["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1", "--phases", "300", "--seed", "42"],
    ));
    let r = record(&three);
    let workers = r["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 2, "{workers:?}");
    // A worker that could not build the scene from the files sent would have failed its job.
    for w in workers {
        assert_eq!(w["state"], "finished", "{w}");
        assert!(w["pixel_phases"].as_u64().unwrap() > 0, "{w}");
    }
    assert_same_image(&single, &three, "textured scene, three-level against one process");
}

/// The record of a running render, once it has one with a worker named `name` in a state `state` names.
fn wait_for_worker_state(out: &Path, name: &str, state: &str) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let r: Option<serde_json::Value> =
            std::fs::read_to_string(out.join("run.json")).ok().and_then(|t| serde_json::from_str(&t).ok());
        let found = r.as_ref().and_then(|r| {
            r["workers"]
                .as_array()?
                .iter()
                .find(|w| w["name"] == name && w["state"].as_str().is_some_and(|s| s.starts_with(state)))
        });
        if let Some(w) = found {
            return w.clone();
        }
        assert!(start.elapsed() < Duration::from_secs(30), "worker {name} never reached '{state}' in the record");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_host_whose_workers_keep_failing_is_refused_for_the_rest_of_the_job_and_the_record_counts_its_failures() {
    let dir = scratch_dir("blocklist");
    let scene = cornell_at(&dir, 32);
    let out = dir.join("out");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    // The local worker renders the job throughout; workers that join from 127.0.0.1 are killed mid-run.
    let mut c = coordinator(&scene, &out, &["--method", "three-level", "--topology", "pack:1 numa:1 core:1 pu:1"]);
    c.args(["--time", "60", "--listen", &addr, "--max-worker-failures", "2", "--save-interval", "0.3"]);
    let child = c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    for round in 0..2 {
        let name = format!("flaky{round}");
        let mut w = Command::new(binary("worker"))
            .args(["join", &addr, "--name", &name])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        wait_for_worker_state(&out, &name, "running");
        w.kill().unwrap();
        w.wait().unwrap();
        let lost = wait_for_worker_state(&out, &name, "lost");
        assert_eq!(lost["failures"], round + 1, "{lost}");
    }
    let refused = Command::new(binary("worker")).args(["join", &addr, "--name", "flaky2"]).output().unwrap();
    let why = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{why}");
    assert!(why.contains("failed 2 times in this job") && why.contains("--max-worker-failures 2"), "{why}");
    // Ctrl-C: the run ends at once and writes what it has.
    assert!(Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("refused for the rest of it"), "{stderr}");
    let r = record(&out);
    let workers = r["workers"].as_array().unwrap();
    let flaky: Vec<_> = workers.iter().filter(|w| w["name"].as_str().unwrap().starts_with("flaky")).collect();
    assert_eq!(flaky.len(), 2, "the refused worker never became one of the job's: {workers:?}");
    assert!(flaky.iter().all(|w| w["failures"] == 2 && w["state"].as_str().unwrap().starts_with("lost")), "{flaky:?}");
    let local = workers.iter().find(|w| w["name"] == "node0").unwrap();
    assert_eq!((&local["state"], &local["failures"]), (&"finished".into(), &0.into()), "{local}");
}

/// The mean of an output's `phases` layer: the phases the image's pixels had.
fn mean_phases(out: &Path) -> f64 {
    use photonfarm::image_io::exr_file::{find_layer, read_exr};
    let path = out.join("image.exr");
    let layers = read_exr(&path).unwrap();
    let phases = find_layer(&layers, &path, "phases").unwrap();
    phases.rgb.iter().map(|p| p[0] as f64).sum::<f64>() / phases.rgb.len() as f64
}

#[test]
fn two_workers_that_dial_in_give_the_blur_and_delta_of_the_planned_three_level_run() {
    let dir = scratch_dir("dialled-share");
    let scene = cornell_at(&dir, 32);
    let (planned, dialled) = (dir.join("planned"), dir.join("dialled"));
    // Wide discs, so that the blur stands far above its estimate's noise; light and depth fixed, so that the
    // runs differ only in how their workers came; frequent snapshots, so that both stop near 300 phases.
    let common = [
        "--group-size",
        "1",
        "--phases",
        "300",
        "--radius-scale",
        "12",
        "--light-paths-per-pixel",
        "1",
        "--backward-diffuse-depth",
        "1",
        "--snapshot-interval",
        "0.25",
    ];
    let mut c = coordinator(&scene, &planned, &["--method", "three-level", "--topology", TWO_NODES, "--seed", "61"]);
    c.args(common);
    run_ok(c);
    // As a Slurm job runs it: the coordinator starts no worker, and two `worker join` processes, each confined
    // to one core as hwloc-bind confines Slurm's, dial in.
    let secret = dir.join("secret");
    std::fs::write(&secret, "a secret for the dialled-in workers").unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let mut c = coordinator(&scene, &dialled, &["--method", "three-level", "--remote-only", "--listen", &addr]);
    c.args(common).args(["--seed", "62", "--secret-file"]).arg(&secret);
    let child = c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let join = |name: &str, core: usize| {
        let mut w = Command::new("taskset");
        w.args(["-c", &(core % cores).to_string()]).arg(binary("worker"));
        w.args(["join", &addr, "--name", name, "--secret-file"]).arg(&secret);
        w.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("taskset (util-linux) runs the workers")
    };
    let workers = [join("a", 0), join("b", 1)];
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for w in workers {
        let o = w.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let (rp, rd) = (record(&planned), record(&dialled));
    let workers = rd["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 2, "{workers:?}");
    assert!(workers.iter().all(|w| w["state"] == "finished"), "{workers:?}");
    // The blur falls about as N^(α − 1) = N^(−1/3) with the pixels' phases N: compared at the planned run's.
    // With a lone process's schedule on each dialled-in worker it came out 14–16% above the planned run's.
    let (np, nd) = (mean_phases(&planned), mean_phases(&dialled));
    let error = |r: &serde_json::Value, key: &str| r["error"][key].as_f64().unwrap();
    let (bp, bd) = (error(&rp, "blur_unlit"), error(&rd, "blur_unlit") * (nd / np).cbrt());
    // δ² is the noise's SEM² plus the blur², and the noise part falls as 1/√N.
    let noise = |r: &serde_json::Value, n: f64| {
        let (d, b) = (error(r, "delta_unlit"), error(r, "blur_unlit"));
        (d * d - b * b).max(0.0).sqrt() * (n / np).sqrt()
    };
    let (sp, sd) = (noise(&rp, np), noise(&rd, nd));
    eprintln!(
        "mean phases {np:.1} planned, {nd:.1} dialled in; at the planned phases blur_unlit {bp:.5} and {bd:.5} \
         (ratio {:.3}), δ_unlit's noise part {sp:.5} and {sd:.5} (ratio {:.3})",
        bd / bp,
        sd / sp
    );
    assert!((bd / bp - 1.0).abs() < 0.06, "blur: dialled in {bd:.5} against planned {bp:.5}");
    // A numbering that starved replicates of phases made δ's spread of the replicates several times larger.
    assert!((sd / sp - 1.0).abs() < 0.25, "δ's noise part: dialled in {sd:.5} against planned {sp:.5}");
    assert_same_image(&planned, &dialled, "dialled-in workers against planned ones");
}

#[test]
fn a_checkpoint_with_one_bit_flipped_is_refused_and_the_previous_one_resumes() {
    let dir = scratch_dir("damaged-checkpoint");
    let scene = cornell_at(&dir, 32);
    let out = dir.join("run");
    let three = ["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1"];
    let mut c = coordinator(&scene, &out, &three);
    c.args(["--time", "3", "--save-interval", "0.5", "--seed", "71"]);
    run_ok(c);
    let (latest, previous) = (out.join("checkpoint.bin"), out.join("checkpoint-previous.bin"));
    assert!(previous.is_file(), "the save before the last one is kept beside it");
    let whole = std::fs::read(&latest).unwrap();
    let record_before = std::fs::read(out.join("run.json")).unwrap();
    // As a user would try it: one bit flipped at 10%, 30%, 50%, 70% or 90% of the file, then --resume.
    for percent in [10, 30, 50, 70, 90] {
        let mut bytes = whole.clone();
        bytes[whole.len() * percent / 100] ^= 0x10;
        std::fs::write(&latest, &bytes).unwrap();
        let mut c = coordinator(&scene, &out, &three);
        let o = c.args(["--time", "6", "--resume"]).arg(&out).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "a checkpoint damaged at {percent}% was resumed: {e}");
        assert!(
            e.contains("is damaged") && e.contains(&format!("--resume {}", previous.display())),
            "at {percent}%: {e}"
        );
        assert_eq!(std::fs::read(out.join("run.json")).unwrap(), record_before, "the refusal wrote nothing");
    }
    // The latest one stays damaged; the previous one continues the run.
    let mut c = coordinator(&scene, &out, &three);
    c.args(["--time", "5", "--resume"]).arg(&previous);
    run_ok(c);
    let r = record(&out);
    assert_eq!(r["session"], 2);
    assert_eq!(r["stop_reason"], "time");
    assert!(r["wall_time_s"].as_f64().unwrap() >= 5.0, "{}", r["wall_time_s"]);
}

#[test]
fn a_memory_limit_is_checked_by_every_worker_against_its_own_engine() {
    let dir = scratch_dir("worker-memory-limit");
    let scene = cornell_at(&dir, 256);
    let three = ["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1", "--phases", "2"];
    // Each worker fails its job with the reason, and a run none of whose workers fit says why.
    let mut c = coordinator(&scene, &dir.join("small"), &three);
    let o = c.args(["--memory-limit", "20M"]).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains("no worker rendered anything") && e.contains("--memory-limit 20 MiB is too small"), "{e}");
    assert!(e.contains("on this worker's 1 thread"), "{e}");
    // A limit the workers fit in renders as without one.
    let mut c = coordinator(&scene, &dir.join("fits"), &three);
    c.args(["--memory-limit", "4G"]);
    run_ok(c);
    assert_eq!(record(&dir.join("fits"))["stop_reason"], "phases");
}
