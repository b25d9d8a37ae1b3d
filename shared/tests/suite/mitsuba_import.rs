//! Mitsuba 3 scenes imported into photonfarm's `Scene`: a room written in both formats renders the same image,
//! every BSDF maps to its family, PLY (ASCII, both binary byte orders) and serialized meshes load with their
//! texture coordinates, mirrored meshes keep their sides, every emitter type maps to the light of its TOML twin,
//! instances are their group's shapes written out, a worker rebuilds the same scene from the job's files, and
//! unsupported or malformed input is refused at its file, line and element.

use crate::common::{mean_sem, regions_phase_means, settings};
use glam::{DMat3, DVec3, Vec2, Vec3};
use photonfarm::bsdf::conductor::ConductorFresnel;
use photonfarm::bsdf::plastic::Coat;
use photonfarm::geometry::Analytic;
use photonfarm::light::infinite::InfiniteLight;
use photonfarm::light::Light;
use photonfarm::material::{Back, Surface};
use photonfarm::render::{Engine, Method};
use photonfarm::scene::mitsuba::serialized::{write_serialized, SerializedMesh};
use photonfarm::scene::{MitsubaOptions, Scene, SceneError};
use photonfarm::texture::Texture;
use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

/// Writes `files` (name, contents) into a fresh folder and returns it with the folder's guard.
fn folder(files: &[(&str, &[u8])]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in files {
        let path = dir.path().join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, bytes).unwrap();
    }
    let path = dir.path().to_path_buf();
    (dir, path)
}

/// Loads `scene.xml` written with `text` (and `files`) into a fresh folder.
fn import(text: &str, files: &[(&str, &[u8])]) -> Result<Scene, SceneError> {
    let mut all = files.to_vec();
    all.push(("scene.xml", text.as_bytes()));
    let (_guard, dir) = folder(&all);
    Scene::load(&dir.join("scene.xml"))
}

/// Import options with these defines.
fn defines(pairs: &[(&str, &str)]) -> MitsubaOptions {
    MitsubaOptions { defines: pairs.iter().map(|(n, v)| (n.to_string(), v.to_string())).collect(), approximate: false }
}

/// The error of a scene that must not load.
fn error_of(result: Result<Scene, SceneError>) -> SceneError {
    match result {
        Ok(_) => panic!("the scene loaded"),
        Err(e) => e,
    }
}

/// A scene file around `body`: a sensor looking at the origin from +z and an emitting rectangle, so that the
/// shapes of `body` are what a test looks at.
fn scene_with(body: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/></film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><translate z="4"/></transform>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
{body}
</scene>"#
    )
}

const ROOM_XML: &str = r#"<scene version="3.0.0">
    <default name="size" value="32"/>
    <integrator type="path"><integer name="max_depth" value="5"/></integrator>
    <sensor type="perspective">
        <string name="fov_axis" value="x"/>
        <float name="fov" value="50"/>
        <transform name="to_world">
            <lookat origin="0, 1, 3.2" target="0, 1, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm">
            <integer name="width" value="$size"/>
            <integer name="height" value="24"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf>
    <bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.7, 0.1, 0.1"/></bsdf>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><translate y="1" z="-1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><rotate y="1" angle="90"/><translate x="-1" y="1"/></transform>
        <ref id="red"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/><translate y="1.99"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="10, 9, 8"/></emitter>
    </shape>
</scene>"#;

/// The room of `ROOM_XML` in photonfarm's format: the same quads (Mitsuba's rectangles are [−1, 1]² facing +z),
/// one-sided materials, and the field of view along y that a 50° one along x gives a 32 × 24 film.
fn room_toml() -> String {
    let fov_y = 2.0 * ((25f64).to_radians().tan() * 24.0 / 32.0).atan().to_degrees();
    format!(
        r#"
[render]
max_depth = 5
[camera]
position = [0.0, 1.0, 3.2]
look_at = [0.0, 1.0, 0.0]
fov_y_deg = {fov_y}
width = 32
height = 24
[materials.white]
type = "diffuse"
albedo = [0.7, 0.7, 0.7]
back = "black"
[materials.red]
type = "diffuse"
albedo = [0.7, 0.1, 0.1]
back = "black"
[materials.black]
type = "diffuse"
albedo = 0.0
back = "black"
[[objects]]
material = "white"
quad = {{ corner = [-1.0, 0.0, 1.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 0.0, -2.0] }}
[[objects]]
material = "white"
quad = {{ corner = [-1.0, 0.0, -1.0], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }}
[[objects]]
material = "red"
quad = {{ corner = [-1.0, 0.0, 1.0], edge1 = [0.0, 0.0, -2.0], edge2 = [0.0, 2.0, 0.0] }}
[[objects]]
material = "black"
emission = [10.0, 9.0, 8.0]
quad = {{ corner = [-0.3, 1.99, -0.3], edge1 = [0.6, 0.0, 0.0], edge2 = [0.0, 0.0, 0.6] }}
"#
    )
}

