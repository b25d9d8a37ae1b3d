//! A production-size render in small: a generated room at 1,920 × 1,080 pixels holding a mesh of 200,000
//! triangles (`end_to_end::room`, written into a scratch folder, never committed), rendered three-level for a
//! few seconds as a user would. It stops on time, shows its first image before the deadline, and no process
//! grows past the memory it estimated before it allocated. A room with a mesh of a million triangles has its
//! BVH cached by the first run and read by the next. `scripts/production-sizes` measures the full sizes.

use end_to_end::room::{write_room, write_room_as, MeshFormat, RoomSpec};
use end_to_end::{binary, repo_root, scratch_dir};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The run's `--time`, seconds.
const TIME_S: f64 = 12.0;

#[test]
fn a_1080p_room_with_a_large_mesh_stops_on_time_saves_before_its_deadline_and_stays_within_its_memory_estimate() {
    let dir = scratch_dir("production-size");
    let room = write_room(&dir, RoomSpec { triangles: 200_000, width: 1920, height: 1080 }).unwrap();
    let out = dir.join("out");
    let coordinator = binary("coordinator");
    let launched = Instant::now();
    let mut run = Command::new(coordinator)
        .arg("render")
        .arg(&room.scene)
        .args(["--method", "three-level", "--group-size", "1", "--time", &TIME_S.to_string(), "--save-interval", "1"])
        .arg("--quiet")
        .arg("--out")
        .arg(&out)
        .current_dir(repo_root())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // When the first preview appears, from the command's start.
    let mut first_preview = None;
    let status = loop {
        if first_preview.is_none() && out.join("preview.png").exists() {
            first_preview = Some(launched.elapsed().as_secs_f64());
        }
        if let Some(status) = run.try_wait().unwrap() {
            break status;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let stderr = std::io::read_to_string(run.stderr.take().unwrap()).unwrap();
    assert!(status.success(), "{stderr}");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    let seconds = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    let workers = record["workers"].as_array().expect("a three-level run records its workers");
    assert!(!workers.is_empty());

    // On time: rendering ends within max(2% of --time, one phase) of it. It ends when the workers' last
    // snapshots are merged, the last history entry (the record's wall time also holds the final checkpoint). A
    // group's phase lasts its worker's rendering seconds over the phases each of its groups ran (one thread per
    // group here).
    let rendered = seconds(&record["history"].as_array().unwrap().last().unwrap()["time_s"]);
    // The run's clock starts when the first worker renders; each worker's start is counted from the launch of
    // the workers, so a later one rendered for `first - started_after_s` less.
    let first = workers.iter().map(|w| seconds(&w["started_after_s"])).fold(f64::INFINITY, f64::min);
    let phase = workers
        .iter()
        .map(|w| {
            let groups = w["cores"].as_array().unwrap().len() as f64;
            let phases = w["totals"]["phases"].as_f64().unwrap();
            assert!(phases > 0.0, "a worker rendered nothing: {w}");
            (rendered + first - seconds(&w["started_after_s"])) * groups / phases
        })
        .fold(0.0, f64::max);
    let late = rendered - TIME_S;
    eprintln!(
        "rendering ended {late:+.2} s from --time {TIME_S} (phases of {phase:.2} s), the first preview {:.2} s after \
         the command's start, rendering from {:.2} s",
        first_preview.unwrap_or(f64::NAN),
        seconds(&record["started_s"])
    );
    assert!(
        late.abs() <= (0.02 * TIME_S).max(phase),
        "rendering took {rendered:.2} s for --time {TIME_S}: {late:+.2} s, with phases of {phase:.2} s"
    );

    // Something to see before the deadline: the first preview, saved from the first merged snapshot.
    let deadline = seconds(&record["started_s"]) + TIME_S;
    let first_preview = first_preview.expect("no preview appeared while the run lasted");
    assert!(first_preview < deadline, "first preview at {first_preview:.2} s, the deadline at {deadline:.2} s");

    // Memory: every process's peak within the estimate it made before allocating.
    let within = |who: &str, r: &serde_json::Value| {
        let (peak, estimate) = (r["peak_memory_bytes"].as_u64().unwrap(), r["memory_estimate_bytes"].as_u64().unwrap());
        eprintln!("{who}: peak {} MiB, estimate {} MiB", peak >> 20, estimate >> 20);
        assert!(peak <= estimate, "{who}: peak {} MiB above its estimate of {} MiB", peak >> 20, estimate >> 20);
    };
    within("the coordinator", &record);
    for w in workers {
        within(w["name"].as_str().unwrap(), w);
    }
}

#[test]
fn a_million_triangle_meshs_bvh_is_cached_by_the_first_run_and_read_by_the_next_worker_or_process() {
    let dir = scratch_dir("bvh-cache");
    let spec = RoomSpec { triangles: 1_010_000, width: 64, height: 36 };
    let room = write_room_as(&dir, spec, MeshFormat::Ply).unwrap();
    assert!(room.triangles >= 1_000_000, "{} triangles are below the cache's threshold", room.triangles);
    let cache = dir.join("cache");
    let render = |method: &str, out: &str| -> serde_json::Value {
        let out = dir.join(out);
        let run = Command::new(binary("coordinator"))
            .arg("render")
            .arg(&room.scene)
            .args(["--method", method, "--time", "1", "--quiet", "--out"])
            .arg(&out)
            .env("PHOTONFARM_BVH_CACHE", &cache)
            .current_dir(repo_root())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap()
    };
    let worker_cache = |record: &serde_json::Value| record["workers"][0]["bvh_cache"].clone();
    assert_eq!(worker_cache(&render("three-level", "first")), "written");
    assert_eq!(worker_cache(&render("three-level", "second")), "read");
    // A process that renders in itself builds the same BVH, so reads the same file.
    assert_eq!(render("pbpm", "in-process")["bvh_cache"], "read");
    let files: Vec<_> = std::fs::read_dir(&cache).unwrap().flatten().map(|e| e.file_name()).collect();
    assert_eq!(files.len(), 1, "{files:?}");
}
