//! `coordinator render` on a Mitsuba 3 scene file with real processes: an XML scene with an include, a search
//! path, PLY and serialized meshes, a bitmap texture and a `$name` parameter renders on every method, and its
//! three-level workers, which receive the XML, the include and every mesh and texture by hash, render the image
//! one process does; so do two workers given the shipped `scenes/mitsuba/cornell.xml` and its PLY meshes, and
//! two workers given a scene that only `--approximate` imports, whose substitutions the run record names.

mod common;

use common::{assert_same_image, record};
use end_to_end::{binary, repo_root, scratch_dir};
use photonfarm::scene::mitsuba::serialized::{write_serialized, SerializedMesh};
use std::path::{Path, PathBuf};
use std::process::Command;

const TWO_NODES: &str = "pack:1 numa:2 core:1 pu:1";

/// A small room in `dir/scene/room.xml`: its walls a binary PLY quad and a serialized one, the floor a
/// textured rectangle, the light an emitting rectangle in an included file, the meshes and the texture in a
/// folder beside the scene's reached through `<path>`.
fn xml_scene(dir: &Path) -> PathBuf {
    let assets = dir.join("assets");
    std::fs::create_dir_all(assets.join("meshes")).unwrap();
    std::fs::create_dir_all(dir.join("scene/parts")).unwrap();
    std::fs::copy(repo_root().join("scenes/hud/slide.png"), assets.join("slide.png")).unwrap();
    // The back wall: the quad [−1, 1] × [0, 2] at z = −1, facing +z, as binary big-endian PLY.
    let mut ply = b"ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
        property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for v in [[-1.0f32, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 2.0, -1.0], [-1.0, 2.0, -1.0]] {
        for x in v {
            ply.extend(x.to_be_bytes());
        }
    }
    ply.push(4);
    for i in [0i32, 1, 2, 3] {
        ply.extend(i.to_be_bytes());
    }
    std::fs::write(assets.join("meshes/back.ply"), ply).unwrap();
    // The left wall at x = −1, facing +x, as the second mesh of a serialized file.
    let left = SerializedMesh {
        positions: vec![[-1.0, 0.0, 1.0], [-1.0, 0.0, -1.0], [-1.0, 2.0, -1.0], [-1.0, 2.0, 1.0]],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        ..SerializedMesh::default()
    };
    let unused = SerializedMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        triangles: vec![[0, 1, 2]],
        ..SerializedMesh::default()
    };
    std::fs::write(assets.join("meshes/walls.serialized"), write_serialized(&[unused, left], false).unwrap()).unwrap();
    std::fs::write(
        dir.join("scene/parts/light.xml"),
        r#"<scene version="3.0.0">
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/><translate y="1.99"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="$radiance"/></emitter>
    </shape>
</scene>"#,
    )
    .unwrap();
    let text = r#"<scene version="3.0.0">
    <default name="radiance" value="5"/>
    <path value="../assets"/>
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="55"/>
        <transform name="to_world"><lookat origin="0, 1, 3.2" target="0, 1, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="24"/><integer name="height" value="18"/>
            <rfilter type="gaussian"/>
        </film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse">
            <texture name="reflectance" type="bitmap"><string name="filename" value="slide.png"/></texture>
        </bsdf>
    </shape>
    <shape type="ply"><string name="filename" value="meshes/back.ply"/></shape>
    <shape type="serialized">
        <string name="filename" value="meshes/walls.serialized"/>
        <integer name="shape_index" value="1"/>
        <bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.2, 0.2"/></bsdf></bsdf>
    </shape>
    <include filename="parts/light.xml"/>
</scene>"#;
    let path = dir.join("scene/room.xml");
    std::fs::write(&path, text).unwrap();
    path
}

