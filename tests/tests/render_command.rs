//! `coordinator render` as a user runs it: outputs written, the run record complete, bad input refused with
//! a clear message, Ctrl-C still writing every completed phase.

use end_to_end::{binary, cornell_at, repo_root, scratch_dir};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Runs `coordinator render` with `args` and `--out out` from the repository root; asserts it succeeded.
fn render(args: &[&str], out: &std::path::Path) -> std::process::Output {
    let result = Command::new(binary("coordinator"))
        .arg("render")
        .args(args)
        .arg("--out")
        .arg(out)
        .current_dir(repo_root())
        .output()
        .unwrap();
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    result
}

fn record(dir: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("run.json")).expect("run.json written");
    serde_json::from_str(&text).expect("run.json is JSON")
}

#[test]
fn render_writes_layers_preview_and_a_complete_run_record() {
    let out = scratch_dir("render");
    let result = render(&["scenes/cornell.toml", "--method", "pbpm", "--phases", "4", "--quiet"], &out);
    let layers = photonfarm::image_io::exr_file::read_exr(&out.join("image.exr")).unwrap();
    let mut names: Vec<&str> = layers.iter().map(|l| l.name.as_str()).collect();
    names.sort();
    assert_eq!(names, ["blur", "caustic", "direct", "indirect", "lit", "phases", "sem", "total", "visible_lights"]);
    assert!(layers.iter().all(|l| l.rgb.iter().flatten().all(|v| v.is_finite())));
    assert!(std::fs::metadata(out.join("preview.png")).unwrap().len() > 1000);
    let r = record(&out);
    assert_eq!(r["totals"]["phases"], 4);
    assert_eq!(r["stop_reason"], "phases");
    assert_eq!(r["history"].as_array().unwrap().len(), 4);
    assert!(r["totals"]["backward_rays"].as_u64().unwrap() > 0 && r["totals"]["forward_rays"].as_u64().unwrap() > 0);
    assert_eq!(r["scene_hash"].as_str().unwrap().len(), 64);
    assert!(r["peak_memory_bytes"].as_u64().unwrap() > 0);
    assert!(r["bytes_per_pixel"].as_f64().unwrap() > 100.0);
    assert!(r["error"]["delta_all"].as_f64().unwrap() > 0.0);
    let stdout = String::from_utf8_lossy(&result.stdout);
    assert!(stdout.contains(&format!("wrote {}", out.display())), "{stdout}");
}

#[test]
fn the_in_process_two_level_render_gives_every_pixel_at_least_the_phases_asked_for() {
    let out = scratch_dir("parallel");
    render(
        &[
            "scenes/cornell.toml",
            "--method",
            "two-level",
            "--phases",
            "3",
            "--threads",
            "2",
            "--group-size",
            "1",
            "--quiet",
        ],
        &out,
    );
    let r = record(&out);
    assert_eq!(r["method"], "two-level");
    assert_eq!(r["threads"], 2);
    assert!(r["layout"].as_str().unwrap().starts_with("2 groups × 1 thread"), "{}", r["layout"]);
    assert!(r["error"]["min_phases"].as_u64().unwrap() >= 3);
    assert!(r["totals"]["merges"].as_u64().unwrap() > 0);
}

/// Two synthetic NUMA nodes of one core each.
const TWO_NODES: &str = "pack:1 numa:2 core:1 pu:1";

#[test]
fn every_method_measures_delta_over_the_same_lit_mask_kept_in_the_record_and_the_exr() {
    let dir = scratch_dir("lit-mask");
    let scene = cornell_at(&dir, 48);
    let scene = scene.to_str().unwrap();
    let runs = [
        ("pbpm", vec!["--method", "pbpm", "--seed", "1"]),
        ("two-level", vec!["--method", "two-level", "--threads", "2", "--group-size", "1", "--seed", "2"]),
        ("three-level", vec!["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1", "--seed", "3"]),
    ];
    let mut masks = Vec::new();
    for (name, args) in runs {
        let out = dir.join(name);
        let mut all = vec![scene, "--phases", "2", "--quiet"];
        all.extend(args);
        render(&all, &out);
        let layers = photonfarm::image_io::exr_file::read_exr(&out.join("image.exr")).unwrap();
        let lit = layers.iter().find(|l| l.name == "lit").expect("a lit layer").rgb.clone();
        let r = record(&out);
        let m = &r["lit_mask"];
        let count = lit.iter().filter(|p| p[0] == 1.0).count() as u64;
        assert_eq!(m["lit_pixels"].as_u64(), Some(count), "{name}: the record counts the EXR's lit pixels");
        assert_eq!(m["lit_pixels"].as_u64().unwrap() + m["unlit_pixels"].as_u64().unwrap(), 48 * 48);
        assert_eq!(m["exr_layer"], "lit");
        masks.push((name, lit, r["lit_mask"].clone()));
    }
    let (_, first, first_record) = &masks[0];
    assert!(first_record["lit_pixels"].as_u64().unwrap() > 0, "the Cornell box's light is seen");
    for (name, lit, r) in &masks[1..] {
        assert_eq!(lit, first, "{name}: the same mask as pbpm's");
        assert_eq!(r["lit_pixels"], first_record["lit_pixels"], "{name}");
    }
}

