//! A scene's description, which both readers produce and one build step turns into a scene: a TOML scene and
//! its Mitsuba twin give descriptions that build the same scene; a description survives the encoding jobs
//! carry it in and hashes the same on the other side, without the paths it was read from; and an error only the
//! build step can find (it needs a file's content) names the file, line and element in both formats.

use glam::{Vec2, Vec3};
use photonfarm::light::Light;
use photonfarm::scene::description::SceneDescription;
use photonfarm::scene::{MitsubaOptions, Scene, SceneError};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// The TOML scene `name` and its Mitsuba twin at the TOML scene's size, read into descriptions.
fn twin_descriptions(name: &str) -> (SceneDescription, SceneDescription, photonfarm::scene::SceneFiles) {
    let toml_path = scenes_dir().join(format!("{name}.toml"));
    let (toml, _) = SceneDescription::read(&toml_path, &MitsubaOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let size = |v: u32| v.to_string();
    let defines = vec![("resx".to_string(), size(toml.camera.width)), ("resy".to_string(), size(toml.camera.height))];
    let xml_path = scenes_dir().join("mitsuba").join(format!("{name}.xml"));
    let (xml, xml_files) = SceneDescription::read(&xml_path, &MitsubaOptions { defines, approximate: false })
        .unwrap_or_else(|e| panic!("{e}"));
    (toml, xml, xml_files)
}

/// Every triangle's area, summed: what a scene's triangles add up to, whatever order or meshes they come in.
fn total_area(scene: &Scene) -> f64 {
    (0..scene.geometry.triangle_count() as u32).map(|t| scene.geometry.triangle(t).area() as f64).sum()
}

/// The emitting triangles as (centroid, radiance, unit normal), sorted.
fn emitters(scene: &Scene) -> Vec<(Vec3, Vec3, Vec3)> {
    let mut lights: Vec<_> = scene
        .lights
        .all()
        .iter()
        .filter_map(|light| match light {
            Light::Area { triangle, emission, normal, .. } => {
                let v = scene.geometry.triangle(*triangle).v;
                Some(((v[0] + v[1] + v[2]) / 3.0, *emission, *normal))
            }
            _ => None,
        })
        .collect();
    lights.sort_by(|a, b| a.0.to_array().partial_cmp(&b.0.to_array()).unwrap());
    lights
}

#[test]
fn a_toml_scene_and_its_mitsuba_twin_describe_and_build_the_same_scene() {
    for name in ["cornell", "caustic", "glossy-room"] {
        let (toml, xml, xml_files) = twin_descriptions(name);
        // The descriptions agree where the formats say the same thing.
        assert_eq!((toml.camera.width, toml.camera.height), (xml.camera.width, xml.camera.height), "{name}");
        assert_eq!(toml.render.max_depth, xml.render.max_depth, "{name}");
        let forward = |c: &photonfarm::scene::description::CameraDesc| (c.look_at - c.position).normalize();
        for (a, b) in [(toml.camera.position, xml.camera.position), (forward(&toml.camera), forward(&xml.camera))] {
            assert!((a - b).length() < 1e-5, "{name}: camera {a} vs {b}");
        }
        // The twin names every file by its path and the SHA-256 of its bytes on disk (the glossy room's shapes
        // and its checkerboard need none).
        assert_eq!(xml.files.is_empty(), name == "glossy-room", "{name}");
        for f in &xml.files {
            let bytes = std::fs::read(scenes_dir().join("mitsuba").join(&f.path)).unwrap();
            assert_eq!(f.sha256, format!("{:x}", Sha256::digest(&bytes)), "{name}: {}", f.path);
            assert_eq!(xml_files[&f.path], bytes, "{name}: {}", f.path);
        }
        // Both build, through the one build step, to the same scene.
        let (a, b) = (Scene::load(&scenes_dir().join(format!("{name}.toml"))).unwrap(), {
            Scene::from_description(&xml, &xml_files).unwrap()
        });
        for (x, y) in [(0, 0), (a.camera.width / 2, a.camera.height / 2), (a.camera.width - 1, a.camera.height - 1)] {
            let (r, s) = (a.camera.generate_ray(x, y, Vec2::splat(0.5), Vec2::ZERO).ray, {
                b.camera.generate_ray(x, y, Vec2::splat(0.5), Vec2::ZERO).ray
            });
            assert!((r.direction - s.direction).length() < 1e-5, "{name}: pixel ({x}, {y})");
        }
        let (ea, eb) = (emitters(&a), emitters(&b));
        assert_eq!(ea.len(), eb.len(), "{name}: emitting triangles");
        for (p, q) in ea.iter().zip(&eb) {
            assert!(
                (p.0 - q.0).length() < 1e-5 && (p.1 - q.1).length() <= 1e-6 * p.1.length(),
                "{name}: {p:?} vs {q:?}"
            );
        }
        let (area_a, area_b) = (total_area(&a), total_area(&b));
        // The glossy room's spheres are analytic in both; its triangles are walls, a cube and light panels.
        assert!((area_a - area_b).abs() <= 1e-4 * area_a, "{name}: triangle area {area_a} vs {area_b}");
        let ((lo_a, hi_a), (lo_b, hi_b)) = (a.geometry.bounds().unwrap(), b.geometry.bounds().unwrap());
        assert!((lo_a - lo_b).length() < 1e-4 && (hi_a - hi_b).length() < 1e-4, "{name}: bounds");
        assert_eq!(a.has_delta_surfaces, b.has_delta_surfaces, "{name}");
    }
}

#[test]
fn a_description_survives_the_jobs_encoding_and_hashes_the_same() {
    let shipped = ["cornell.toml", "caustic.toml", "materials.toml", "outdoor.toml", "lens.toml", "hud.toml"];
    let twins = ["mitsuba/cornell.xml", "mitsuba/glossy-room.xml"];
    for name in shipped.iter().chain(&twins) {
        let path = scenes_dir().join(name);
        let (desc, files) = SceneDescription::read(&path, &MitsubaOptions::default()).unwrap();
        let bytes = desc.to_bytes();
        let (back, read): (SceneDescription, usize) =
            bincode::serde::decode_from_slice(&bytes, bincode::config::standard()).unwrap();
        assert_eq!(read, bytes.len(), "{name}");
        assert_eq!(back, desc, "{name}");
        assert_eq!(back.hash(), desc.hash(), "{name}");
        // The received description builds the scene the reader's machine builds, hash and all.
        let here = Scene::from_description(&desc, &files).unwrap();
        let there = Scene::from_description(&back, &files).unwrap();
        assert_eq!(
            (here.hash.as_str(), here.geometry.triangle_count()),
            (there.hash.as_str(), there.geometry.triangle_count())
        );
        assert_eq!(here.hash, desc.hash(), "{name}");
        // The scene read from another folder is the same scene: its hash leaves out where it was read.
        let mut moved = desc.clone();
        moved.path = PathBuf::from("/elsewhere").join(name);
        assert_eq!(moved.hash(), desc.hash(), "{name}");
    }
    // What the scene says is in the hash: another size is another scene.
    let (mut desc, _) = SceneDescription::read(&scenes_dir().join("cornell.toml"), &MitsubaOptions::default()).unwrap();
    let hash = desc.hash();
    desc.camera.width += 1;
    assert_ne!(desc.hash(), hash);
}

#[test]
fn a_file_that_is_not_the_one_described_is_refused_by_name() {
    let (desc, mut files) =
        SceneDescription::read(&scenes_dir().join("cornell.toml"), &MitsubaOptions::default()).unwrap();
    let name = desc.files[0].path.clone();
    files.get_mut(&name).unwrap().push(b'\n');
    let e = Scene::from_description(&desc, &files).err().expect("a changed file is refused");
    assert!(e.message.contains(&name) && e.message.contains("SHA-256"), "{e}");
    files.remove(&name);
    let e = Scene::from_description(&desc, &files).err().expect("a missing file is refused");
    assert!(e.message.contains(&name) && e.message.contains("not sent"), "{e}");
    // Files known to be the described ones are not hashed again, but one missing is refused all the same.
    let e = Scene::from_hashed_files(&desc, &files).err().expect("a missing file is refused");
    assert!(e.message.contains(&name) && e.message.contains("not sent"), "{e}");
}

#[test]
fn files_already_hashed_build_the_scene_the_checked_ones_do() {
    let (desc, files) = SceneDescription::read(&scenes_dir().join("cornell.toml"), &MitsubaOptions::default()).unwrap();
    let checked = Scene::from_description(&desc, &files).unwrap();
    let trusted = Scene::from_hashed_files(&desc, &files).unwrap();
    assert_eq!(checked.hash, trusted.hash);
    assert!(checked.geometry.triangle_count() > 0);
    assert_eq!(checked.geometry.triangle_count(), trusted.geometry.triangle_count());
}

/// A triangle in an OBJ file without texture coordinates.
const OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

/// The 1-based line of the first line of `text` that contains `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).expect("the needle is in the text") + 1
}