#[test]
fn a_mitsuba_room_sees_through_the_camera_of_its_toml_twin_and_renders_its_image() {
    let xml = import(ROOM_XML, &[]).unwrap();
    let toml = Scene::from_toml(&room_toml(), Path::new("room.toml"), Path::new(".")).unwrap();
    assert_eq!((xml.camera.width, xml.camera.height), (32, 24));
    assert_eq!(xml.render.max_depth, 5);
    for (x, y) in [(0, 0), (31, 0), (16, 12), (5, 23), (31, 23)] {
        for jitter in [Vec2::ZERO, Vec2::new(0.5, 0.5), Vec2::new(0.99, 0.01)] {
            let a = xml.camera.generate_ray(x, y, jitter, Vec2::ZERO).ray;
            let b = toml.camera.generate_ray(x, y, jitter, Vec2::ZERO).ray;
            assert!((a.origin - b.origin).length() < 1e-5, "pixel ({x}, {y}) origin");
            assert!(
                (a.direction - b.direction).length() < 1e-5,
                "pixel ({x}, {y}): {} vs {}",
                a.direction,
                b.direction
            );
        }
    }
    assert_same_image_in_blocks(&xml, &toml, 7);
}

/// Asserts that two 32 × 32 scenes render the same image: twelve blocks of 8 × 8 pixels, each block's mean over
/// 200 independent path-traced phases of each scene (seeds `seed` and `seed + 1`) within 4.5 combined SEM.
fn assert_same_image_in_blocks(xml: &Scene, toml: &Scene, seed: u64) {
    let blocks: Vec<Vec<usize>> = (0..12)
        .map(|b| {
            let (bx, by) = (b % 4 * 8, b / 4 * 8);
            (0..64).map(|i| (by + i / 8) * 32 + bx + i % 8).collect()
        })
        .collect();
    let regions: Vec<(&[usize], _)> = blocks.iter().map(|b| (b.as_slice(), None)).collect();
    let mut means = Vec::new();
    for (scene, seed) in [(xml, seed), (toml, seed + 1)] {
        let mut engine = Engine::new(scene, settings(scene, Method::Path, seed));
        means.push(regions_phase_means(&mut engine, 200, &regions));
    }
    for (b, (xml_block, toml_block)) in means[0].iter().zip(&means[1]).enumerate() {
        let (m1, s1) = mean_sem(xml_block);
        let (m2, s2) = mean_sem(toml_block);
        let z = (m1 - m2) / (s1 * s1 + s2 * s2).sqrt().max(1e-12);
        assert!(z.abs() < 4.5, "block {b}: {m1} ± {s1} (XML) vs {m2} ± {s2} (TOML), z = {z}");
    }
}

#[test]
fn each_bsdf_maps_to_its_family_with_mitsubas_defaults_and_sides() {
    let shapes = [
        r#"<bsdf type="diffuse"/>"#,
        r#"<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.2"/></bsdf></bsdf>"#,
        r#"<bsdf type="conductor"><string name="material" value="Au"/></bsdf>"#,
        r#"<bsdf type="roughconductor"><string name="distribution" value="ggx"/></bsdf>"#,
        r#"<bsdf type="dielectric"><string name="int_ior" value="water"/></bsdf>"#,
        r#"<bsdf type="roughdielectric"><float name="alpha" value="0.3"/></bsdf>"#,
        r#"<bsdf type="thindielectric"/>"#,
        r#"<bsdf type="plastic"><float name="int_ior" value="1.9"/></bsdf>"#,
        r#"<bsdf type="roughplastic"><float name="alpha" value="0.2"/></bsdf>"#,
        r#"<bsdf type="principled"><float name="metallic" value="0.5"/></bsdf>"#,
        r#"<bsdf type="mask"><float name="opacity" value="0.3"/><bsdf type="diffuse"/></bsdf>"#,
        r#"<bsdf type="twosided"><bsdf type="diffuse"/><bsdf type="conductor"/></bsdf>"#,
        "",
    ];
    let body: String = shapes
        .iter()
        .enumerate()
        .map(|(i, b)| {
            format!("<shape type=\"sphere\"><point name=\"center\" x=\"{i}\" y=\"0\" z=\"-9\"/>{b}</shape>\n")
        })
        .collect();
    let scene = import(&scene_with(&body), &[]).unwrap();
    // Object 0 is the emitter; the spheres follow in order.
    let m = |i: usize| &scene.materials[scene.objects[i + 1].material as usize];
    let grey = |v: f32| Texture::grey(v);
    assert_eq!(m(0).front, Surface::Diffuse { reflectance: grey(0.5) });
    assert_eq!(m(0).back, Back::Black, "Mitsuba's BSDFs are one-sided");
    assert_eq!(m(1).front, Surface::Diffuse { reflectance: grey(0.2) });
    assert_eq!(m(1).back, Back::Same);
    let Surface::Conductor { fresnel, roughness: None, .. } = &m(2).front else { panic!("{:?}", m(2).front) };
    assert_eq!(*fresnel, ConductorFresnel::named("Au").unwrap());
    let Surface::Conductor { fresnel: ConductorFresnel::Perfect, roughness: Some(r), .. } = &m(3).front else {
        panic!("{:?}", m(3).front)
    };
    assert_eq!((r.distribution, r.alpha_u.clone()), (photonfarm::bsdf::microfacet::Distribution::Ggx, grey(0.1)));
    let Surface::Dielectric { ior, ext_ior, anti_reflection: false } = &m(4).front else { panic!() };
    assert_eq!((ior.d, ext_ior.d), (1.333, 1.000277));
    let Surface::RoughDielectric { ior, roughness, .. } = &m(5).front else { panic!("{:?}", m(5).front) };
    assert_eq!((ior.d, roughness.alpha_v.clone()), (1.5046, grey(0.3)));
    assert!(matches!(m(6).front, Surface::ThinDielectric { .. }));
    let Surface::Plastic { eta, coat: Coat::Smooth, diffuse_reflectance, .. } = &m(7).front else { panic!() };
    assert!((eta - 1.9 / 1.000277).abs() < 1e-6, "{eta}");
    assert_eq!(*diffuse_reflectance, grey(0.5));
    assert!(matches!(m(8).front, Surface::Plastic { coat: Coat::Rough { .. }, .. }));
    let Surface::Principled(p) = &m(9).front else { panic!() };
    assert_eq!(p.metallic, grey(0.5));
    assert_eq!((m(10).opacity.clone(), &m(10).front), (Some(grey(0.3)), &Surface::Diffuse { reflectance: grey(0.5) }));
    assert!(matches!(&m(11).back, Back::Other(s) if matches!(**s, Surface::Conductor { .. })));
    assert_eq!(m(12), m(0), "a shape without a BSDF gets Mitsuba's default diffuse");
}