#[test]
fn a_run_with_a_target_error_keeps_its_forecast_next_to_when_the_target_was_met() {
    let dir = scratch_dir("forecast");
    let scene = cornell_at(&dir, 48);
    let out = dir.join("out");
    render(&[scene.to_str().unwrap(), "--method", "pbpm", "--target-error", "0.05", "--quiet"], &out);
    let r = record(&out);
    assert_eq!(r["stop_reason"], "target-error");
    let f = &r["forecast"];
    assert_eq!(f["target"], 0.05);
    let made = &f["within_2x"];
    let reached = f["reached_phases"].as_f64().expect("the phases at which the target was met");
    assert!(made["end_phases"].as_f64().unwrap() > made["at_phases"].as_f64().unwrap());
    assert!(made["remaining_s"].as_f64().unwrap() >= 0.0);
    assert!(reached >= made["at_phases"].as_f64().unwrap());
    assert!(f["reached_s"].as_f64().unwrap() <= r["wall_time_s"].as_f64().unwrap());
}

#[test]
fn the_record_flags_light_paths_that_max_depth_cut_short_and_nothing_for_a_complete_run() {
    let capped = scratch_dir("flags-capped");
    let result =
        render(&["scenes/cornell.toml", "--method", "pbpm", "--phases", "3", "--max-depth", "3", "--quiet"], &capped);
    let r = record(&capped);
    let flags: Vec<&str> = r["flags"].as_array().unwrap().iter().map(|f| f.as_str().unwrap()).collect();
    let n = r["totals"]["capped_light_paths"].as_u64().unwrap();
    assert!(n > 0 && flags.len() == 1 && flags[0].starts_with(&format!("{n} light paths")), "{flags:?}");
    assert!(String::from_utf8_lossy(&result.stderr).contains("note: "), "the terminal shows the flag too");

    // At the default depth of 12 the paths capped in a closed box are flagged too; the path tracer caps none.
    let complete = scratch_dir("flags-complete");
    render(&["scenes/cornell.toml", "--method", "path", "--phases", "2", "--quiet"], &complete);
    assert_eq!(record(&complete)["flags"], serde_json::json!([]));
}

#[test]
fn render_with_a_reference_reports_the_true_error() {
    let out = scratch_dir("reference");
    render(
        &["scenes/cornell.toml", "--phases", "3", "--quiet", "--reference", "scenes/references/cornell-path.exr"],
        &out,
    );
    let r = record(&out);
    let t = r["true_error"]["rmse_unlit"].as_f64().unwrap();
    assert!(t > 0.0 && t < 1.0, "{t}");
    // The reference's own noise is reported beside it, and every step of the history has its true error.
    let d_ref = r["true_error"]["reference_delta_unlit"].as_f64().unwrap();
    assert!(d_ref > 0.0 && d_ref < t, "reference δ {d_ref}, true error {t}");
    assert!(r["history"].as_array().unwrap().iter().all(|h| h["true_unlit"].as_f64().is_some_and(|e| e > 0.0)));
}