/// Reads `text` (written to `name` beside `tri.obj`) into a description, which must succeed, and builds it,
/// which must fail: the error is the build step's.
fn build_error(name: &str, text: &str) -> (SceneError, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tri.obj"), OBJ).unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    let (desc, files) = SceneDescription::read(&path, &MitsubaOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let e = Scene::from_description(&desc, &files).err().expect("the build step refuses the scene");
    // The scene loaded in one go fails the same way, and so does a coordinator's, which builds no BVH.
    assert_eq!(Scene::load(&path).err(), Some(e.clone()));
    assert_eq!(Scene::untraced_from_hashed_files(&desc, &files).err(), Some(e.clone()));
    (e, path)
}

#[test]
fn an_error_the_build_step_finds_names_the_file_line_and_element_in_both_formats() {
    let toml = r#"
[camera]
position = [0.3, 0.3, -1.0]
look_at = [0.3, 0.3, 0.0]
fov_y_deg = 40
width = 8
height = 8

[materials.checked]
type = "diffuse"
albedo = { checkerboard = true }

[[objects]]
name = "triangle"
material = "checked"
mesh = "tri.obj"

[[lights]]
type = "point"
position = [0.0, 0.0, -1.0]
intensity = [1.0, 1.0, 1.0]
"#;
    let (e, path) = build_error("scene.toml", toml);
    assert_eq!(e.file, path);
    assert_eq!(e.line, Some(line_of(toml, "material = \"checked\"")), "{e}");
    assert_eq!(e.field.as_deref(), Some("objects[0].material"), "{e}");
    assert!(e.message.contains("no texture coordinates") && e.message.contains("OBJ"), "{e}");

    let xml = r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <film type="hdrfilm">
            <integer name="width" value="8"/>
            <integer name="height" value="8"/>
        </film>
    </sensor>
    <shape type="obj" id="triangle">
        <string name="filename" value="tri.obj"/>
        <bsdf type="diffuse">
            <texture type="checkerboard" name="reflectance"/>
        </bsdf>
    </shape>
    <emitter type="point">
        <point name="position" x="0" y="0" z="1"/>
    </emitter>
</scene>
"#;
    let (e, path) = build_error("scene.xml", xml);
    assert_eq!(e.file, path);
    assert_eq!(e.line, Some(line_of(xml, "<shape type=\"obj\"")), "{e}");
    assert_eq!(e.field.as_deref(), Some("<shape type=\"obj\">"), "{e}");
    assert!(e.message.contains("no texture coordinates"), "{e}");
}