/// The texel (x, y) (y = 0 the top row) of the environment map the emitter tests write: every texel differs.
fn env_texel(x: usize, y: usize) -> [f32; 3] {
    [1.0 + x as f32, 1.0 + 2.0 * y as f32, 0.5 + 0.25 * (x + 3 * y) as f32]
}

/// An 8 × 4 environment map of `env_texel` as a PFM file (rows from the bottom up, little-endian).
fn env_pfm() -> Vec<u8> {
    let (w, h) = (8, 4);
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    for y in (0..h).rev() {
        for x in 0..w {
            for c in env_texel(x, y) {
                bytes.extend(c.to_le_bytes());
            }
        }
    }
    bytes
}

/// Directions to compare lights along: a spiral over the whole sphere.
fn spiral(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let phi = i as f32 * 2.399_963;
            let r = (1.0 - z * z).sqrt();
            Vec3::new(r * phi.cos(), z, r * phi.sin())
        })
        .collect()
}

/// Asserts that two lights are the same light: the same kind and parameters (to single-precision rounding of
/// transforms), and for lights at infinity the same radiance and sampling density in every direction.
fn assert_same_light(i: usize, a: &Light, b: &Light) {
    let close = |x: Vec3, y: Vec3| (x - y).length() <= 1e-5 * (1.0 + y.length());
    match (a, b) {
        (
            Light::Sphere { object: o1, center: c1, radius: r1, emission: e1 },
            Light::Sphere { object: o2, center: c2, radius: r2, emission: e2 },
        ) => {
            assert_eq!((o1, e1), (o2, e2), "light {i}");
            assert!(close(*c1, *c2) && (r1 - r2).abs() < 1e-6, "light {i}: {a:?} vs {b:?}");
        }
        (
            Light::Disc { object: o1, center: c1, normal: n1, radius: r1, emission: e1 },
            Light::Disc { object: o2, center: c2, normal: n2, radius: r2, emission: e2 },
        ) => {
            assert_eq!((o1, e1), (o2, e2), "light {i}");
            assert!(close(*c1, *c2) && close(*n1, *n2) && (r1 - r2).abs() < 1e-6, "light {i}: {a:?} vs {b:?}");
        }
        (Light::Area { triangle: t1, emission: e1, .. }, Light::Area { triangle: t2, emission: e2, .. }) => {
            assert_eq!((t1, e1), (t2, e2), "light {i}");
        }
        (Light::Infinite(x), Light::Infinite(y)) => {
            assert_eq!(x.is_delta(), y.is_delta(), "light {i}");
            assert!(close(x.radiance_integral(), y.radiance_integral()), "light {i}: {a:?} vs {b:?}");
            for u in [Vec2::new(0.3, 0.7), Vec2::new(0.9, 0.1), Vec2::new(0.5, 0.5)] {
                let (p, q) = (x.sample(u).unwrap(), y.sample(u).unwrap());
                assert!(close(p.direction, q.direction) && p.delta == q.delta, "light {i} at {u}: {p:?} vs {q:?}");
            }
            for d in spiral(500) {
                let (l1, l2) = (x.radiance(d), y.radiance(d));
                assert!((l1 - l2).length() <= 1e-4 * (1.0 + l2.length()), "light {i} along {d}: {l1} vs {l2}");
                let (p1, p2) = (x.pdf(d), y.pdf(d));
                assert!((p1 - p2).abs() <= 1e-4 * (1.0 + p2), "light {i} pdf along {d}: {p1} vs {p2}");
            }
        }
        _ => panic!("light {i}: {a:?} vs {b:?}"),
    }
}

