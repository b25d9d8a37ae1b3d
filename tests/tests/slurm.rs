//! deploy/slurm/photonfarm.sbatch on a real Slurm cluster: a job on a node with a synthetic two-NUMA-node
//! topology runs one worker step per NUMA node and renders the single-process image, and a job one of whose
//! worker steps is cancelled mid-run completes with the other, every merged phase counted once. The cluster is
//! the one tests/slurm/run starts (it sets SLURM_CONF and runs these tests); plain `cargo test` lists them as
//! ignored.

mod common;

use common::{assert_same_image, record};
use end_to_end::{binary, cornell_at, repo_root, scratch_dir};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const TWO_NODES: &str = "pack:1 numa:2 core:1 pu:1";
/// The test scene's width and height.
const SIZE: u64 = 32;

fn slurm(program: &str, args: &[&str]) -> String {
    assert!(
        std::env::var_os("SLURM_CONF").is_some(),
        "SLURM_CONF is not set: run these tests through tests/slurm/run, which starts a Slurm cluster"
    );
    let o = Command::new(program).args(args).output().unwrap_or_else(|e| panic!("cannot run {program}: {e}"));
    assert!(o.status.success(), "{program} {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A submitted job: its id and submit directory.
struct Job {
    id: String,
    dir: PathBuf,
}

impl Job {
    /// Submits the sbatch script from `dir` for the scene `cornell.toml` there. The job inherits this
    /// environment, whose hwloc variables make its node a machine of two NUMA nodes with one core each,
    /// mapped onto this machine's cores 0 and 1.
    fn submit(dir: &Path, render_args: &[&str]) -> Job {
        let bin = binary("worker").parent().unwrap().to_path_buf();
        assert!(binary("coordinator").is_file());
        let script = repo_root().join("deploy/slurm/photonfarm.sbatch");
        let mut args = vec!["--parsable", "--nodes=1", "--time=5", script.to_str().unwrap(), "cornell.toml"];
        args.extend_from_slice(render_args);
        // A port free now rather than the script's default, which another program on this machine may hold.
        let port = std::net::TcpListener::bind("0.0.0.0:0").unwrap().local_addr().unwrap().port();
        let o = Command::new("sbatch")
            .args(&args)
            .current_dir(dir)
            .env("PHOTONFARM_BIN", &bin)
            .env("PHOTONFARM_PORT", port.to_string())
            .env("HWLOC_SYNTHETIC", TWO_NODES)
            .env("HWLOC_THISSYSTEM", "1")
            .output()
            .expect("cannot run sbatch");
        assert!(o.status.success(), "sbatch: {}", String::from_utf8_lossy(&o.stderr));
        let id = String::from_utf8_lossy(&o.stdout).trim().split(';').next().unwrap().to_string();
        Job { id, dir: dir.to_path_buf() }
    }

    fn out(&self) -> PathBuf {
        self.dir.join(format!("photonfarm-{}", self.id))
    }

    /// The job's own log and its workers' logs, for failure messages.
    fn logs(&self) -> String {
        let mut text =
            std::fs::read_to_string(self.dir.join(format!("photonfarm-{}.log", self.id))).unwrap_or_default();
        if let Ok(entries) = std::fs::read_dir(self.out().join("workers")) {
            for e in entries.flatten() {
                let log = std::fs::read_to_string(e.path()).unwrap_or_default();
                text += &format!("\n--- {}\n{log}", e.path().display());
            }
        }
        text
    }

    /// `scontrol show job`'s `KEY=value` fields.
    fn field(&self, key: &str) -> String {
        let line = slurm("scontrol", &["show", "job", "--oneliner", &self.id]);
        line.split_whitespace()
            .find_map(|f| f.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
            .unwrap_or_default()
            .to_string()
    }

    /// Waits until the job ends and asserts that it completed with exit code 0.
    fn assert_completes(&self, limit: Duration) {
        let start = Instant::now();
        let ended = ["COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY", "PREEMPTED"];
        let state = loop {
            let state = self.field("JobState");
            if ended.contains(&state.as_str()) {
                break state;
            }
            if start.elapsed() > limit {
                let _ = Command::new("scancel").arg(&self.id).status();
                panic!("job {} still {state} after {limit:?}:\n{}", self.id, self.logs());
            }
            std::thread::sleep(Duration::from_millis(200));
        };
        assert_eq!((state.as_str(), self.field("ExitCode").as_str()), ("COMPLETED", "0:0"), "{}", self.logs());
    }

    /// The job's running steps whose name ends with `suffix`, as JOB.STEP.
    fn steps_named(&self, suffix: &str) -> Vec<String> {
        slurm("squeue", &["--noheader", "--steps", "--jobs", &self.id, "--format", "%i %j"])
            .lines()
            .filter_map(|l| l.split_once(' '))
            .filter(|(_, name)| name.trim().ends_with(suffix))
            .map(|(step, _)| step.to_string())
            .collect()
    }
}

fn reference(dir: &Path, scene: &Path, phases: &str) -> PathBuf {
    let out = dir.join("single");
    let o = Command::new(binary("coordinator"))
        .arg("render")
        .arg(scene)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--method", "pbpm", "--phases", phases, "--seed", "61"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

fn u64_at(v: &serde_json::Value, path: &[&str]) -> u64 {
    path.iter().fold(v, |v, k| &v[k]).as_u64().unwrap_or_else(|| panic!("no number at {path:?} in {v}"))
}

/// Asserts that no merged phase was counted twice or lost: the image holds exactly the pixel-phases the
/// workers' snapshots brought, each worker's merged pixel-phases are the phases it reported rendering over
/// the whole image, and the run's ray totals are the sum of the workers'.
fn assert_every_phase_counted_once(r: &serde_json::Value) {
    let workers = r["workers"].as_array().unwrap();
    let merged: u64 = workers.iter().map(|w| u64_at(w, &["pixel_phases"])).sum();
    assert_eq!(u64_at(r, &["pixel_phases"]), merged, "{workers:?}");
    for w in workers {
        assert_eq!(u64_at(w, &["pixel_phases"]), u64_at(w, &["totals", "phases"]) * SIZE * SIZE, "{w}");
    }
    for key in ["phases", "backward_rays", "forward_rays", "light_paths"] {
        let sum: u64 = workers.iter().map(|w| u64_at(w, &["totals", key])).sum();
        assert_eq!(u64_at(r, &["totals", key]), sum, "totals.{key}: {workers:?}");
    }
}

#[test]
#[ignore = "needs the Slurm cluster that tests/slurm/run starts"]
fn a_slurm_job_runs_one_worker_per_numa_node_and_renders_the_single_process_image() {
    let dir = scratch_dir("slurm-job");
    let scene = cornell_at(&dir, SIZE as u32);
    let job = Job::submit(&dir, &["--phases", "400", "--seed", "62", "--group-size", "1"]);
    let single = reference(&dir, &scene, "400");
    job.assert_completes(Duration::from_secs(120));
    let r = record(&job.out());
    assert_eq!(r["stop_reason"], "phases", "{}", job.logs());
    let workers = r["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 2, "{workers:?}");
    let mut names: Vec<&str> = workers.iter().map(|w| w["name"].as_str().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["pf1-numa0", "pf1-numa1"]);
    let mut cores: Vec<u64> = Vec::new();
    for w in workers {
        assert_eq!(w["state"], "finished", "{w}");
        assert!(u64_at(w, &["pixel_phases"]) > 0, "{w}");
        // hwloc-bind confined each worker to its NUMA node's one core.
        let c = w["cores"].as_array().unwrap();
        assert_eq!(c.len(), 1, "{w}");
        cores.push(c[0].as_u64().unwrap());
    }
    cores.sort();
    assert_eq!(cores, [0, 1], "{workers:?}");
    assert_every_phase_counted_once(&r);
    assert_same_image(&single, &job.out(), "Slurm job against one process");
}

#[test]
#[ignore = "needs the Slurm cluster that tests/slurm/run starts"]
fn cancelling_one_worker_step_mid_run_keeps_its_phases_and_the_job_completes_with_the_other() {
    let dir = scratch_dir("slurm-cancel");
    let scene = cornell_at(&dir, SIZE as u32);
    // A time, not a phase count, so that the kept worker renders on for seconds after the cancel however fast
    // the machine is (2000 phases of this small image can end before the cancel on a quiet machine).
    let args = ["--time", "10", "--seed", "63", "--group-size", "1", "--snapshot-interval", "0.25"];
    let job = Job::submit(&dir, &args);
    // Both worker steps run, and the one to cancel has had time to send snapshots (four a second).
    let start = Instant::now();
    let step = loop {
        let (zero, one) = (job.steps_named("-numa0"), job.steps_named("-numa1"));
        if zero.len() == 1 && one.len() == 1 {
            break one[0].clone();
        }
        assert!(start.elapsed() < Duration::from_secs(60), "the worker steps did not start:\n{}", job.logs());
        std::thread::sleep(Duration::from_millis(100));
    };
    std::thread::sleep(Duration::from_secs(2));
    slurm("scancel", &[&step]);
    let single = reference(&dir, &scene, "2000");
    job.assert_completes(Duration::from_secs(120));
    let r = record(&job.out());
    let workers = r["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 2, "{workers:?}");
    let by_name = |n: &str| workers.iter().find(|w| w["name"] == n).unwrap_or_else(|| panic!("no {n}: {workers:?}"));
    let (kept, cancelled) = (by_name("pf1-numa0"), by_name("pf1-numa1"));
    assert_eq!(kept["state"], "finished", "{kept}");
    assert!(cancelled["state"].as_str().unwrap().starts_with("lost"), "{cancelled}");
    eprintln!(
        "pixel-phases merged: kept worker {}, cancelled worker {}; {} s",
        kept["pixel_phases"], cancelled["pixel_phases"], r["wall_time_s"]
    );
    // What the cancelled worker sent before its step was cancelled stays in the image.
    assert!(u64_at(cancelled, &["pixel_phases"]) > 0, "{cancelled}");
    assert!(u64_at(kept, &["pixel_phases"]) > u64_at(cancelled, &["pixel_phases"]), "{workers:?}");
    assert!(u64_at(&r, &["error", "min_phases"]) >= 100, "{}", r["error"]);
    assert_every_phase_counted_once(&r);
    assert_same_image(&single, &job.out(), "Slurm job with a cancelled worker against one process");
}
