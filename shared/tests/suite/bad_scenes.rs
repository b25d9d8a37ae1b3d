//! Malformed scene files give an error naming the file, the line and the field, never a panic.

use photonfarm::light::Light;
use photonfarm::scene::{Scene, SceneError};
use std::path::Path;

const GOOD: &str = r#"
[camera]
position = [0.0, 0.0, -1.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 40
width = 8
height = 8

[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[[objects]]
name = "floor"
material = "white"
quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }

[[lights]]
type = "point"
position = [0.0, 0.0, -0.5]
intensity = [1.0, 1.0, 1.0]
"#;

fn load(text: &str) -> Result<Scene, SceneError> {
    Scene::from_toml(text, Path::new("bad.toml"), &Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes"))
}

/// Loads `text`, expects an error on `line` whose message contains every one of `needles`.
fn expect_error(text: &str, line: Option<usize>, needles: &[&str]) {
    let err = match load(text) {
        Ok(_) => panic!("scene was accepted:\n{text}"),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert!(msg.starts_with("bad.toml"), "error does not name the file: {msg}");
    assert_eq!(err.line, line, "wrong line in: {msg}");
    for n in needles {
        assert!(msg.contains(n), "error {msg:?} does not mention {n:?}");
    }
}

fn line_of(text: &str, needle: &str) -> Option<usize> {
    text.lines().position(|l| l.contains(needle)).map(|i| i + 1)
}

#[test]
fn the_good_scene_loads() {
    load(GOOD).unwrap();
}

#[test]
fn unknown_material_names_the_field_and_the_known_materials() {
    let t = GOOD.replace("material = \"white\"", "material = \"whtie\"");
    expect_error(&t, line_of(&t, "whtie"), &["objects[0].material", "whtie", "white"]);
}

#[test]
fn a_number_that_is_not_a_number_names_the_line() {
    let t = GOOD.replace("fov_y_deg = 40", "fov_y_deg = \"forty\"");
    expect_error(&t, line_of(&t, "forty"), &["fov_y_deg", "expected"]);
}

#[test]
fn nan_is_refused() {
    let t = GOOD.replace("albedo = [0.5, 0.5, 0.5]", "albedo = [0.5, nan, 0.5]");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.albedo", "finite"]);
}

#[test]
fn albedo_above_one_is_refused() {
    let t = GOOD.replace("albedo = [0.5, 0.5, 0.5]", "albedo = [0.5, 1.5, 0.5]");
    expect_error(&t, line_of(&t, "[materials.white]"), &["albedo", "at most 1"]);
}

#[test]
fn missing_mesh_file_is_named() {
    let t = GOOD.replace(
        "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
        "mesh = \"nowhere/missing.obj\"",
    );
    expect_error(&t, line_of(&t, "missing.obj"), &["objects[0].mesh", "missing.obj", "cannot read"]);
}

/// Loads GOOD with its floor replaced by the OBJ mesh `obj`; returns the error's message.
fn obj_error(name: &str, obj: &str) -> String {
    let dir = std::env::temp_dir().join(format!("photonfarm-bad-obj-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("mesh.obj"), obj).unwrap();
    let t = GOOD.replace(
        "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
        "mesh = \"mesh.obj\"",
    );
    let err = Scene::from_toml(&t, Path::new("bad.toml"), &dir).err().expect("the broken OBJ was accepted");
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(err.line, line_of(&t, "mesh.obj"), "{err}");
    assert!(err.to_string().contains("objects[0].mesh"), "{err}");
    err.to_string()
}

#[test]
fn obj_indices_out_of_range_are_refused_with_a_clear_error() {
    let square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
    let e = obj_error("vertex", &format!("{square}f 1 2 5\n"));
    assert!(e.contains("face vertex index out of bounds"), "{e}");
    let e = obj_error("relative", &format!("{square}f -1 -2 -9\n"));
    assert!(e.contains("out of bounds"), "{e}");
    let e = obj_error("normal", &format!("{square}vn 0 0 1\nf 1//1 2//1 3//2\n"));
    assert!(e.contains("face normal index out of bounds"), "{e}");
    let e = obj_error("texcoord", &format!("{square}vt 0 0\nf 1/1 2/1 3/3\n"));
    assert!(e.contains("face texcoord index out of bounds"), "{e}");
    let e = obj_error("zero", &format!("{square}f 0 1 2\n"));
    assert!(e.contains("cannot parse OBJ"), "{e}");
}

#[test]
fn obj_normals_or_texture_coordinates_on_only_some_faces_are_refused_with_a_clear_error() {
    let square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\n";
    let e = obj_error("some-normals", &format!("{square}f 1//1 2//1 3//1\nf 1 3 4\n"));
    assert!(e.contains("vertex normals") && e.contains("some face corners"), "{e}");
    let e = obj_error("some-uvs", &format!("{square}f 1/1 2/2 3/3\nf 1 3 4\n"));
    assert!(e.contains("texture coordinates") && e.contains("some face corners"), "{e}");
}

#[test]
fn the_first_bad_triangle_or_object_of_a_large_obj_in_file_order_is_the_one_named() {
    // A strip of quads split into triangles, read in parallel: the error is the one a serial read meets first.
    let n = 40_000;
    let mut strip = String::new();
    for i in 0..=n {
        strip.push_str(&format!("v {i} 0 0\nv {i} 1 0\n"));
    }
    let faces = |bad: &[usize]| {
        let mut f = String::new();
        for i in 0..n {
            let (a, b, c) = (2 * i + 1, 2 * i + 3, 2 * i + 2);
            let c = if bad.contains(&i) { a } else { c };
            f.push_str(&format!("f {a} {b} {c}\n"));
        }
        f
    };
    let partial = "o partial\nvn 0 0 1\nf 1//1 3//1 2\n";
    let e = obj_error("first-bad", &format!("{strip}{}{partial}", faces(&[31_000, 17_000, 39_000])));
    assert!(e.contains("triangle 17000 of 'unnamed_object' is degenerate"), "{e}");
    let e = obj_error("first-partial", &format!("{strip}{partial}o strip\n{}", faces(&[3])));
    assert!(e.contains("'partial' gives vertex normals"), "{e}");
}

#[test]
fn degenerate_triangle_in_an_obj_is_located() {
    let dir = std::env::temp_dir().join(format!("photonfarm-bad-scene-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("flat.obj"), "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 4\nf 1 2 3\n").unwrap();
    let t = GOOD.replace(
        "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
        "mesh = \"flat.obj\"",
    );
    let err = Scene::from_toml(&t, Path::new("bad.toml"), &dir).err().expect("degenerate triangle accepted");
    let msg = err.to_string();
    assert_eq!(err.line, line_of(&t, "flat.obj"));
    assert!(msg.contains("triangle 1") && msg.contains("degenerate"), "{msg}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn unknown_field_is_refused_with_its_name() {
    let t = GOOD.replace("fov_y_deg = 40", "fov_y_deg = 40\nfocal_lenght = 50");
    expect_error(&t, line_of(&t, "focal_lenght"), &["focal_lenght"]);
}

#[test]
fn missing_required_field_is_named() {
    let t = GOOD.replace("width = 8\n", "");
    let err = load(&t).err().expect("accepted a camera without width");
    assert!(err.to_string().contains("width"), "{err}");
}

#[test]
fn object_with_two_shapes_is_refused() {
    let t = GOOD.replace("name = \"floor\"", "name = \"floor\"\nsphere = { center = [0.0, 0.0, 0.0], radius = 1.0 }");
    expect_error(&t, line_of(&t, "[[objects]]"), &["objects[0]", "exactly one shape"]);
}

#[test]
fn zero_sized_image_is_refused() {
    let t = GOOD.replace("height = 8", "height = 0");
    expect_error(&t, line_of(&t, "height = 0"), &["camera.height", "1..=16384"]);
}

#[test]
fn camera_looking_at_itself_is_refused() {
    let t = GOOD.replace("look_at = [0.0, 0.0, 0.0]", "look_at = [0.0, 0.0, -1.0]");
    expect_error(&t, line_of(&t, "look_at"), &["camera.look_at", "differ"]);
}

#[test]
fn scene_without_light_is_refused() {
    let t = GOOD.split("[[lights]]").next().unwrap().to_string();
    let err = load(&t).err().expect("accepted a scene with no light");
    assert!(err.to_string().contains("no light"), "{err}");
}

#[test]
fn emission_on_an_analytic_sphere_and_a_full_disc_makes_them_lights() {
    for shape in [
        "sphere = { center = [0.0, 0.0, 0.0], radius = 0.5 }",
        "annulus = { center = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], inner_radius = 0.0, outer_radius = 0.5 }",
    ] {
        let t = GOOD.replace(
            "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
            &format!("{shape}\nemission = [1.0, 1.0, 1.0]"),
        );
        let scene = load(&t).unwrap_or_else(|e| panic!("{shape}: {e}"));
        // The shape's light and the point light.
        assert_eq!(scene.lights.all().len(), 2, "{shape}");
    }
}

#[test]
fn emission_on_an_annulus_with_a_hole_or_a_lens_surface_is_refused() {
    for shape in [
        "annulus = { center = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], inner_radius = 0.1, outer_radius = 0.5 }",
        "lens_surface = { vertex = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], curvature_radius = 1.0, aperture_radius = 0.2 }",
    ] {
        let t = GOOD.replace(
            "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
            &format!("{shape}\nemission = [1.0, 1.0, 1.0]"),
        );
        expect_error(&t, line_of(&t, "emission"), &["objects[0].emission", "full disc"]);
    }
}

/// GOOD with its point light replaced by `light` (the lines of one `[[lights]]` table).
fn with_light(light: &str) -> String {
    GOOD.replace("type = \"point\"\nposition = [0.0, 0.0, -0.5]\nintensity = [1.0, 1.0, 1.0]", light)
}

/// A PFM file (little-endian, rows from the bottom) of `w` × `h` RGB texels.
fn pfm(w: usize, h: usize, texels: &[[f32; 3]]) -> Vec<u8> {
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for y in (0..h).rev() {
        for t in &texels[y * w..(y + 1) * w] {
            for c in t {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    bytes
}

/// Loads GOOD lit by an environment map `map.pfm` holding `bytes`, from a scratch folder.
fn load_with_map(bytes: &[u8]) -> (String, Result<Scene, SceneError>) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("map.pfm"), bytes).unwrap();
    let t = with_light("type = \"environment\"\nfilename = \"map.pfm\"");
    let r = Scene::from_toml(&t, Path::new("bad.toml"), dir.path());
    (t, r)
}

#[test]
fn environments_and_suns_load() {
    let (_, r) = load_with_map(&pfm(4, 3, &[[0.5, 1.0, 2.0]; 12]));
    assert_eq!(r.unwrap().lights.all().len(), 1);
    for light in [
        "type = \"environment\"\nradiance = [0.5, 0.5, 0.5]",
        "type = \"sun\"\ndirection = [0.0, -1.0, 0.2]\nirradiance = [3.0, 3.0, 3.0]",
        "type = \"directional\"\ndirection = [0.0, -1.0, 0.2]\nirradiance = [3.0, 3.0, 3.0]\nangular_radius_deg = 0.5",
    ] {
        load(&with_light(light)).unwrap_or_else(|e| panic!("{light}: {e}"));
    }
}

#[test]
fn an_environment_map_in_png_is_decoded_from_srgb_as_textures_are() {
    let dir = tempfile::tempdir().unwrap();
    let file = std::fs::File::create(dir.path().join("map.png")).unwrap();
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), 4, 3);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header().unwrap().write_image_data(&[128; 4 * 3 * 3]).unwrap();
    let t = with_light("type = \"environment\"\nfilename = \"map.png\"");
    let scene = Scene::from_toml(&t, Path::new("map.toml"), dir.path()).unwrap_or_else(|e| panic!("{e}"));
    let Light::Infinite(map) = &scene.lights.all()[0] else { panic!("not an environment") };
    // sRGB 128/255 is linear ((128/255 + 0.055)/1.055)^2.4 = 0.2158; read linearly it would be 0.502.
    let l = map.radiance(glam::Vec3::new(0.3, 0.8, -0.5).normalize());
    for c in l.to_array() {
        assert!((c - 0.2158).abs() < 1e-3, "{l:?}");
    }
}

#[test]
fn a_missing_environment_map_names_the_file_and_the_field() {
    let t = with_light("type = \"environment\"\nfilename = \"no/such/sky.exr\"");
    expect_error(&t, line_of(&t, "[[lights]]"), &["lights[0].filename", "no/such/sky.exr", "cannot read"]);
}

#[test]
fn an_environment_map_that_is_no_image_is_refused() {
    let t = with_light("type = \"environment\"\nfilename = \"cornell/floor.obj\"");
    expect_error(&t, line_of(&t, "[[lights]]"), &["lights[0].filename", "not an image file"]);
}

#[test]
fn an_environment_map_with_a_non_finite_texel_is_refused() {
    let mut texels = [[1.0f32; 3]; 12];
    texels[5][1] = f32::NAN;
    let (t, r) = load_with_map(&pfm(4, 3, &texels));
    let msg = r.err().expect("accepted a NaN texel").to_string();
    assert!(msg.contains("lights[0].filename") && msg.contains("not a finite number"), "{msg}");
    assert!(msg.starts_with(&format!("bad.toml:{}:", line_of(&t, "[[lights]]").unwrap())), "{msg}");
    assert!(msg.contains("pixel (1, 1)"), "the error names the texel: {msg}");
}

#[test]
fn an_environment_map_of_one_row_or_all_black_is_refused() {
    let (_, r) = load_with_map(&pfm(4, 1, &[[1.0; 3]; 4]));
    let msg = r.err().expect("accepted a map of one row").to_string();
    assert!(msg.contains("lights[0].filename") && msg.contains("at least 1 × 2 texels"), "{msg}");
    let (_, r) = load_with_map(&pfm(4, 3, &[[0.0; 3]; 12]));
    let msg = r.err().expect("accepted a black map").to_string();
    assert!(msg.contains("lights[0].filename") && msg.contains("black everywhere"), "{msg}");
}

#[test]
fn bad_environment_and_sun_parameters_name_their_field() {
    let cases = [
        ("type = \"environment\"", "lights[0].filename", "needs `filename`"),
        ("type = \"environment\"\nradiance = [0.0, 0.0, 0.0]", "lights[0].radiance", "not all zero"),
        ("type = \"environment\"\nradiance = [1.0, 1.0, 1.0]\nfilename = \"x.exr\"", "lights[0].radiance", "not both"),
        ("type = \"environment\"\nradiance = [1.0, 1.0, 1.0]\nscale = -2.0", "lights[0].scale", "positive"),
        (
            "type = \"environment\"\nfilename = \"x.exr\"\nto_world = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]",
            "lights[0].to_world",
            "not a rotation",
        ),
        ("type = \"sun\"\ndirection = [0.0, 0.0, 0.0]\nirradiance = [1.0, 1.0, 1.0]", "lights[0].direction", "zero"),
        ("type = \"sun\"\ndirection = [0.0, -1.0, 0.0]\nirradiance = [0.0, 0.0, 0.0]", "lights[0].irradiance", "not all zero"),
        (
            "type = \"sun\"\ndirection = [0.0, -1.0, 0.0]\nirradiance = [1.0, 1.0, 1.0]\nangular_radius_deg = 95",
            "lights[0].angular_radius_deg",
            "[0, 90)",
        ),
    ];
    for (light, field, what) in cases {
        let t = with_light(light);
        expect_error(&t, line_of(&t, "[[lights]]"), &[field, what]);
    }
}

#[test]
fn lens_aperture_larger_than_its_curvature_is_refused() {
    let t = GOOD.replace(
        "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
        "lens_surface = { vertex = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], curvature_radius = 0.01, aperture_radius = 0.02 }",
    );
    expect_error(&t, line_of(&t, "lens_surface"), &["aperture_radius", "smaller"]);
}

#[test]
fn annulus_whose_hole_is_not_smaller_than_its_rim_is_refused() {
    let t = GOOD.replace(
        "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }",
        "annulus = { center = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], inner_radius = 0.2, outer_radius = 0.1 }",
    );
    expect_error(&t, line_of(&t, "annulus"), &["objects[0].annulus.outer_radius", "larger than inner_radius"]);
}

/// GOOD with a lens surface named "rear" in front of a sensor camera (replacing the pinhole's field of view).
fn sensor_scene(rear_element: &str) -> String {
    GOOD.replace(
        "fov_y_deg = 40",
        &format!("type = \"sensor\"\nsensor_width = 0.036\nrear_element = \"{rear_element}\""),
    ) + r#"
[[objects]]
name = "rear"
material = "white"
lens_surface = { vertex = [0.0, 0.0, -0.5], axis = [0.0, 0.0, -1.0], curvature_radius = -0.1, aperture_radius = 0.02 }
"#
}

#[test]
fn sensor_camera_names_an_unknown_rear_element_and_the_known_ones() {
    load(&sensor_scene("rear")).unwrap();
    let t = sensor_scene("raer");
    expect_error(&t, line_of(&t, "raer"), &["camera.rear_element", "raer", "\"rear\""]);
}

#[test]
fn sensor_camera_refuses_a_field_of_view_and_a_rear_element_behind_it() {
    let t = sensor_scene("rear").replace("sensor_width = 0.036", "sensor_width = 0.036\nfov_y_deg = 40");
    expect_error(&t, line_of(&t, "fov_y_deg"), &["camera.fov_y_deg", "sensor"]);
    let t = sensor_scene("rear").replace("vertex = [0.0, 0.0, -0.5]", "vertex = [0.0, 0.0, -1.5]");
    expect_error(&t, line_of(&t, "rear_element ="), &["camera.rear_element", "in front of the sensor"]);
}

#[test]
fn pinhole_camera_without_a_field_of_view_is_refused() {
    let t = GOOD.replace("fov_y_deg = 40\n", "");
    expect_error(&t, line_of(&t, "[camera]"), &["camera.fov_y_deg", "pinhole"]);
}

#[test]
fn unknown_material_type_is_refused() {
    let t = GOOD.replace("type = \"diffuse\"", "type = \"velvet\"");
    let err = load(&t).err().expect("accepted an unknown material type");
    assert!(err.to_string().contains("velvet"), "{err}");
    assert!(err.line.is_some());
}

#[test]
fn broken_toml_syntax_names_the_line() {
    let t = GOOD.replace("width = 8", "width = [8");
    let err = load(&t).err().expect("accepted broken TOML");
    assert!(err.line.is_some(), "{err}");
}

#[test]
fn a_missing_scene_file_is_an_error_naming_it() {
    let err = Scene::load(Path::new("no/such/scene.toml")).err().expect("loaded a missing file");
    assert!(err.to_string().contains("no/such/scene.toml"), "{err}");
}

#[test]
fn the_shipped_scenes_load() {
    let lens = Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/lens.toml"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((lens.camera.width, lens.camera.height), (360, 240));
    for name in ["cornell.toml", "caustic.toml"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name);
        let s = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((s.camera.width, s.camera.height), (256, 256));
        assert_eq!(s.render.max_depth, 12);
    }
}

/// GOOD with the floor's material given an albedo texture.
fn textured(texture: &str) -> String {
    GOOD.replace("albedo = [0.5, 0.5, 0.5]", &format!("albedo = [0.5, 0.5, 0.5]\nalbedo_texture = \"{texture}\""))
}

#[test]
fn a_textured_quad_loads_with_texture_coordinates() {
    let s = load(&textured("hud/slide.png")).unwrap();
    assert!(s.materials[0].uses_uv());
    assert!((0..s.geometry.triangle_count() as u32).all(|i| s.triangle_uvs.get(i).is_some()));
    assert!(s.mesh_files.iter().any(|(p, _)| p == "hud/slide.png"), "the texture travels with the scene's files");
}

#[test]
fn a_missing_texture_file_names_the_field_and_the_path() {
    let t = textured("hud/no-such.png");
    expect_error(
        &t,
        line_of(&t, "[materials.white]"),
        &["materials.white.albedo_texture", "no-such.png", "cannot read"],
    );
}

#[test]
fn a_texture_that_is_not_a_png_is_refused() {
    let t = GOOD.replace("name = \"floor\"", "name = \"floor\"\nemission_texture = \"cornell/floor.obj\"");
    expect_error(&t, line_of(&t, "emission_texture"), &["objects[0].emission_texture", "floor.obj", "PNG"]);
}

#[test]
fn a_texture_on_a_shape_without_texture_coordinates_is_refused() {
    let quad = "quad = { corner = [-1.0, -1.0, 0.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }";
    let t = textured("hud/slide.png").replace(quad, "box = { min = [-1.0, -1.0, 0.0], max = [1.0, 1.0, 0.1] }");
    expect_error(
        &t,
        line_of(&t, "material = \"white\""),
        &["objects[0].material", "albedo_texture", "box", "texture coordinates"],
    );
    let t = textured("hud/slide.png").replace(quad, "mesh = \"cornell/floor.obj\"");
    expect_error(&t, line_of(&t, "material = \"white\""), &["objects[0].material", "vt"]);
    let t =
        GOOD.replace(quad, "sphere = { center = [0.0, 0.0, 1.0], radius = 0.5 }\nemission_texture = \"hud/slide.png\"");
    expect_error(
        &t,
        line_of(&t, "emission_texture"),
        &["objects[0].emission_texture", "sphere", "texture coordinates"],
    );
}

#[test]
fn a_diffuse_material_needs_an_albedo_or_a_texture() {
    let t = GOOD.replace("albedo = [0.5, 0.5, 0.5]", "");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.albedo"]);
}

#[test]
fn too_many_ghost_paths_are_refused_with_the_limit() {
    let t = format!("[render]\nghost_paths = 1000\n{GOOD}");
    expect_error(&t, line_of(&t, "ghost_paths"), &["render.ghost_paths", "at most 64", "1000"]);
}

#[test]
fn a_ghost_radius_outside_its_range_is_refused_with_the_range() {
    for bad in ["-1.0", "100.0", "nan"] {
        let t = format!("[render]\nghost_radius = {bad}\n{GOOD}");
        expect_error(&t, line_of(&t, "ghost_radius"), &["render.ghost_radius", "in [0, 32] (pixels)"]);
    }
}

/// GOOD with the floor's material replaced by the TOML lines `material`.
fn with_material(material: &str) -> String {
    GOOD.replace("type = \"diffuse\"\nalbedo = [0.5, 0.5, 0.5]", material)
}

#[test]
fn every_material_family_loads_into_its_own_surface() {
    use photonfarm::material::{Back, Surface};
    type IsFamily = fn(&Surface) -> bool;
    let cases: [(&str, IsFamily); 8] = [
        ("type = \"conductor\"\nmaterial = \"Au\"", |s| matches!(s, Surface::Conductor { roughness: None, .. })),
        (
            "type = \"conductor\"\nmaterial = \"Cu\"\nalpha_u = 0.1\nalpha_v = 0.3",
            |s| matches!(s, Surface::Conductor { roughness: Some(r), .. } if r.is_anisotropic()),
        ),
        ("type = \"conductor\"\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.2]\nalpha = 0.2", |s| {
            matches!(s, Surface::Conductor { roughness: Some(_), .. })
        }),
        ("type = \"dielectric\"\nior = 1.5", |s| matches!(s, Surface::Dielectric { .. })),
        ("type = \"dielectric\"\nior = 1.5\nalpha = 0.1", |s| matches!(s, Surface::RoughDielectric { .. })),
        ("type = \"thin_dielectric\"\nior = 1.5", |s| matches!(s, Surface::ThinDielectric { .. })),
        ("type = \"plastic\"\nalpha = 0.2", |s| matches!(s, Surface::Plastic { .. })),
        ("type = \"principled\"\nbase_color = [0.8, 0.2, 0.3]\nmetallic = 0.5", |s| {
            matches!(s, Surface::Principled(_))
        }),
    ];
    for (toml, is_family) in cases {
        let s = load(&with_material(toml)).unwrap_or_else(|e| panic!("{toml}: {e}"));
        assert!(is_family(&s.materials[0].front), "{toml} loaded as {:?}", s.materials[0].front);
        assert_eq!(s.materials[0].back, Back::Same, "{toml}: photonfarm's materials are two-sided by default");
    }
}

#[test]
fn an_unknown_metal_is_refused_with_the_known_ones() {
    let t = with_material("type = \"conductor\"\nmaterial = \"Unobtainium\"");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.material", "Unobtainium", "Au"]);
}

#[test]
fn a_roughness_of_zero_or_an_unknown_distribution_is_refused() {
    let t = with_material("type = \"conductor\"\nmaterial = \"Al\"\nalpha = 0.0");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.alpha", "above 0"]);
    let t = with_material("type = \"conductor\"\nmaterial = \"Al\"\nalpha = 0.1\ndistribution = \"phong\"");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.distribution", "phong", "ggx"]);
    let t = with_material("type = \"conductor\"\nmaterial = \"Al\"\nalpha_u = 0.1");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.alpha"]);
}

#[test]
fn a_conductor_needs_a_metal_or_both_eta_and_k() {
    let t = with_material("type = \"conductor\"\neta = [0.2, 0.9, 1.1]");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.eta", "both eta and k"]);
    let t = with_material("type = \"conductor\"\nmaterial = \"Au\"\neta = [0.2, 0.9, 1.1]\nk = [1.0, 1.0, 1.0]");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.material", "not both"]);
}

#[test]
fn the_back_of_a_material_is_black_the_same_or_another_material() {
    use photonfarm::material::{Back, Surface};
    let s = load(&with_material("type = \"diffuse\"\nalbedo = 0.5\nback = \"black\"")).unwrap();
    assert_eq!(s.materials[0].back, Back::Black);
    let t = format!(
        "{}\n[materials.red]\ntype = \"diffuse\"\nalbedo = [0.5, 0.0, 0.0]\n",
        with_material("type = \"plastic\"\nback = \"red\"")
    );
    let s = load(&t).unwrap();
    let white = &s.materials[s.objects[0].material as usize];
    assert!(matches!(&white.back, Back::Other(b) if matches!(**b, Surface::Diffuse { .. })), "{:?}", white.back);
    let t = with_material("type = \"diffuse\"\nalbedo = 0.5\nback = \"grene\"");
    expect_error(&t, line_of(&t, "[materials.white]"), &["materials.white.back", "grene", "black"]);
}

#[test]
fn an_opacity_mask_loads_as_a_texture_and_needs_texture_coordinates_when_it_varies() {
    let s = load(&with_material("type = \"diffuse\"\nalbedo = 0.5\nopacity = 0.5")).unwrap();
    assert!(s.materials[0].opacity.is_some());
    assert!(s.materials[0].has_delta(), "a cut-out passes light straight through");
    let s = load(&with_material("type = \"diffuse\"\nalbedo = 0.5\nopacity = { bitmap = \"hud/slide.png\" }")).unwrap();
    assert!(s.materials[0].uses_uv());
}