const EMITTERS_XML: &str = r#"<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="4"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0, 1.6, 3" target="0, 0.5, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale value="2"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf>
    </shape>
    <shape type="sphere">
        <transform name="to_world"><scale value="0.25"/><translate x="-0.6" y="0.5" z="0.2"/></transform>
        <emitter type="area"><rgb name="radiance" value="4, 2, 1"/></emitter>
    </shape>
    <shape type="disk">
        <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/><translate x="0.5" y="1.2"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="3, 3, 5"/></emitter>
    </shape>
    <emitter type="envmap">
        <string name="filename" value="env.pfm"/>
        <float name="scale" value="0.05"/>
        <transform name="to_world"><rotate y="1" angle="90"/><translate x="7"/></transform>
    </emitter>
    <emitter type="constant"><rgb name="radiance" value="0.05, 0.1, 0.2"/></emitter>
    <emitter type="directional">
        <vector name="direction" x="0.4" y="-1" z="-0.3"/>
        <rgb name="irradiance" value="2, 1.8, 1.5"/>
    </emitter>
    <emitter type="directional">
        <transform name="to_world"><rotate x="1" angle="70"/></transform>
        <float name="irradiance" value="0.5"/>
    </emitter>
</scene>"#;

/// The scene of `EMITTERS_XML` in photonfarm's format. The disk's normal, Mitsuba's +z turned by 90° about x,
/// points down (−y): photonfarm's disc emits toward −axis, so its axis is +y. A 60° field of view along x on a
/// 32 × 24 film is the vertical one below. The second directional light travels along +z turned by 70° about x.
fn emitters_toml() -> String {
    let fov_y = 2.0 * ((30f64).to_radians().tan() * 24.0 / 32.0).atan().to_degrees();
    let (s, c) = 70f64.to_radians().sin_cos();
    format!(
        r#"
[render]
max_depth = 4
[camera]
position = [0.0, 1.6, 3.0]
look_at = [0.0, 0.5, 0.0]
fov_y_deg = {fov_y}
width = 32
height = 24
[materials.floor]
type = "diffuse"
albedo = 0.6
back = "black"
[materials.default]
type = "diffuse"
albedo = 0.5
back = "black"
[materials.black]
type = "diffuse"
albedo = 0.0
back = "black"
[[objects]]
material = "floor"
quad = {{ corner = [-2.0, 0.0, 2.0], edge1 = [4.0, 0.0, 0.0], edge2 = [0.0, 0.0, -4.0] }}
[[objects]]
material = "default"
emission = [4.0, 2.0, 1.0]
sphere = {{ center = [-0.6, 0.5, 0.2], radius = 0.25 }}
[[objects]]
material = "black"
emission = [3.0, 3.0, 5.0]
annulus = {{ center = [0.5, 1.2, 0.0], axis = [0.0, 1.0, 0.0], inner_radius = 0.0, outer_radius = 0.3 }}
[[lights]]
type = "environment"
filename = "env.pfm"
scale = 0.05
to_world = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
[[lights]]
type = "environment"
radiance = [0.05, 0.1, 0.2]
[[lights]]
type = "sun"
direction = [0.4, -1.0, -0.3]
irradiance = [2.0, 1.8, 1.5]
[[lights]]
type = "sun"
direction = [0.0, {}, {c}]
irradiance = [0.5, 0.5, 0.5]
"#,
        -s
    )
}

#[test]
fn each_emitter_type_maps_to_the_light_of_its_toml_twin_and_renders_its_image() {
    let (pfm, toml) = (env_pfm(), emitters_toml());
    let files: [(&str, &[u8]); 3] =
        [("scene.xml", EMITTERS_XML.as_bytes()), ("twin.toml", toml.as_bytes()), ("env.pfm", &pfm)];
    let (_guard, dir) = folder(&files);
    let xml = Scene::load(&dir.join("scene.xml")).unwrap();
    let twin = Scene::load(&dir.join("twin.toml")).unwrap();
    let (a, b) = (xml.lights.all(), twin.lights.all());
    assert_eq!(a.len(), 6, "{a:?}");
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert_same_light(i, x, y);
    }
    assert_same_image_in_blocks(&xml, &twin, 11);
}

#[test]
fn an_envmap_shows_each_texel_in_mitsubas_direction_turned_by_a_rotating_or_mirroring_to_world() {
    let pfm = env_pfm();
    let (w, h) = (8, 4);
    for transform in [
        "<rotate y=\"1\" angle=\"30\"/><rotate x=\"1\" angle=\"-40\"/>",
        "<scale x=\"-1\"/><rotate z=\"1\" angle=\"25\"/>",
    ] {
        let body = format!(
            "<emitter type=\"envmap\"><string name=\"filename\" value=\"env.pfm\"/><float name=\"scale\" value=\"2\"/>\
             <transform name=\"to_world\">{transform}<translate y=\"3\"/></transform></emitter>"
        );
        let scene = import(&scene_with(&body), &[("env.pfm", &pfm)]).unwrap();
        let to_world = match scene.lights.all().iter().find_map(|l| match l {
            Light::Infinite(InfiniteLight::Map(m)) => Some(m.clone()),
            _ => None,
        }) {
            Some(m) => m,
            None => panic!("no map among {:?}", scene.lights.all()),
        };
        // The same transform composed here: the map's frame to the world.
        let m = match transform.contains("scale") {
            false => DMat3::from_rotation_x((-40f64).to_radians()) * DMat3::from_rotation_y(30f64.to_radians()),
            true => DMat3::from_rotation_z(25f64.to_radians()) * DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0)),
        };
        // Mitsuba's envmap: texel (x, y) is the radiance from u = (x + ½)/W, v = y/(H − 1), φ = 2πu, θ = πv,
        // ω = (sin φ sin θ, cos θ, −cos φ sin θ) in the map's frame. The poles (top and bottom rows) are one
        // direction each, so the rows between them are checked.
        for y in 1..h - 1 {
            for x in 0..w {
                let (phi, theta) = (TAU * (x as f64 + 0.5) / w as f64, PI * y as f64 / (h - 1) as f64);
                let local = DVec3::new(phi.sin() * theta.sin(), theta.cos(), -phi.cos() * theta.sin());
                let d = (m * local).as_vec3();
                let got = to_world.radiance(d);
                let want = Vec3::from(env_texel(x, y)) * 2.0;
                assert!((got - want).length() < 1e-3 * want.length(), "{transform}: texel ({x}, {y}) {got} vs {want}");
            }
        }
    }
}