fn coordinator(scene: &Path, out: &Path, args: &[&str]) -> std::process::Output {
    let o = Command::new(binary("coordinator"))
        .arg("render")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .args(args)
        .current_dir(repo_root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
    o
}

/// Renders `scene` with `pbpm` in one process (seed `seed`) and with three-level over two worker processes (seed
/// `seed + 1`), `phases` each, and checks that both read the same scene and that both workers finished: a worker
/// that could not rebuild the scene from the files it was sent would have failed its job. Returns both folders.
fn one_process_and_two_workers(scene: &Path, dir: &Path, args: &[&str], phases: &str, seed: u64) -> (PathBuf, PathBuf) {
    let (single, three) = (dir.join("single"), dir.join("three"));
    let (seed1, seed3) = (seed.to_string(), (seed + 1).to_string());
    coordinator(scene, &single, &[args, &["--method", "pbpm", "--phases", phases, "--seed", &seed1]].concat());
    let three_level = ["--method", "three-level", "--topology", TWO_NODES, "--group-size", "1"];
    coordinator(scene, &three, &[args, &three_level, &["--phases", phases, "--seed", &seed3]].concat());
    let (r, r3) = (record(&single), record(&three));
    assert_eq!(r3["scene_hash"], r["scene_hash"]);
    let workers = r3["workers"].as_array().unwrap();
    assert_eq!(workers.len(), 2, "{workers:?}");
    for w in workers {
        assert_eq!(w["state"], "finished", "{w}");
    }
    (single, three)
}

#[test]
fn an_xml_scene_renders_on_every_method_and_three_level_workers_render_the_image_of_one_process() {
    let dir = scratch_dir("mitsuba-scene");
    let scene = xml_scene(&dir);
    let define = ["--define", "radiance=8"];
    let (single, three) = one_process_and_two_workers(&scene, &dir, &define, "100", 3);
    let r = record(&single);
    assert_eq!((r["width"].as_u64(), r["height"].as_u64()), (Some(24), Some(18)));
    let flags: Vec<&str> = r["flags"].as_array().unwrap().iter().filter_map(|f| f.as_str()).collect();
    assert!(flags.iter().any(|f| f.starts_with("scene import:") && f.contains("gaussian")), "{flags:?}");
    assert_same_image(&single, &three, "XML scene, three-level against one process");
    for method in ["path", "sync", "async", "two-level", "combination"] {
        let out = dir.join(method);
        let mut args = vec!["--method", method, "--phases", "2"];
        if method == "combination" {
            args.extend(["--topology", TWO_NODES]);
        }
        coordinator(&scene, &out, &[&define[..], &args[..]].concat());
        assert_eq!(record(&out)["scene_hash"], r["scene_hash"], "{method}");
    }
}

#[test]
fn the_shipped_mitsuba_cornell_box_renders_over_two_worker_processes_to_the_image_of_one_process() {
    let dir = scratch_dir("mitsuba-cornell");
    let scene = repo_root().join("scenes/mitsuba/cornell.xml");
    let small = ["--define", "resx=32", "--define", "resy=32"];
    let (single, three) = one_process_and_two_workers(&scene, &dir, &small, "300", 5);
    assert_eq!((record(&three)["width"].as_u64(), record(&three)["height"].as_u64()), (Some(32), Some(32)));
    assert_same_image(&single, &three, "shipped cornell.xml, three-level against one process");
}

#[test]
fn without_approximate_an_unsupported_element_is_refused_at_its_line_and_with_it_workers_render_the_noted_substitutes()
{
    let dir = scratch_dir("mitsuba-approximate");
    let scene = xml_scene(&dir);
    // The room with an integrator and a BSDF that have no exact counterpart.
    let text = std::fs::read_to_string(&scene).unwrap();
    let text = text
        .replace(r#"<integrator type="path"><integer name="max_depth" value="4"/></integrator>"#,
            r#"<integrator type="bdpt"><integer name="max_depth" value="4"/></integrator>"#)
        .replace("<include", "<shape type=\"sphere\"><float name=\"radius\" value=\"0.3\"/><point name=\"center\" x=\"0\" y=\"0.3\" z=\"0\"/><bsdf type=\"hair\"/></shape>\n    <include");
    std::fs::write(&scene, &text).unwrap();
    let line_of = |needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;
    let refused = Command::new(binary("coordinator"))
        .arg("render")
        .arg(&scene)
        .args(["--out", dir.join("refused").to_str().unwrap(), "--quiet", "--phases", "2"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "an integrator without a counterpart rendered: {stderr}");
    assert!(
        stderr.contains(&format!("room.xml:{}:", line_of("bdpt"))) && stderr.contains("bdpt"),
        "the refusal names neither the element nor its line: {stderr}"
    );
    assert!(!dir.join("refused/image.exr").exists(), "a refused scene left an image");
    let (single, three) = one_process_and_two_workers(&scene, &dir, &["--approximate"], "100", 7);
    for out in [&single, &three] {
        let r = record(out);
        let flags: Vec<&str> = r["flags"].as_array().unwrap().iter().filter_map(|f| f.as_str()).collect();
        for (element, line) in [("bdpt", line_of("bdpt")), ("hair", line_of("hair"))] {
            assert!(
                flags.iter().any(|f| f.starts_with("scene import: approximated: ")
                    && f.contains(&format!("room.xml:{line}:"))
                    && f.contains(element)),
                "no flag for {element} at line {line}: {flags:?}"
            );
        }
    }
    assert_same_image(&single, &three, "--approximate, three-level against one process");
}
