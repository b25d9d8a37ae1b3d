//! `coordinator bench` and `coordinator reference` as a user runs them: every bench configuration becomes a real
//! render process, and the bench folder gets one results row per run, the runs' error against time, and the
//! report with its tables and comparisons.

use end_to_end::{binary, cornell_at, repo_root, scratch_dir};
use std::process::Command;

fn csv_rows(path: &std::path::Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    (header, lines.map(|l| l.split(',').map(String::from).collect()).collect())
}

#[test]
fn bench_writes_a_row_per_run_their_error_series_and_the_report() {
    let out = scratch_dir("bench");
    // Each run stops at its phases, however loaded the machine: what the checks below need, not a wall-clock
    // budget that a slow phase can use up (the time is only a cap).
    let result = Command::new(binary("coordinator"))
        .args(["bench", "--phases", "4", "--time", "300", "--scenes", "cornell"])
        .args(["--methods", "path,pbpm,two-level,three-level"])
        .args(["--threads", "1,2", "--out"])
        .arg(&out)
        .current_dir(repo_root())
        .output()
        .unwrap();
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));

    let (header, rows) = csv_rows(&out.join("results.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column {name}"));
    for name in ["topology", "processes", "peak_memory_bytes", "true_unlit", "true_all", "merges", "bytes_per_pixel"] {
        col(name);
    }
    // path and pbpm run at one thread only; the parallel methods at both counts.
    let runs: Vec<(String, String)> =
        rows.iter().map(|r| (r[col("method")].clone(), r[col("threads")].clone())).collect();
    let expected = [
        ("path", "1"),
        ("pbpm", "1"),
        ("two-level", "1"),
        ("two-level", "2"),
        ("three-level", "1"),
        ("three-level", "2"),
    ];
    assert_eq!(runs, expected.map(|(m, t)| (m.to_string(), t.to_string())).to_vec());
    for r in &rows {
        assert_eq!(r.len(), header.len(), "{r:?}");
        let number = |name: &str| r[col(name)].parse::<f64>().unwrap_or_else(|_| panic!("{name} in {r:?}"));
        assert!(number("wall_s") > 0.0 && number("peak_memory_bytes") > 1e6, "{r:?}");
        assert!(number("phases") >= 4.0, "{r:?}");
        // cornell ships a reference, so every run has a true error.
        assert!(number("true_unlit") > 0.0 && number("true_unlit") < 1.0, "{r:?}");
        let processes = if r[col("method")] == "three-level" { r[col("threads")].as_str() } else { "1" };
        assert_eq!(r[col("processes")], processes, "{r:?}");
        // A light path counts once in every map it gathers into: only groups sharing their maps (two-level on
        // two threads: two groups of one) count it more than once.
        let (paths, in_maps) = (number("light_paths"), number("map_light_paths"));
        match (r[col("method")].as_str(), r[col("threads")].as_str()) {
            ("path", _) => assert_eq!(paths, 0.0, "{r:?}"),
            ("two-level", "2") => {
                assert_eq!(r[col("groups")], "2", "{r:?}");
                assert!(in_maps > paths, "{r:?}");
            }
            _ => assert_eq!(in_maps, paths, "{r:?}"),
        }
    }

    let (series_header, series) = csv_rows(&out.join("series.csv"));
    assert_eq!(series_header[..5], ["scene", "method", "threads", "repeat", "time_s"]);
    for (method, threads) in expected {
        let points: Vec<&Vec<String>> = series.iter().filter(|p| p[1] == method && p[2] == threads).collect();
        // A single-threaded step is a phase: four of them. A parallel step is a whole round (or snapshot), which
        // may hold all four.
        let least = if method == "path" || method == "pbpm" { 4 } else { 1 };
        assert!(points.len() >= least, "{method} at {threads} threads has {} series points", points.len());
        let times: Vec<f64> = points.iter().map(|p| p[4].parse().unwrap()).collect();
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "{method}: series out of time order");
    }

    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("| cornell | two-level | 2 | 1×2×1 |") && report.contains("tracing speedup"), "{report}");
    assert!(report.contains("maps per light path"), "{report}");
    assert!(report.contains("PBPM against the path tracer") && report.contains("cornell: path tracer"), "{report}");
    assert!(report.contains("Two-level against sync and async"), "{report}");
    assert!(report.contains("- cornell, 2 threads: two-level tracing speedup"), "{report}");
}

#[test]
fn bench_refuses_bad_arguments_with_a_message() {
    for (args, needle) in [
        (vec!["bench", "--time", "0"], "--time"),
        (vec!["bench", "--threads", "0"], "--threads"),
        (vec!["bench", "--scenes", "no-such-scene"], "no-such-scene"),
    ] {
        let out = Command::new(binary("coordinator")).args(&args).current_dir(repo_root()).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(needle), "{args:?}: {stderr}");
    }
}

#[test]
fn reference_command_keeps_the_image_and_how_to_remake_it_and_never_overwrites_by_accident() {
    let dir = scratch_dir("reference");
    // A small image: a loaded machine still renders the phases that δ needs within the second.
    let scene = cornell_at(&dir, 32);
    let out = dir.join("references");
    let reference = |extra: &[&str]| {
        Command::new(binary("coordinator"))
            .arg("reference")
            .arg(&scene)
            .args(["--time", "1", "--out"])
            .arg(&out)
            .args(extra)
            .current_dir(repo_root())
            .output()
            .unwrap()
    };
    let first = reference(&[]);
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    assert!(out.join("cornell-path.exr").is_file());
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("cornell-path.json")).unwrap()).unwrap();
    let command = format!("coordinator render {} --method path --time 1 --seed 1000", scene.display());
    assert_eq!(record["command"], command.as_str());
    assert!(record.get("history").is_none() && record["error"]["delta_unlit"].as_f64().unwrap() > 0.0);

    let again = reference(&[]);
    assert!(!again.status.success() && String::from_utf8_lossy(&again.stderr).contains("--force"));
    let forced = reference(&["--force", "--radius-scale", "2"]);
    assert!(forced.status.success(), "{}", String::from_utf8_lossy(&forced.stderr));
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("cornell-path.json")).unwrap()).unwrap();
    assert!(record["command"].as_str().unwrap().ends_with("--seed 1000 --radius-scale 2"), "{}", record["command"]);
}