#[test]
fn instances_of_a_shapegroup_are_its_shapes_written_out_with_the_instance_transform_after_their_own() {
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
    let triangle = r#"<shape type="obj"><string name="filename" value="tri.obj"/>
        <transform name="to_world"><rotate y="1" angle="20"/><translate z="-1"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.3"/></bsdf></shape>"#;
    let ball = r#"<shape type="sphere"><point name="center" x="0.5" y="0" z="0"/><float name="radius" value="0.2"/>
        <transform name="to_world"><scale value="2"/></transform></shape>"#;
    let instances =
        [r#"<translate x="3" y="-1"/><rotate z="1" angle="35"/>"#, r#"<scale x="-1"/><translate x="-2" z="-4"/>"#];
    let grouped = format!(
        r#"<shape type="shapegroup" id="pair">{triangle}{ball}</shape>
        <shape type="shapegroup" id="unused"><shape type="cube"/></shape>
        <shape type="instance"><ref id="pair"/><transform name="to_world">{}</transform></shape>
        <shape type="instance"><ref id="pair"/><transform name="to_world">{}</transform></shape>"#,
        instances[0], instances[1]
    );
    // Written out: each shape's own transform elements, then the instance's (later elements apply after).
    let written_out: String = instances
        .iter()
        .map(|t| {
            let own = |shape: &str| shape.replace("</transform>", &format!("{t}</transform>"));
            own(triangle) + &own(ball)
        })
        .collect();
    let files: [(&str, &[u8]); 1] = [("tri.obj", obj)];
    let a = import(&scene_with(&grouped), &files).unwrap();
    let b = import(&scene_with(&written_out), &files).unwrap();
    // The emitting rectangle's two triangles and one per instanced triangle; the unused group adds nothing.
    assert_eq!(a.geometry.triangle_count(), 4);
    assert_eq!(b.geometry.triangle_count(), 4);
    let close = |x: Vec3, y: Vec3| (x - y).length() < 1e-5;
    for i in 0..4 {
        let (s, t) = (a.geometry.triangle(i), b.geometry.triangle(i));
        let normals = match (s.n, t.n) {
            (Some(m), Some(n)) => (0..3).all(|k| close(m[k], n[k])),
            (m, n) => m.is_none() && n.is_none(),
        };
        assert!((0..3).all(|k| close(s.v[k], t.v[k])) && normals, "triangle {i}: {s:?} vs {t:?}");
    }
    let (sa, sb) = (a.geometry.analytic_surfaces(), b.geometry.analytic_surfaces());
    assert_eq!(sa.len(), 2);
    for ((ia, x), (ib, y)) in sa.iter().zip(sb) {
        let (Analytic::Sphere(x), Analytic::Sphere(y)) = (x, y) else { panic!("{x:?} vs {y:?}") };
        assert!(ia == ib && close(x.center, y.center) && (x.radius - y.radius).abs() < 1e-6, "{x:?} vs {y:?}");
    }
    assert_eq!(a.objects.len(), b.objects.len());
    for (x, y) in a.objects.iter().zip(&b.objects) {
        assert_eq!(a.materials[x.material as usize], b.materials[y.material as usize]);
    }
    // What Mitsuba refuses in a group is refused here at its line.
    refused(
        "<shape type=\"shapegroup\" id=\"g\"><shape type=\"sphere\">\n<emitter type=\"area\"/></shape></shape>",
        "type=\"area\"/>",
        "area",
        "does not instance emitters",
    );
    refused(
        "<shape type=\"shapegroup\" id=\"g\">\n<shape type=\"shapegroup\" id=\"h\"/></shape>",
        "id=\"h\"",
        "shapegroup",
        "not allowed",
    );
    refused("<shape type=\"instance\">\n<shape type=\"sphere\"/></shape>", "instance", "instance", "one shapegroup");
}

#[test]
fn approximate_imports_what_has_no_counterpart_as_the_nearest_thing_and_notes_each_substitution_at_its_line() {
    let body = r#"<integrator type="bdpt"><integer name="max_depth" value="7"/><boolean name="lightImage" value="true"/></integrator>
<medium type="homogeneous" id="fog"/>
<shape type="sphere"><bsdf type="hair"/></shape>
<shape type="sphere"><point name="center" x="3" y="0" z="0"/><bsdf type="normalmap"><texture type="bitmap" name="normalmap"><string name="filename" value="n.png"/></texture><bsdf type="diffuse"><rgb name="reflectance" value="0.2"/></bsdf></bsdf></shape>
<shape type="sphere"><point name="center" x="-3" y="0" z="0"/><ref name="interior" id="fog"/></shape>"#;
    let text = scene_with(body);
    let line_of = |needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;
    let (_guard, dir) = folder(&[("scene.xml", text.as_bytes())]);
    let path = dir.join("scene.xml");
    // Refused without the option, at the first thing that has no counterpart.
    let e = error_of(Scene::load_with_options(&path, &MitsubaOptions::default()));
    assert_eq!(e.line, Some(line_of("bdpt")), "{e}");
    let approximate = MitsubaOptions { approximate: true, ..MitsubaOptions::default() };
    let scene = Scene::load_with_options(&path, &approximate).unwrap();
    assert_eq!(scene.render.max_depth, 7, "the other integrator's depth carries over");
    // Object 0 is the emitting rectangle.
    let m = |i: usize| &scene.materials[scene.objects[i].material as usize];
    assert_eq!(m(1).front, Surface::Diffuse { reflectance: Texture::grey(0.5) }, "hair as Mitsuba's default BSDF");
    assert_eq!(m(2).front, Surface::Diffuse { reflectance: Texture::grey(0.2) }, "the BSDF inside the normal map");
    assert_eq!(scene.objects.len(), 4, "the shape inside a medium stays, in vacuum");
    let approximated: Vec<&String> = scene.notes.iter().filter(|n| n.starts_with("approximated: ")).collect();
    for (needle, element) in [
        ("bdpt", "<integrator type=\"bdpt\">"),
        ("homogeneous", "<medium type=\"homogeneous\">"),
        ("hair", "<bsdf type=\"hair\">"),
        ("normalmap", "<bsdf type=\"normalmap\">"),
        ("interior", "<medium type=\"homogeneous\">"),
    ] {
        let at = format!("scene.xml:{}:", line_of(needle));
        assert!(
            approximated.iter().any(|n| n.contains(&at) && n.contains(element) && n.contains("; rendered ")),
            "no note for {element} at {at}: {approximated:#?}"
        );
    }
    assert_eq!(approximated.len(), 5, "{approximated:#?}");
    // The option is part of the scene: a worker given it rebuilds the same scene, and without it none.
    let files = BTreeMap::new();
    let there = Scene::from_job_files(&text, Path::new("scene.xml"), &approximate, &files).unwrap();
    assert_eq!(there.hash, scene.hash);
    assert!(Scene::from_job_files(&text, Path::new("scene.xml"), &MitsubaOptions::default(), &files).is_err());
    let toml = dir.join("room.toml");
    std::fs::write(&toml, room_toml()).unwrap();
    let e = error_of(Scene::load_with_options(&toml, &approximate));
    assert!(e.message.contains("--approximate"), "{e}");
}

/// A unit quad in the plane z = 0 with texture coordinates, as PLY in `format`.
fn ply_quad(format: &str) -> Vec<u8> {
    let header = format!(
        "ply\nformat {format} 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\nproperty float u\nproperty float v\n\
         element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    );
    let vertices = [
        [0.0f32, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0],
        [1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.25],
        [0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.25],
    ];
    let mut bytes = header.into_bytes();
    match format {
        "ascii" => {
            for v in vertices {
                bytes.extend(v.map(|x| x.to_string()).join(" ").bytes());
                bytes.push(b'\n');
            }
            bytes.extend(b"4 0 1 2 3\n");
        }
        _ => {
            let big = format == "binary_big_endian";
            for x in vertices.iter().flatten() {
                bytes.extend(if big { x.to_be_bytes() } else { x.to_le_bytes() });
            }
            bytes.push(4);
            for i in [0i32, 1, 2, 3] {
                bytes.extend(if big { i.to_be_bytes() } else { i.to_le_bytes() });
            }
        }
    }
    bytes
}

#[test]
fn ply_in_every_encoding_and_serialized_meshes_load_placed_with_their_texture_coordinates() {
    let quad = SerializedMesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
        normals: None,
        uvs: Some(vec![[0.0, 0.0], [1.0, 0.0], [1.0, 0.25], [0.0, 0.25]]),
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        ..SerializedMesh::default()
    };
    let other = SerializedMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        triangles: vec![[0, 1, 2]],
        ..SerializedMesh::default()
    };
    let serialized = write_serialized(&[other, quad], false).unwrap();
    let textured = r#"<bsdf type="diffuse"><texture name="reflectance" type="checkerboard"/></bsdf>"#;
    let shape = |kind: &str, file: &str, x: f32, extra: &str| {
        format!(
            "<shape type=\"{kind}\"><string name=\"filename\" value=\"{file}\"/>{extra}{textured}\
             <transform name=\"to_world\"><translate x=\"{x}\" z=\"-2\"/></transform></shape>\n"
        )
    };
    let body = [
        shape("ply", "meshes/ascii.ply", 10.0, ""),
        shape("ply", "meshes/little.ply", 20.0, ""),
        shape("ply", "meshes/big.ply", 30.0, ""),
        shape("serialized", "meshes/two.serialized", 40.0, r#"<integer name="shape_index" value="1"/>"#),
    ]
    .concat();
    let files: [(&str, &[u8]); 4] = [
        ("meshes/ascii.ply", &ply_quad("ascii")),
        ("meshes/little.ply", &ply_quad("binary_little_endian")),
        ("meshes/big.ply", &ply_quad("binary_big_endian")),
        ("meshes/two.serialized", &serialized),
    ];
    let scene = import(&scene_with(&body), &files).unwrap();
    // The emitting rectangle's two triangles, then two per quad.
    assert_eq!(scene.geometry.triangle_count(), 2 + 4 * 2);
    for (k, x) in [10.0f32, 20.0, 30.0, 40.0].into_iter().enumerate() {
        let first = 2 + 2 * k as u32;
        let t = scene.geometry.triangle(first);
        assert_eq!(t.v[0], Vec3::new(x, 0.0, -2.0), "mesh {k} placed by to_world");
        assert_eq!(t.v[2], Vec3::new(x + 1.0, 1.0, -2.0));
        // Mitsuba's v = 0.25 is photonfarm's 0.75 (its v runs downward).
        let uv = *scene.triangle_uvs.get(first).unwrap();
        assert_eq!(uv, [Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.75)], "mesh {k}");
    }
    assert_eq!(scene.mesh_files.len(), 4);
}