#[test]
fn a_memory_limit_makes_async_give_up_threads_and_other_methods_refuse_up_front() {
    // 512 × 512: async's per-thread buffers (about 160 MB per extra thread) dwarf the variation of the memory a
    // process has in use after loading a scene.
    let scene_dir = scratch_dir("memory-limit");
    let scene = cornell_at(&scene_dir, 512);
    let scene = scene.to_str().unwrap();
    // Async's estimate is about 1.1 kB per pixel at one thread and 2 kB at two: about 270 and 490 MiB over what is
    // in use.
    let out = scratch_dir("memory-limit-async");
    let result = render(
        &[scene, "--method", "async", "--threads", "2", "--phases", "2", "--memory-limit", "300M", "--quiet"],
        &out,
    );
    let r = record(&out);
    assert_eq!(r["threads"], 1, "{}", String::from_utf8_lossy(&result.stderr));
    let flags = r["flags"].as_array().unwrap();
    assert!(flags.iter().any(|f| f.as_str().unwrap().starts_with("--memory-limit 300 MiB: async needs")), "{flags:?}");
    assert!(r["peak_memory_bytes"].as_u64().unwrap() < 300 << 20);

    let sync_out = scratch_dir("memory-limit-sync");
    let refused = Command::new(binary("coordinator"))
        .args(["render", scene, "--method", "sync", "--threads", "2", "--phases", "2", "--memory-limit", "20M"])
        .arg("--out")
        .arg(&sync_out)
        .current_dir(repo_root())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && stderr.contains("--memory-limit 20 MiB is too small"), "{stderr}");

    // The one-thread methods check it too: refused under 20 MiB, rendering under a limit they fit in.
    for method in ["pbpm", "path"] {
        let out = scratch_dir(&format!("memory-limit-{method}"));
        let run = |limit: &str| {
            Command::new(binary("coordinator"))
                .args(["render", scene, "--method", method, "--phases", "1", "--memory-limit", limit, "--quiet"])
                .arg("--out")
                .arg(&out)
                .current_dir(repo_root())
                .output()
                .unwrap()
        };
        let refused = run("20M");
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert!(
            !refused.status.success() && stderr.contains("--memory-limit 20 MiB is too small"),
            "{method}: {stderr}"
        );
        assert!(!out.join("run.json").exists(), "{method}: a refused run wrote a record");
        let fits = run("4G");
        assert!(fits.status.success(), "{method}: {}", String::from_utf8_lossy(&fits.stderr));
    }
}

#[test]
fn a_render_larger_than_the_machines_available_memory_is_refused_before_anything_is_sized_by_the_image() {
    // 16,384² pixels, the largest image the loader accepts: about 100 GiB for a coordinator's sums alone and
    // twice that for an engine's buffers.
    let available = photonfarm::render::memory::available_bytes().expect("/proc/meminfo");
    if available > 90 << 30 {
        eprintln!("skipped: this machine has {} GiB available, enough for the estimate", available >> 30);
        return;
    }
    let scene_dir = scratch_dir("too-large");
    let scene = cornell_at(&scene_dir, 16384);
    for method in ["pbpm", "path", "sync", "async", "three-level"] {
        let out = scratch_dir(&format!("too-large-{method}"));
        let o = Command::new(binary("coordinator"))
            .args(["render", scene.to_str().unwrap(), "--method", method, "--phases", "1", "--quiet", "--out"])
            .arg(&out)
            .current_dir(repo_root())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{method}: a render of 16,384² pixels started: {stderr}");
        assert!(
            stderr.contains("of memory this machine has available is not enough: this render needs about")
                && stderr.contains("--memory-limit sets the budget instead"),
            "{method}: {stderr}"
        );
        // Refused before the lit mask, which would have left its seconds and the output folder's files.
        assert!(!out.join("run.json").exists() && !out.join("preview.png").exists(), "{method}: outputs written");
    }
}