#[test]
fn an_untraced_scene_has_the_traced_ones_lights_objects_and_layers_and_no_bvh() {
    for name in ["cornell.toml", "caustic.toml", "outdoor-sun.toml", "outdoor.toml", "hud.toml", "lens.toml"] {
        let path = scenes_dir().join(name);
        let traced = Scene::load(&path).unwrap();
        let untraced = Scene::load_untraced(&path, &MitsubaOptions::default()).unwrap();
        assert!(untraced.is_released() && !traced.is_released(), "{name}");
        assert_eq!(untraced.geometry.triangle_count(), 0, "{name}");
        assert_eq!((&untraced.hash, &untraced.mesh_files), (&traced.hash, &traced.mesh_files), "{name}");
        let objects = |s: &Scene| s.objects.iter().map(|o| (o.name.clone(), o.material)).collect::<Vec<_>>();
        assert_eq!(objects(&untraced), objects(&traced), "{name}");
        // The sun's and the environment's light paths start on the scene's bounding sphere: the same one.
        assert_eq!(untraced.lights.scene_sphere(), traced.lights.scene_sphere(), "{name}");
        assert_eq!(untraced.lights.all().len(), traced.lights.all().len(), "{name}");
        assert_eq!(
            photonfarm::ray_map::emitter_names(&untraced),
            photonfarm::ray_map::emitter_names(&traced),
            "{name}"
        );
        let layers = |s: &Scene| photonfarm::accumulation::AuxLayout::for_scene(s, 2);
        assert_eq!(layers(&untraced), layers(&traced), "{name}");
        assert_eq!(untraced.has_delta_surfaces, traced.has_delta_surfaces, "{name}");
    }
}