#[test]
fn a_mirrored_mesh_keeps_the_side_its_vertex_normals_face_and_flip_normals_turns_it() {
    let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n";
    let shape = |transform: &str, flip: bool| {
        format!(
            "<shape type=\"obj\"><string name=\"filename\" value=\"t.obj\"/><boolean name=\"flip_normals\" \
             value=\"{flip}\"/><transform name=\"to_world\">{transform}</transform></shape>\n"
        )
    };
    let body = [
        shape("<scale x=\"-1\"/>", false),
        shape("", false),
        shape("<scale x=\"-1\"/>", true),
        shape("<matrix value=\"1 0 0 0  0 1 0 0  0 0 -1 0  0 0 0 1\"/>", false),
    ]
    .concat();
    let scene = import(&scene_with(&body), &[("t.obj", obj)]).unwrap();
    let facing = |k: u32| {
        let t = scene.geometry.triangle(2 + k);
        let geometric = (t.v[1] - t.v[0]).cross(t.v[2] - t.v[0]).normalize();
        let shading = t.n.expect("vertex normals")[0];
        assert!(geometric.dot(shading) > 0.99, "triangle {k}: winding and normals disagree");
        shading
    };
    assert_eq!(facing(0), Vec3::Z, "mirrored along x, the normal still faces +z");
    assert_eq!(facing(1), Vec3::Z);
    assert_eq!(facing(2), -Vec3::Z, "flip_normals turns it");
    assert_eq!(facing(3), -Vec3::Z, "mirrored along z, the normal follows the mirror");
}