#[test]
fn bad_input_is_refused_with_a_message_and_no_output() {
    let out = scratch_dir("bad");
    for (args, needle) in [
        (vec!["render", "scenes/no-such-scene.toml"], "no-such-scene.toml"),
        (vec!["render", "scenes/cornell.toml", "--target-error", "0"], "--target-error"),
        (vec!["render", "scenes/cornell.toml", "--backward-diffuse-depth", "3"], "--backward-diffuse-depth"),
        (vec!["render", "scenes/cornell.toml", "--reference", "scenes/cornell.toml"], "cornell.toml"),
        (vec!["render", "scenes/cornell.toml", "--method", "path", "--threads", "2"], "--threads"),
        (vec!["render", "scenes/cornell.toml", "--cores", "0,x"], "--cores"),
        (vec!["render", "scenes/cornell.toml", "--group-size", "3"], "group size"),
    ] {
        let result = Command::new(binary("coordinator"))
            .args(&args)
            .arg("--out")
            .arg(&out)
            .current_dir(repo_root())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(!result.status.success(), "{args:?} was accepted");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    assert!(!out.join("run.json").exists());
}

#[test]
fn ctrl_c_stops_cleanly_and_writes_every_completed_phase() {
    let out = scratch_dir("interrupt");
    let mut child = Command::new(binary("coordinator"))
        .args(["render", "scenes/cornell.toml", "--time", "120", "--quiet", "--out"])
        .arg(&out)
        .current_dir(repo_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    let killed = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(killed.success());
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "the renderer did not stop after Ctrl-C");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success(), "exit status after Ctrl-C: {status:?}");
    let r = record(&out);
    assert_eq!(r["stop_reason"], "interrupted");
    assert!(r["totals"]["phases"].as_u64().unwrap() >= 1);
    assert!(out.join("image.exr").exists());
}

#[test]
fn a_reader_that_closes_stdout_early_neither_fails_the_render_nor_loses_its_files() {
    // As `coordinator render ... | head -0`: every line the render prints meets a closed pipe.
    let out = scratch_dir("closed-stdout");
    let mut child = Command::new(binary("coordinator"))
        .args(["render", "scenes/cornell.toml", "--method", "pbpm", "--phases", "2", "--ray-map", "--quiet", "--out"])
        .arg(&out)
        .current_dir(repo_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let result = child.wait_with_output().unwrap();
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert_eq!(record(&out)["totals"]["phases"], 2);
    assert!(out.join("image.exr").exists());
    assert!(std::fs::read_dir(out.join("raymap")).unwrap().next().is_some(), "no ray map written");
}

#[test]
fn a_run_chooses_its_light_paths_per_pixel_unless_they_are_fixed() {
    // On the Cornell box with two diffuse camera vertices, the second vertex's random direction is most of the
    // noise and more light paths gain little for their cost: starting from 1, the run moves below it
    // (docs/estimator.md), and says so in every history step.
    let out = scratch_dir("adaptive-light");
    let args =
        ["scenes/cornell.toml", "--method", "pbpm", "--phases", "32", "--backward-diffuse-depth", "2", "--quiet"];
    render(&args, &out);
    let r = record(&out);
    assert_eq!(r["settings"]["adaptive_light"], true);
    assert_eq!(r["settings"]["adaptive_depth"], false, "--backward-diffuse-depth fixes the depth");
    assert!(r["history"].as_array().unwrap().iter().all(|h| h["backward_diffuse_depth"] == 2));
    let light: Vec<f64> =
        r["history"].as_array().unwrap().iter().map(|h| h["light_paths_per_pixel"].as_f64().unwrap()).collect();
    assert_eq!(light.len(), 32);
    assert!(light[0] > 1.0 && light[1] < 1.0, "the first two steps try above and below 1: {light:?}");
    // Each fit needs about four phases per pixel of both trials, after four phases that settle the means: two
    // fits by phase 24.
    assert!(light[24..].iter().all(|&l| l < 1.0), "still trying 1 or more after 24 phases: {light:?}");

    let fixed = scratch_dir("fixed-light");
    render(
        &["scenes/cornell.toml", "--method", "pbpm", "--phases", "4", "--light-paths-per-pixel", "2", "--quiet"],
        &fixed,
    );
    let r = record(&fixed);
    assert_eq!(r["settings"]["adaptive_light"], false);
    assert!(r["history"].as_array().unwrap().iter().all(|h| h["light_paths_per_pixel"] == 2.0));
    assert_eq!(r["settings"]["adaptive_depth"], false, "cornell.toml fixes the depth");

    // Where the scene leaves the depth open, the run's first steps try 2 and 1 in turn.
    let open = scratch_dir("open-depth");
    render(&["scenes/ghost-room.toml", "--method", "pbpm", "--phases", "4", "--quiet"], &open);
    let r = record(&open);
    assert_eq!(r["settings"]["adaptive_depth"], true);
    let depths: Vec<u64> =
        r["history"].as_array().unwrap().iter().map(|h| h["backward_diffuse_depth"].as_u64().unwrap()).collect();
    assert_eq!(depths, [2, 1, 2, 1]);
}