#[test]
fn a_released_scene_keeps_what_describes_it_and_refuses_to_be_traced() {
    let mut scene = Scene::load(&scenes_dir().join("cornell.toml")).unwrap();
    assert!(scene.geometry.triangle_count() > 0);
    let (hash, files, camera) = (scene.hash.clone(), scene.mesh_files.clone(), scene.camera.pixel_count());
    scene.release_geometry();
    assert!(scene.is_released());
    assert_eq!(scene.geometry.triangle_count(), 0);
    assert!(scene.triangle_uvs.is_empty());
    // What a coordinator sends and saves is unchanged.
    assert_eq!((scene.hash.clone(), scene.mesh_files.clone(), scene.camera.pixel_count()), (hash, files, camera));
    assert_eq!(scene.description.hash(), scene.hash);
    let traced = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        photonfarm::accumulation::LitMask::of_scene(&scene, 8)
    }));
    assert!(traced.is_err(), "a released scene must not render an empty world");
}

#[test]
fn triangles_keep_the_order_their_objects_were_added_in_when_a_mesh_follows_quads() {
    // Four triangles in a row along x, at z = 1; a quad before them and an emitting one after.
    let obj = "v 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\nv 2 0 1\nv 2 1 1\nf 1 2 3\nf 2 4 3\nf 2 5 4\nf 5 6 4\n";
    let toml = r#"
[camera]
position = [1.0, 0.5, -2.0]
look_at = [1.0, 0.5, 1.0]
fov_y_deg = 40
width = 8
height = 8

[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[[objects]]
name = "floor"
material = "white"
quad = { corner = [-1.0, -1.0, 0.0], edge1 = [4.0, 0.0, 0.0], edge2 = [0.0, 0.0, 3.0] }

[[objects]]
name = "strip"
material = "white"
mesh = "strip.obj"

[[objects]]
name = "light"
material = "white"
emission = [1.0, 1.0, 1.0]
quad = { corner = [0.0, 2.0, 0.0], edge1 = [1.0, 0.0, 0.0], edge2 = [0.0, 0.0, 1.0] }
"#;
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("strip.obj"), obj).unwrap();
    std::fs::write(dir.path().join("scene.toml"), toml).unwrap();
    let scene = Scene::load(&dir.path().join("scene.toml")).unwrap();
    let g = &scene.geometry;
    let objects: Vec<u32> = (0..g.triangle_count() as u32).map(|t| g.object_of_triangle(t)).collect();
    assert_eq!(objects, [0, 0, 1, 1, 1, 1, 2, 2]);
    // The mesh's triangles, in the file's order, after the floor's.
    let xs: Vec<f32> = (2..6).map(|t| g.triangle(t).v.iter().map(|v| v.x).sum::<f32>()).collect();
    assert_eq!(xs, [1.0, 2.0, 4.0, 5.0]);
    assert!((2..6).all(|t| g.triangle(t).v.iter().all(|v| v.z == 1.0)));
    // The light's triangles are the last two, found by the index they were added with.
    let lit: Vec<u32> = scene
        .lights
        .all()
        .iter()
        .filter_map(|l| match l {
            Light::Area { triangle, .. } => Some(*triangle),
            _ => None,
        })
        .collect();
    assert_eq!(lit, [6, 7]);
    assert!(lit.iter().all(|&t| g.triangle(t).v.iter().all(|v| v.y == 2.0)));
}