#[test]
fn a_worker_rebuilds_the_same_scene_from_the_job_files_includes_and_search_paths_among_them() {
    let main = r#"<scene version="3.0.0">
    <path value="../common"/>
    <bsdf type="diffuse" id="wood"><texture name="reflectance" type="bitmap"><string name="filename" value="tex.png"/></texture></bsdf>
    <include filename="parts/room.xml"/>
</scene>"#;
    let room =
        scene_with(r#"<shape type="obj"><string name="filename" value="meshes/quad.obj"/><ref id="wood"/></shape>"#);
    let png = {
        let mut bytes = Vec::new();
        let mut encoder = png::Encoder::new(&mut bytes, 2, 2);
        encoder.set_color(png::ColorType::Rgb);
        encoder.write_header().unwrap().write_image_data(&[200; 12]).unwrap();
        bytes
    };
    let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nf 1/1 2/2 3/3\n";
    let (_guard, dir) = folder(&[
        ("scenes/main.xml", main.as_bytes()),
        ("scenes/parts/room.xml", room.as_bytes()),
        ("common/tex.png", &png),
        ("common/meshes/quad.obj", obj),
    ]);
    let path = dir.join("scenes/main.xml");
    let here = Scene::load(&path).unwrap();
    let keys: Vec<&str> = here.mesh_files.iter().map(|(k, _)| k.as_str()).collect();
    // A job sends the files the description names; the include is part of the description, not one of them.
    assert_eq!(keys, ["../common/tex.png", "../common/meshes/quad.obj"]);
    let mut sent: BTreeMap<String, Vec<u8>> =
        here.mesh_files.iter().map(|(k, _)| (k.clone(), std::fs::read(dir.join("scenes").join(k)).unwrap())).collect();
    // Read again from memory, the include must be there too.
    sent.insert("parts/room.xml".into(), room.as_bytes().to_vec());
    let there = Scene::from_job_files(main, Path::new("main.xml"), &MitsubaOptions::default(), &sent).unwrap();
    assert_eq!(there.mesh_files, here.mesh_files);
    assert_eq!(there.hash, here.hash);
    assert_eq!(there.geometry.triangle_count(), here.geometry.triangle_count());
    assert_eq!(there.materials, here.materials);
    let mut missing = sent.clone();
    missing.remove("../common/tex.png");
    let e = error_of(Scene::from_job_files(main, Path::new("main.xml"), &MitsubaOptions::default(), &missing));
    assert!(e.to_string().contains("was not sent with the job"), "{e}");
}

#[test]
fn defines_override_defaults_and_change_the_hash() {
    let text = ROOM_XML;
    let (_guard, dir) = folder(&[("room.xml", text.as_bytes())]);
    let path = dir.join("room.xml");
    let plain = Scene::load_with_options(&path, &MitsubaOptions::default()).unwrap();
    let wide = Scene::load_with_options(&path, &defines(&[("size", "48")])).unwrap();
    assert_eq!((plain.camera.width, wide.camera.width), (32, 48));
    assert_ne!(plain.hash, wide.hash);
    let e = error_of(Scene::load_with_options(&path, &defines(&[("sise", "48")])));
    assert!(e.message.contains("sise"), "{e}");
}

/// The error of importing `body` in `scene_with`, which must name the line of `needle` in the file and the
/// element `element`, with `words` in its message.
fn refused(body: &str, needle: &str, element: &str, words: &str) {
    let text = scene_with(body);
    let line = text.lines().position(|l| l.contains(needle)).expect("needle in the scene") + 1;
    let e = error_of(import(&text, &[]));
    assert_eq!(e.line, Some(line), "{e}");
    assert!(e.field.as_deref().is_some_and(|f| f.contains(element)), "{e}");
    assert!(e.message.contains(words), "{e}");
}

#[test]
fn unsupported_plugins_and_parameters_are_refused_at_their_line_and_element() {
    refused("<shape type=\"sphere\">\n<bsdf type=\"hair\"/></shape>", "hair", "bsdf type=\"hair\"", "`hair`");
    refused(
        "<shape type=\"sphere\"><bsdf type=\"diffuse\">\n<float name=\"roughness\" value=\"1\"/></bsdf></shape>",
        "roughness",
        "roughness",
        "not supported",
    );
    refused("<emitter type=\"sunsky\">\n</emitter>", "sunsky", "sunsky", "no counterpart");
    refused(
        "<emitter type=\"envmap\"><string name=\"filename\" value=\"sky.exr\"/>\n\
         <transform name=\"to_world\"><scale value=\"2\"/></transform></emitter>",
        "sky.exr",
        "envmap",
        "rotation",
    );
    refused(
        "<emitter type=\"directional\"><vector name=\"direction\" x=\"1\" y=\"0\" z=\"0\"/>\n\
         <transform name=\"to_world\"><rotate x=\"1\" angle=\"20\"/></transform></emitter>",
        "directional",
        "directional",
        "not both",
    );
    refused("<shape type=\"hair\"/>", "hair", "shape type=\"hair\"", "not supported");
    refused(
        "<shape type=\"obj\"><string name=\"filename\" value=\"missing.obj\"/></shape>",
        "missing",
        "obj",
        "missing.obj",
    );
    refused("<integrator type=\"bdpt\"/>", "bdpt", "bdpt", "--define integrator=path");
    refused("<medium type=\"homogeneous\"/>", "homogeneous", "medium", "not supported");
    refused(
        "<shape type=\"cube\"><bsdf type=\"diffuse\"><texture type=\"checkerboard\" name=\"reflectance\"/></bsdf></shape>",
        "cube",
        "cube",
        "texture coordinates",
    );
    refused(
        "<shape type=\"sphere\"><bsdf type=\"bumpmap\"><bsdf type=\"diffuse\"/></bsdf></shape>",
        "bumpmap",
        "bumpmap",
        "not supported",
    );
    refused(
        "<shape type=\"sphere\"><transform name=\"to_world\"><scale x=\"2\"/></transform></shape>",
        "sphere",
        "sphere",
        "unevenly",
    );
    refused(
        "<shape type=\"sphere\"><bsdf type=\"dielectric\">\n<string name=\"int_ior\" value=\"glas\"/></bsdf></shape>",
        "glas",
        "int_ior",
        "named indices",
    );
    refused(
        "<shape type=\"rectangle\"><bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"1.5\"/></bsdf></shape>",
        "1.5",
        "reflectance",
        "above 1",
    );
}

#[test]
fn a_mirroring_camera_and_malformed_xml_are_refused_with_their_line() {
    let mirrored = scene_with("").replace(
        r#"<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#,
        r#"<scale x="-1"/><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>"#,
    );
    let e = error_of(import(&mirrored, &[]));
    assert_eq!(e.line, Some(2), "{e}");
    assert!(e.message.contains("mirrors the image"), "{e}");
    let e = error_of(import("<scene version=\"3.0.0\">\n<shape type=\"sphere\">\n</scene>", &[]));
    assert!(e.line.is_some() && e.message.contains("XML"), "{e}");
    let dark = scene_with("").replace(r#"<rgb name="radiance" value="1"/>"#, r#"<rgb name="radiance" value="0"/>"#);
    let e = error_of(import(&dark, &[]));
    assert!(e.message.contains("no light"), "{e}");
}
