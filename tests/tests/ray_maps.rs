//! Ray maps through the real program: `render --ray-map` writes a map in every method (a three-level run's
//! workers send theirs to the coordinator, which writes one map) that `rays select` reads, selects from and
//! shows (overlay, side view, glTF scene, OBJ polylines, report); bad expressions and fractions are refused
//! with clear errors; the thread count changes neither a selection nor what a damaged map reports.

use end_to_end::{binary, cornell_at, render_output, repo_root, scratch_dir};
use std::path::Path;
use std::process::{Command, Output};

fn rays(args: &[&str]) -> Output {
    Command::new(binary("coordinator")).arg("rays").args(args).current_dir(repo_root()).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn a_recorded_render_is_selected_by_events_and_shown_as_overlay_polylines_and_report() {
    let dir = scratch_dir("ray-maps");
    let scene = cornell_at(&dir, 32);
    let run = dir.join("run");
    let o =
        render_output(&scene, &run, &["--method", "pbpm", "--phases", "3", "--ray-map", "--ray-map-fraction", "0.5"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("bytes per segment"), "{}", text(&o));
    assert!(run.join("raymap/stream-0.pfrm").is_file());

    let map = run.to_str().unwrap();
    let o =
        rays(&["select", map, "--where", "lightpath and light(light) and diffuse(*) >= 2", "--limit", "50", "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let sel = run.join("selection");
    for f in ["overlay.png", "section.png", "selection.glb", "paths.obj", "report.json", "report.txt"] {
        assert!(sel.join(f).is_file(), "{f} missing: {}", text(&o));
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sel.join("report.json")).unwrap()).unwrap();
    let matched = report["matched_paths"].as_u64().unwrap();
    let listed = report["paths"].as_array().unwrap();
    assert!(matched > 50 && listed.len() == 50, "{matched} matched, {} listed", listed.len());
    for p in listed {
        assert_eq!(p["kind"], "light");
        assert_eq!(p["source"], "light");
        let diffuse =
            p["vertices"].as_array().unwrap().iter().filter(|v| v["events"].as_str().unwrap().contains("diffuse"));
        assert!(diffuse.count() >= 2, "{p}");
    }
    let obj = std::fs::read_to_string(sel.join("paths.obj")).unwrap();
    assert_eq!(obj.lines().filter(|l| l.starts_with("l ")).count(), 50);
    let overlay = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(sel.join("overlay.png")).unwrap()));
    let info = overlay.read_info().unwrap();
    // Enlarged 8 times for legible lines, with the legend below the image.
    assert_eq!(info.info().width, 256);
    assert!(info.info().height > 256, "no legend strip");

    // A name the scene does not have is pointed at.
    let o = rays(&["select", map, "--where", "reflect(tallbox) and hits(lamp)", "--quiet"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("no object is called 'lamp'") && text(&o).contains("^^^^"), "{}", text(&o));
}

#[test]
fn bad_fractions_and_missing_maps_are_refused_with_clear_errors() {
    let dir = scratch_dir("ray-maps-refused");
    let scene = cornell_at(&dir, 16);
    let o = render_output(
        &scene,
        &dir.join("zero"),
        &["--method", "pbpm", "--phases", "1", "--ray-map", "--ray-map-fraction", "0"],
    );
    assert!(!o.status.success());
    assert!(text(&o).contains("--ray-map-fraction must be in (0, 1]"), "{}", text(&o));
    let o = rays(&["select", Path::new(&dir).join("nothing").to_str().unwrap(), "--where", "camera"]);
    assert!(!o.status.success(), "{}", text(&o));
}

/// The paths of a selection's report.json.
fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

/// The number after "ray map: " in a render's output: the paths its map holds.
fn recorded_paths(o: &Output) -> u64 {
    let t = text(o);
    let at = t.find("ray map: ").unwrap_or_else(|| panic!("no ray map summary: {t}")) + "ray map: ".len();
    t[at..].split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn the_in_process_parallel_methods_record_from_every_thread() {
    let dir = scratch_dir("ray-maps-parallel");
    let scene = cornell_at(&dir, 16);
    for method in ["sync", "async", "two-level"] {
        let run = dir.join(method);
        let o = render_output(
            &scene,
            &run,
            &["--method", method, "--threads", "2", "--phases", "2", "--ray-map", "--ray-map-fraction", "0.5"],
        );
        assert!(o.status.success(), "{method}: {}", text(&o));
        let paths = recorded_paths(&o);
        let o = rays(&["select", run.to_str().unwrap(), "--where", "camera or lightpath", "--limit", "1", "--quiet"]);
        assert!(o.status.success(), "{method}: {}", text(&o));
        let r = report(&run.join("selection"));
        assert!(paths > 0 && r["total_paths"] == paths, "{method}: {paths} recorded, {} read", r["total_paths"]);
    }
}

#[test]
fn a_three_level_run_on_two_synthetic_nodes_records_one_map_with_both_workers_paths() {
    let dir = scratch_dir("ray-maps-three-level");
    let scene = cornell_at(&dir, 32);
    let run = dir.join("run");
    let o = render_output(
        &scene,
        &run,
        &[
            "--method",
            "three-level",
            "--topology",
            "pack:1 numa:2 core:1 pu:1",
            "--group-size",
            "1",
            "--phases",
            "6",
            "--ray-map",
            "--ray-map-fraction",
            "0.25",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let recorded = recorded_paths(&o);
    let streams: Vec<_> = std::fs::read_dir(run.join("raymap")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(streams, ["stream-0.pfrm"], "the run's one map file");

    // Read whole: every path the coordinator counted, no portion damaged or cut.
    // The limit is the number recorded, so that every camera path is kept and listed whatever the run made.
    let o = rays(&["select", run.to_str().unwrap(), "--where", "camera", "--limit", &recorded.to_string(), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let sel = run.join("selection");
    let r = report(&sel);
    assert_eq!(r["total_paths"].as_u64().unwrap(), recorded);
    assert!(r["damaged"].as_array().unwrap().is_empty() && r["truncated"].as_array().unwrap().is_empty(), "{r}");
    // A camera path's phase is its pixel's j, which two processes interleave: worker 0's are odd, worker 1's even.
    let phases: Vec<u64> = r["paths"].as_array().unwrap().iter().map(|p| p["phase"].as_u64().unwrap()).collect();
    assert_eq!(phases.len() as u64, r["matched_paths"].as_u64().unwrap(), "every camera path listed");
    let odd = phases.iter().filter(|&&j| j % 2 == 1).count();
    assert!(odd > 0 && odd < phases.len(), "paths from one worker only: {odd} of {} odd phases", phases.len());
    let light = rays(&["select", run.to_str().unwrap(), "--where", "lightpath", "--limit", "1", "--quiet"]);
    assert!(light.status.success(), "{}", text(&light));
    assert!(report(&sel)["matched_paths"].as_u64().unwrap() > 0, "no light paths recorded");

    // The pictures and the glTF file of a selection with every path kept.
    let o = rays(&[
        "select",
        run.to_str().unwrap(),
        "--where",
        "lightpath and diffuse(*) >= 2",
        "--limit",
        "300",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for f in ["overlay.png", "section.png", "selection.glb"] {
        assert!(sel.join(f).is_file(), "{f} missing: {}", text(&o));
    }
    let listed = report(&sel)["paths"].as_array().unwrap().clone();
    assert!(!listed.is_empty());
    let bytes = std::fs::read(sel.join("selection.glb")).unwrap();
    let gltf = gltf::Gltf::from_slice(&bytes).expect("selection.glb is valid glTF");
    let blob = gltf.blob.as_deref().expect("a binary chunk");
    let paths_node = gltf.nodes().find(|n| n.name() == Some("paths")).expect("a node of the paths");
    let lines: Vec<Vec<[f32; 3]>> = paths_node
        .children()
        .map(|n| {
            let primitive = n.mesh().unwrap().primitives().next().unwrap();
            assert_eq!(primitive.mode(), gltf::mesh::Mode::Lines);
            primitive.reader(|_| Some(blob)).read_positions().unwrap().collect()
        })
        .collect();
    assert_eq!(lines.len(), listed.len(), "one line node per selected path");
    assert!(gltf.nodes().any(|n| n.name() == Some("floor")), "the scene's objects are in the file");
    for (p, points) in listed.iter().zip(&lines) {
        let vertices = p["vertices"].as_array().unwrap();
        for v in vertices.iter().filter(|v| !v["events"].as_str().unwrap().contains("escaped")) {
            let v: Vec<f32> = v["point"].as_array().unwrap().iter().map(|c| c.as_f64().unwrap() as f32).collect();
            assert!(points.iter().any(|q| q[..] == v[..]), "vertex {v:?} of {p} is not in its line");
        }
    }
}

/// The shipped lens scene at 72 × 48 pixels in `dir`, its last surface (s10) coated against reflection when
/// `coat_s10`.
fn lens_at(dir: &Path, coat_s10: bool) -> std::path::PathBuf {
    let mut text = std::fs::read_to_string(repo_root().join("scenes/lens.toml")).unwrap();
    assert!(text.contains("width = 360\n") && text.contains("[materials.n1717_to_air]\ntype = \"dielectric\"\n"));
    text = text.replace("width = 360\n", "width = 72\n").replace("height = 240\n", "height = 48\n");
    if coat_s10 {
        text = text.replace(
            "[materials.n1717_to_air]\ntype = \"dielectric\"\n",
            "[materials.n1717_to_air]\ntype = \"dielectric\"\nanti_reflection = true\n",
        );
    }
    let path = dir.join(if coat_s10 { "lens-coated.toml" } else { "lens.toml" });
    std::fs::write(&path, text).unwrap();
    path
}

/// `rays ghosts` on a path-traced lens whose every path was recorded: its report.
fn ghosts(dir: &Path, coat_s10: bool) -> serde_json::Value {
    let scene = lens_at(dir, coat_s10);
    let run = dir.join(if coat_s10 { "coated" } else { "uncoated" });
    let o = render_output(&scene, &run, &["--method", "path", "--phases", "3", "--ray-map", "--ray-map-fraction", "1"]);
    assert!(o.status.success(), "{}", text(&o));
    let o = rays(&["ghosts", run.to_str().unwrap(), "--top", "1000"]);
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_str(&std::fs::read_to_string(run.join("ghosts/ghosts.json")).unwrap()).unwrap()
}

#[test]
fn ghost_pairs_carry_the_ghost_layers_light_and_a_coated_surface_is_in_none() {
    let dir = scratch_dir("ray-maps-ghosts");
    let uncoated = ghosts(&dir, false);
    // Every path recorded: the pairs' light is the ghost layer's, up to f32 sums.
    let recorded = uncoated["ghost_light"].as_f64().unwrap();
    let layer = uncoated["ghost_layer"]["total"].as_f64().unwrap();
    assert!(layer > 0.0 && (recorded / layer - 1.0).abs() < 1e-3, "pairs {recorded}, ghost layer {layer}");
    let pairs = uncoated["pairs"].as_array().unwrap();
    let shares: f64 = pairs.iter().map(|p| p["share"].as_f64().unwrap()).sum();
    assert!((shares - 1.0).abs() < 1e-6, "shares add up to {shares}");
    let has_s10 = |p: &serde_json::Value| p["first"] == "s10" || p["second"] == "s10";
    assert!(pairs.iter().any(has_s10), "no pair involves s10 on the uncoated lens");
    let coated = ghosts(&dir, true);
    let pairs = coated["pairs"].as_array().unwrap();
    assert!(!pairs.is_empty() && !pairs.iter().any(has_s10), "{coated}");
}

/// `rays select MAP --where EXPR --threads T --limit LIMIT --out OUT --quiet`: its output and its report.
fn select_with(map: &Path, expr: &str, threads: usize, limit: usize, out: &Path) -> (Output, String) {
    let o = rays(&[
        "select",
        map.to_str().unwrap(),
        "--where",
        expr,
        "--threads",
        &threads.to_string(),
        "--limit",
        &limit.to_string(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    let report = std::fs::read_to_string(out.join("report.json")).unwrap_or_default();
    (o, report)
}

/// A path-traced lens whose every path was recorded, in `dir/run`: a map of several portions.
fn recorded_lens(dir: &Path) -> std::path::PathBuf {
    let scene = lens_at(dir, false);
    let run = dir.join("run");
    let o = render_output(&scene, &run, &["--method", "path", "--phases", "3", "--ray-map", "--ray-map-fraction", "1"]);
    assert!(o.status.success(), "{}", text(&o));
    run
}

/// The (offset, compressed length, paths) of every portion of a stream file, read from its portion headers.
fn portions_of(stream: &[u8]) -> Vec<(usize, usize, u64)> {
    let u32_at = |at: usize| u32::from_le_bytes(stream[at..at + 4].try_into().unwrap()) as usize;
    let mut at = 16 + u32_at(12);
    let mut out = Vec::new();
    while at + 20 <= stream.len() {
        assert_eq!(&stream[at..at + 4], b"PRTN");
        let compressed = u32_at(at + 4);
        out.push((at, compressed, u32_at(at + 12) as u64));
        at += 20 + compressed;
    }
    out
}

#[test]
fn one_two_and_three_threads_keep_the_same_first_matches_in_map_order() {
    let dir = scratch_dir("ray-maps-threads");
    let run = recorded_lens(&dir);
    let stream = std::fs::read(run.join("raymap/stream-0.pfrm")).unwrap();
    assert!(portions_of(&stream).len() >= 3, "{} portions", portions_of(&stream).len());
    let expr = "camera and reflect(*) >= 2";
    let (o, all) = select_with(&run, expr, 1, usize::MAX, &dir.join("all"));
    assert!(o.status.success(), "{}", text(&o));
    let all: serde_json::Value = serde_json::from_str(&all).unwrap();
    let every = all["paths"].as_array().unwrap();
    assert!(every.len() > 100 && every.len() as u64 == all["matched_paths"].as_u64().unwrap());
    // A limit that ends inside a later portion, so that the kept matches come from several portions.
    let limit = every.len() * 2 / 3;
    let mut reports = Vec::new();
    for threads in [1, 2, 3] {
        let (o, report) = select_with(&run, expr, threads, limit, &dir.join(format!("t{threads}")));
        assert!(o.status.success(), "{}", text(&o));
        reports.push(report);
    }
    assert!(reports[0] == reports[1] && reports[1] == reports[2], "the thread count changed the selection");
    let limited: serde_json::Value = serde_json::from_str(&reports[0]).unwrap();
    assert_eq!(limited["matched_paths"], all["matched_paths"]);
    assert_eq!(limited["matched_segments"], all["matched_segments"]);
    assert_eq!(limited["paths"].as_array().unwrap()[..], every[..limit], "not the first matches in map order");
}

#[test]
fn a_damaged_and_truncated_map_skips_the_damaged_portion_and_reads_every_whole_one_on_any_thread_count() {
    let dir = scratch_dir("ray-maps-damaged");
    let run = recorded_lens(&dir);
    let file = run.join("raymap/stream-0.pfrm");
    let mut stream = std::fs::read(&file).unwrap();
    let portions = portions_of(&stream);
    assert!(portions.len() >= 3 && portions.last().unwrap().1 > 200, "{portions:?}");
    // Damage the second portion's frame in its middle, and cut the last portion short.
    let (at, compressed, _) = portions[1];
    stream[at + 20 + compressed / 2] ^= 0x5a;
    let cut = 100;
    stream.truncate(stream.len() - cut);
    std::fs::write(&file, &stream).unwrap();
    let whole: u64 = portions[..portions.len() - 1].iter().enumerate().filter(|(i, _)| *i != 1).map(|(_, p)| p.2).sum();
    let left = portions.last().map(|p| (p.1 + 20 - cut) as u64).unwrap();

    let mut reports = Vec::new();
    for threads in [1, 2] {
        let (o, report) = select_with(&run, "camera or lightpath", threads, 10, &dir.join(format!("t{threads}")));
        assert!(o.status.success(), "{}", text(&o));
        let says = text(&o);
        assert!(says.contains(&format!("byte {} is corrupt", at)) && says.contains("it was skipped"), "{says}");
        assert!(says.contains(&format!("its last {left} bytes were left")), "{says}");
        reports.push(report);
    }
    assert!(reports[0] == reports[1], "the thread count changed the report of a damaged map");
    let report: serde_json::Value = serde_json::from_str(&reports[0]).unwrap();
    assert_eq!(report["total_paths"].as_u64(), Some(whole));
    assert_eq!(report["matched_paths"].as_u64(), Some(whole));
    assert_eq!(report["damaged"].as_array().unwrap().len(), 1, "{report}");
    assert_eq!(report["truncated"][0]["bytes_left"].as_u64(), Some(left), "{report}");
}
