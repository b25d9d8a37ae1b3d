//! The ghost layer through the real programs: a three-level render of the lens scene (worker processes on a
//! synthetic two-node topology, snapshots merged by the coordinator) writes a non-zero `ghost` layer into its
//! EXR, a resumed run carries the ghost sums over from its checkpoint, and a scene without a lens gets none.

use end_to_end::{cornell_at, render_output, repo_root, scratch_dir};
use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::render::checkpoint::Checkpoint;
use photonfarm::render::images::luminance_of;
use std::path::{Path, PathBuf};

const TWO_NODES: &str = "pack:1 numa:2 core:1 pu:1";

fn render(scene: &Path, out: &Path, args: &[&str]) {
    let o = render_output(scene, out, args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The shipped lens scene at 72 × 48 pixels, written into `dir` (it has no mesh to copy).
fn lens_at(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(repo_root().join("scenes/lens.toml")).unwrap();
    assert!(text.contains("width = 360\n") && text.contains("height = 240\n"), "the scene's resolution moved");
    let path = dir.join("lens.toml");
    std::fs::write(&path, text.replace("width = 360\n", "width = 72\n").replace("height = 240\n", "height = 48\n"))
        .unwrap();
    path
}

/// The ghost layer's sums of a run's checkpoint, with the pixel-phases they hold.
fn checkpointed_ghost(run: &Path, scene: &Path) -> (Vec<f64>, u64) {
    let scene = photonfarm::scene::Scene::load(scene).unwrap();
    let (_, sums) = Checkpoint::load(&run.join("checkpoint.bin"), &scene).unwrap();
    assert_eq!(sums.aux.layout().offset("ghost"), Some(0), "the checkpoint has no ghost layer");
    let ghost = (0..sums.pixels.len()).flat_map(|p| sums.aux.pixel(p)[..3].to_vec()).collect();
    (ghost, sums.pixels.iter().map(|p| p.phases as u64).sum())
}

#[test]
fn a_three_level_render_of_the_lens_writes_a_non_zero_ghost_layer_and_a_resumed_run_keeps_its_sums() {
    let dir = scratch_dir("ghost-layer");
    let scene = lens_at(&dir);
    let run = dir.join("run");
    let three = ["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1"];
    render(&scene, &run, &[&three[..], &["--phases", "16", "--seed", "41"]].concat());

    let path = run.join("image.exr");
    let layers = read_exr(&path).unwrap();
    let (ghost, total) = (find_layer(&layers, &path, "ghost").unwrap(), find_layer(&layers, &path, "total").unwrap());
    let ghost_pixels = ghost.rgb.iter().filter(|p| luminance_of(**p) > 0.0).count();
    let share = ghost.rgb.iter().map(|p| luminance_of(*p)).sum::<f64>()
        / total.rgb.iter().map(|p| luminance_of(*p)).sum::<f64>();
    println!(
        "three-level, 16 phases: ghost light on {ghost_pixels} of 3456 pixels, {:.3} % of the light",
        100.0 * share
    );
    assert!(ghost_pixels >= 20, "ghost light on only {ghost_pixels} pixels");
    for (i, (g, t)) in ghost.rgb.iter().zip(&total.rgb).enumerate() {
        // The lens disperses, so a channel of a pure spectral colour may be negative (outside the RGB gamut);
        // luminance, ȳ weighted, never is. Means of f64 sums written as f32: the overlay holds up to rounding.
        let (lg, lt) = (luminance_of(*g), luminance_of(*t));
        assert!(lg >= -1e-9 && lg <= lt * (1.0 + 1e-5) + 1e-12, "pixel {i}: ghost {g:?} over the total {t:?}");
    }

    // Continue the run from its checkpoint for 16 more phases than it reached (the workers render on until the
    // coordinator's stop arrives, so it may have many more than 16): sums only grow, so every ghost sum of the
    // checkpoint is still there, with the light of the phases added since.
    let (before, phases_before) = checkpointed_ghost(&run, &scene);
    let record: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap();
    let target = (record["error"]["min_phases"].as_u64().unwrap() + 16).to_string();
    let mut resume = three.to_vec();
    resume.extend(["--phases", &target, "--resume", run.to_str().unwrap()]);
    render(&scene, &run, &resume);
    let (after, phases_after) = checkpointed_ghost(&run, &scene);
    assert!(phases_after > phases_before, "the resumed run added no phase");
    // Per pixel in luminance: the lens disperses, so one channel of a spectral sample may be negative, but
    // its luminance (ȳ weighted) never is, and a pixel's luminance sum only grows.
    let luminance =
        |v: &[f64]| -> Vec<f64> { v.chunks(3).map(|c| photonfarm::color::luminance_f64([c[0], c[1], c[2]])).collect() };
    let (before, after) = (luminance(&before), luminance(&after));
    assert!(
        before.iter().zip(&after).all(|(b, a)| *a >= *b - 1e-12 * b.abs()),
        "a checkpointed ghost sum was lost on resume"
    );
    let (sum_before, sum_after) = (before.iter().sum::<f64>(), after.iter().sum::<f64>());
    println!("ghost sums: {sum_before:.4e} after {phases_before} pixel-phases, {sum_after:.4e} after {phases_after}");
    assert!(sum_after > sum_before, "the resumed run added no ghost light");
}

#[test]
fn a_render_of_a_scene_without_a_lens_writes_no_ghost_layer() {
    let dir = scratch_dir("no-ghost-layer");
    let scene = cornell_at(&dir, 16);
    let run = dir.join("run");
    render(&scene, &run, &["--method", "pbpm", "--phases", "2"]);
    let path = run.join("image.exr");
    let layers = read_exr(&path).unwrap();
    assert!(find_layer(&layers, &path, "total").is_ok());
    assert!(find_layer(&layers, &path, "ghost").is_err(), "a ghost layer for a scene without a lens");
}
