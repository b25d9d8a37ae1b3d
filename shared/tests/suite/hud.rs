//! The head-up display scene and what it relies on: the virtual image of the slide lands at the designed
//! distance and reads upright, the combiner splits energy into exactly its reflectance and transmittance, and
//! textures decode from sRGB and emit what they show.

use crate::common::{mean_sem, region_phase_means, regions_phase_means, scene, settings, shipped};
use glam::{Vec2, Vec3};
use photonfarm::bsdf::{reflect, Transport};
use photonfarm::camera::Lens;
use photonfarm::color::{luminance, Rgb};
use photonfarm::geometry::{ray::offset_origin, Ray, SurfaceHit};
use photonfarm::integrator::Layer;
use photonfarm::material::{Material, Surface};
use photonfarm::render::{Engine, Method};
use photonfarm::sampling::{Pass, Sampler};
use photonfarm::scene::Scene;
use photonfarm::texture::{barycentric, interpolate_uv, Bitmap};
use std::path::{Path, PathBuf};

/// The distance from the eye at which the scene file says the virtual image lies.
const DESIGNED_DISTANCE: f32 = 2.5;

fn object_name<'s>(scene: &'s Scene, hit: &SurfaceHit) -> &'s str {
    &scene.objects[hit.object as usize].name
}

/// Follows a ray by specular reflection only (mirror and combiner reflect, nothing transmits) until it meets
/// the object named `target`; returns every vertex and the final ray's direction, or None if it goes elsewhere.
fn reflect_to(scene: &Scene, mut ray: Ray, target: &str) -> Option<(Vec<SurfaceHit>, Vec3)> {
    let mut hits = Vec::new();
    for _ in 0..4 {
        let hit = scene.geometry.intersect(&ray)?;
        hits.push(hit);
        if object_name(scene, &hit) == target {
            return Some((hits, ray.direction));
        }
        match scene.materials[scene.objects[hit.object as usize].material as usize].front {
            Surface::Conductor { roughness: None, .. } | Surface::Coating { .. } => {
                let wi = reflect(-ray.direction, hit.ns);
                ray = Ray::new(offset_origin(hit.p, hit.ng, wi), wi);
            }
            _ => return None,
        }
    }
    None
}

/// Traces a ray from a screen point through the mirror and the combiner; returns the last ray (leaving the
/// combiner toward the eye).
fn screen_to_eye(scene: &Scene, from: Vec3, toward: Vec3) -> Ray {
    let d = (toward - from).normalize();
    let mut ray = Ray::new(from + d * 1e-5, d);
    for expected in ["mirror", "combiner"] {
        let hit = scene.geometry.intersect(&ray).expect("the ray from the screen hits the HUD optics");
        assert_eq!(object_name(scene, &hit), expected);
        let wi = reflect(-ray.direction, hit.ns);
        ray = Ray::new(offset_origin(hit.p, hit.ng, wi), wi);
    }
    ray
}

/// The point on line (a, da) closest to line (b, db), in f64: for nearly parallel lines aa·bb − ab² is tiny
/// and f32 would cancel it away.
fn closest_on_first(a: Vec3, da: Vec3, b: Vec3, db: Vec3) -> Vec3 {
    let (a, da, b, db) = (a.as_dvec3(), da.as_dvec3(), b.as_dvec3(), db.as_dvec3());
    let w = a - b;
    let (aa, ab, bb, aw, bw) = (da.dot(da), da.dot(db), db.dot(db), da.dot(w), db.dot(w));
    let s = (ab * bw - bb * aw) / (aa * bb - ab * ab);
    (a + da * s).as_vec3()
}

/// Distances from the eye of the virtual image of the screen point seen along `view`: where pairs of rays
/// leaving that point 1 mm apart at the mirror, about the bundle a 2 mm pupil takes in (one pair across the
/// plane of the fold, one in it), appear to diverge from once the mirror and the combiner have reflected
/// them. Returns (sagittal, tangential).
fn virtual_image_distances(scene: &Scene, eye: Vec3, view: Vec3) -> (f32, f32) {
    let (hits, _) = reflect_to(scene, Ray::new(eye, view), "screen")
        .unwrap_or_else(|| panic!("the view ray {view} from {eye} does not reach the screen"));
    let (mirror, screen) = (hits[1].p, hits[2].p);
    let along = (mirror - screen).normalize();
    let across = along.cross(Vec3::Y).normalize(); // ≈ x: perpendicular to the fold plane
    let within = along.cross(across).normalize();
    let mut out = [0.0; 2];
    for (k, e) in [across, within].into_iter().enumerate() {
        let delta = 0.5e-3;
        let a = screen_to_eye(scene, screen, mirror + e * delta);
        let b = screen_to_eye(scene, screen, mirror - e * delta);
        // The rays reach the eye within a pupil: the bundle is the one the eye would see.
        for r in [a, b] {
            let to_eye = eye - r.origin;
            let miss = (to_eye - r.direction * to_eye.dot(r.direction)).length();
            assert!(miss < 2e-3, "a ray from the screen passes the eye {miss} m off");
        }
        // Backward extensions (toward the world) of the two rays meet at the virtual point.
        let v = closest_on_first(a.origin, -a.direction, b.origin, -b.direction);
        out[k] = (v - eye).length();
    }
    (out[0], out[1])
}

#[test]
fn the_slide_virtual_image_lies_at_the_designed_distance_within_five_percent() {
    let scene = shipped("hud.toml");
    let eye = scene.camera.position;
    let Lens::Thin { focus_distance, radius } = scene.camera.lens else { panic!("the eye is a thin lens") };
    assert!((0.002..=0.003).contains(&radius), "pupil radius {radius} m");
    assert_eq!(focus_distance, DESIGNED_DISTANCE, "the eye focuses at the designed virtual image");
    // Near the HUD axis and four field points toward the corners of the 6° × 3° image. The axis itself runs
    // exactly along the diagonals of the combiner's and the screen's quads, where the ray-triangle test is not
    // watertight: 0.05° off it, no ray of the test does.
    let field = [(0.05f32, 0.05f32), (2.0, 1.0), (-2.0, 1.0), (2.0, -1.0), (-2.0, -1.0)];
    let mut all = Vec::new();
    for (h, v) in field {
        let view = Vec3::new(-h.to_radians().tan(), v.to_radians().tan(), 1.0).normalize();
        let (sagittal, tangential) = virtual_image_distances(&scene, eye, view);
        eprintln!(
            "field ({h:+}°, {v:+}°): virtual image at {sagittal:.3} m (sagittal), {tangential:.3} m (tangential)"
        );
        for d in [sagittal, tangential] {
            assert!(
                (d / DESIGNED_DISTANCE - 1.0).abs() < 0.05,
                "field ({h}°, {v}°): virtual image at {d} m, designed {DESIGNED_DISTANCE} m"
            );
        }
        all.push(0.5 * (sagittal + tangential));
    }
    let mean = all.iter().sum::<f32>() / all.len() as f32;
    assert!((mean / DESIGNED_DISTANCE - 1.0).abs() < 0.02, "mean virtual image distance {mean} m");
}

/// Texture coordinates on the screen seen along a view ray from the pupil's centre.
fn screen_uv(scene: &Scene, ray: Ray) -> Option<Vec2> {
    let (hits, _) = reflect_to(scene, ray, "screen")?;
    let hit = hits.last()?;
    let uv = *scene.triangle_uvs.get(hit.triangle)?;
    Some(interpolate_uv(&uv, barycentric(&scene.geometry.triangle(hit.triangle).v, hit.p)))
}

#[test]
fn the_slide_reads_upright_and_unmirrored_and_fills_its_six_by_three_degree_field() {
    let scene = shipped("hud.toml");
    let cam = &scene.camera;
    let centre = Vec2::splat(0.5);
    let ray = |x: u32, y: u32| cam.generate_ray(x, y, Vec2::splat(0.5), centre).ray;
    let pixels: Vec<(u32, u32)> = (0..cam.height)
        .flat_map(|y| (0..cam.width).map(move |x| (x, y)))
        .filter(|&(x, y)| screen_uv(&scene, ray(x, y)).is_some())
        .collect();
    assert!(!pixels.is_empty(), "no pixel sees the slide");
    let (x0, x1) = (pixels.iter().map(|p| p.0).min().unwrap(), pixels.iter().map(|p| p.0).max().unwrap());
    let (y0, y1) = (pixels.iter().map(|p| p.1).min().unwrap(), pixels.iter().map(|p| p.1).max().unwrap());
    let (cx, cy) = ((x0 + x1) / 2, (y0 + y1) / 2);
    let uv = screen_uv(&scene, ray(cx, cy)).unwrap();
    let right = screen_uv(&scene, ray(cx + 5, cy)).unwrap();
    let below = screen_uv(&scene, ray(cx, cy + 5)).unwrap();
    assert!(right.x > uv.x + 0.02 && (right.y - uv.y).abs() < 0.01, "u does not grow to the right: {uv} → {right}");
    assert!(below.y < uv.y - 0.04 && (below.x - uv.x).abs() < 0.01, "v does not grow upward: {uv} → {below}");
    // The field the slide covers, in degrees (one pixel subtends pixel_angle radians).
    let deg = cam.pixel_angle().to_degrees();
    let (w, h) = ((x1 - x0 + 1) as f32 * deg, (y1 - y0 + 1) as f32 * deg);
    eprintln!("the slide covers {w:.2}° × {h:.2}° of the view, pixels x {x0}..{x1}, y {y0}..{y1}");
    assert!((w - 6.0).abs() < 0.3 && (h - 3.0).abs() < 0.3, "{w}° × {h}°");
}

fn coating_of(scene: &Scene) -> (Rgb, Rgb) {
    scene
        .materials
        .iter()
        .find_map(|m| match m.front {
            Surface::Coating { reflectance, transmittance } => Some((reflectance, transmittance)),
            _ => None,
        })
        .expect("the HUD scene has a coating combiner")
}

#[test]
fn the_combiner_reflects_r_and_transmits_t_of_the_incident_energy_in_both_transport_modes() {
    let (r, t) = coating_of(&shipped("hud.toml"));
    let m = Material::two_sided(Surface::Coating { reflectance: r, transmittance: t });
    let n = Vec3::new(0.0, -1.0, -1.0).normalize();
    let hit = SurfaceHit { t: 1.0, p: Vec3::ZERO, ng: n, ns: n, object: 0, triangle: 0 };
    let wo = Vec3::new(0.1, -0.2, -1.0).normalize();
    for mode in [Transport::Radiance, Transport::Importance] {
        let mut sampler = Sampler::new(5, Pass::Path, 1, 0);
        let count = 200_000;
        let (mut reflected, mut transmitted) = (Vec::with_capacity(count), Vec::with_capacity(count));
        for _ in 0..count {
            let bsdf = m.bsdf(&hit, Vec2::ZERO, wo);
            let s = bsdf.sample(wo, sampler.next_2d(), mode).expect("the coating never absorbs a whole sample");
            assert!(s.is_delta());
            let y = luminance(s.weight) as f64;
            if s.wi.dot(wo) > -0.999 {
                assert!((s.wi - reflect(wo, n)).length() < 1e-5, "a reflection goes the mirror way");
                reflected.push(y);
                transmitted.push(0.0);
            } else {
                reflected.push(0.0);
                transmitted.push(y);
            }
        }
        let (mr, sr) = mean_sem(&reflected);
        let (mt, st) = mean_sem(&transmitted);
        let (er, et) = (luminance(r) as f64, luminance(t) as f64);
        eprintln!("{mode:?}: reflected {mr:.4} ± {sr:.4} (r = {er}), transmitted {mt:.4} ± {st:.4} (t = {et})");
        assert!((mr - er).abs() < 4.0 * sr, "reflected {mr} ± {sr}, expected {er}");
        assert!((mt - et).abs() < 4.0 * st, "transmitted {mt} ± {st}, expected {et}");
        // Each sample carries r or t divided by the probability of its branch: together they return r + t of
        // the incident energy, the rest (1 − r − t) being absorbed.
        assert!(((mr + mt) - (er + et)).abs() < 4.0 * (sr * sr + st * st).sqrt());
    }
}

/// A lit diffuse wall seen by a pinhole camera, optionally through a combiner between them. The lamp lies on
/// the wall's side of the combiner, out of view, so the wall's direct light is the same either way; the
/// combiner only adds light it reflects onto the wall (caustic and indirect layers).
fn wall_scene(r: Rgb, t: Rgb, with_combiner: bool) -> String {
    let mut s = format!(
        "[camera]\nposition = [0.0, 0.0, -1.0]\nlook_at = [0.0, 0.0, 1.0]\nfov_y_deg = 30\nwidth = 24\nheight = 24\n\
         [materials.wall]\ntype = \"diffuse\"\nalbedo = [0.6, 0.6, 0.6]\n\
         [materials.black]\ntype = \"diffuse\"\nalbedo = [0.0, 0.0, 0.0]\n\
         [materials.combiner]\ntype = \"coating\"\nreflectance = [{}, {}, {}]\ntransmittance = [{}, {}, {}]\n\
         [[objects]]\nmaterial = \"wall\"\nquad = {{ corner = [-2.0, -2.0, 1.0], edge1 = [4.0, 0.0, 0.0], edge2 = [0.0, 4.0, 0.0] }}\n\
         [[objects]]\nmaterial = \"black\"\nemission = [5.0, 5.0, 5.0]\n\
         quad = {{ corner = [-0.5, 1.2, 0.0], edge1 = [1.0, 0.0, 0.0], edge2 = [0.0, 0.0, 0.5] }}\n",
        r.x, r.y, r.z, t.x, t.y, t.z
    );
    if with_combiner {
        // Tilted 30° with its top toward the camera, like a windshield; the camera's reflection in it looks
        // into the empty, black space below.
        s += "[[objects]]\nname = \"combiner\"\nmaterial = \"combiner\"\n\
              quad = { corner = [-1.0, -1.0, 0.855], edge1 = [2.0, 0.0, 0.0], edge2 = [0.0, 2.0, -1.1547] }\n";
    }
    s
}

#[test]
fn the_world_seen_through_the_combiner_is_its_transmittance_times_the_world_without_it() {
    let (r, t) = coating_of(&shipped("hud.toml"));
    let centre = |x: u32, y: u32| (6..18).contains(&x) && (6..18).contains(&y);
    let mut means = Vec::new();
    for with in [false, true] {
        let sc = scene(&wall_scene(r, t, with));
        let mut engine = Engine::new(&sc, settings(&sc, Method::Pbpm, 21));
        means.push(mean_sem(&region_phase_means(&mut engine, 300, Some(Layer::Direct), &centre)));
    }
    let ((open, s_open), (through, s_through)) = (means[0], means[1]);
    let expect = luminance(t) as f64 * open;
    let sem = (s_through * s_through + (luminance(t) as f64 * s_open).powi(2)).sqrt();
    eprintln!(
        "wall {open:.4} ± {s_open:.4} without, {through:.4} ± {s_through:.4} through the combiner (t × = {expect:.4})"
    );
    assert!((through - expect).abs() < 4.0 * sem, "through the combiner {through} ± {sem}, expected {expect}");
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("hud-tests").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes an 8-bit PNG of the given colour type.
fn write_png(path: &Path, width: u32, height: u32, color: png::ColorType, data: &[u8]) {
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(color);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header().unwrap().write_image_data(data).unwrap();
}

/// The sRGB decoding curve written out independently of the renderer's.
fn srgb(v: u8) -> f32 {
    let c = v as f64 / 255.0;
    (if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }) as f32
}

#[test]
fn an_srgb_png_decodes_to_the_right_linear_values_in_every_colour_type() {
    let dir = scratch("decode");
    // Known points of the curve: 0 → 0, 10 → 10/255/12.92 (the linear toe), 128 → 0.21586, 188 → 0.50289,
    // 255 → 1.
    let known = [(0u8, 0.0f32), (10, 0.003_035_3), (128, 0.215_861), (188, 0.502_886), (255, 1.0)];
    for (v, lin) in known {
        assert!((srgb(v) - lin).abs() < 1e-5, "{v}: {} vs {lin}", srgb(v));
    }
    let rgb = [0u8, 10, 128, 188, 255, 64];
    write_png(&dir.join("rgb.png"), 2, 1, png::ColorType::Rgb, &rgb);
    let t = Bitmap::from_png(&std::fs::read(dir.join("rgb.png")).unwrap()).unwrap();
    assert_eq!((t.width(), t.height()), (2, 1));
    assert!((t.texel(0, 0) - Vec3::new(srgb(0), srgb(10), srgb(128))).abs().max_element() < 1e-6);
    assert!((t.texel(1, 0) - Vec3::new(srgb(188), srgb(255), srgb(64))).abs().max_element() < 1e-6);
    // Grey, grey with alpha and RGBA: the same curve, alpha ignored.
    write_png(&dir.join("grey.png"), 1, 2, png::ColorType::Grayscale, &[128, 188]);
    let g = Bitmap::from_png(&std::fs::read(dir.join("grey.png")).unwrap()).unwrap();
    assert!((g.texel(0, 0) - Vec3::splat(srgb(128))).abs().max_element() < 1e-6);
    assert!((g.texel(0, 1) - Vec3::splat(srgb(188))).abs().max_element() < 1e-6);
    write_png(&dir.join("ga.png"), 1, 1, png::ColorType::GrayscaleAlpha, &[188, 7]);
    let ga = Bitmap::from_png(&std::fs::read(dir.join("ga.png")).unwrap()).unwrap();
    assert!((ga.texel(0, 0) - Vec3::splat(srgb(188))).abs().max_element() < 1e-6);
    write_png(&dir.join("rgba.png"), 1, 1, png::ColorType::Rgba, &[255, 128, 0, 0]);
    let rgba = Bitmap::from_png(&std::fs::read(dir.join("rgba.png")).unwrap()).unwrap();
    assert!((rgba.texel(0, 0) - Vec3::new(1.0, srgb(128), 0.0)).abs().max_element() < 1e-6);
    // The mean is the mean of the linear values, not of the encoded ones.
    let mean = (srgb(0) + srgb(188)) / 2.0;
    assert!((Bitmap::from_png(&std::fs::read(dir.join("rgb.png")).unwrap()).unwrap().mean().x - mean).abs() < 1e-6);
    assert!(Bitmap::from_png(b"\x89PNG\r\n\x1a\nnot really").is_err());
}

/// An 8 × 8 texture of four 4 × 4 blocks of the given sRGB colours (top row first); returns them linear.
fn blocks_png(path: &Path, colours: [[[u8; 3]; 2]; 2]) -> [[Vec3; 2]; 2] {
    let mut data = Vec::new();
    for y in 0..8 {
        for x in 0..8 {
            data.extend_from_slice(&colours[y / 4][x / 4]);
        }
    }
    write_png(path, 8, 8, png::ColorType::Rgb, &data);
    colours.map(|row| row.map(|c| Vec3::new(srgb(c[0]), srgb(c[1]), srgb(c[2]))))
}

/// A textured square emitter at z = 1 facing a pinhole camera that sees it fill the view, plus (optionally)
/// a floor it lights. `emission_line` is the emitter's emission setting.
fn emitter_scene(emission_line: &str, floor: bool) -> String {
    let mut s = format!(
        "[render]\nmax_depth = 4\n\
         [camera]\nposition = [0.0, 0.0, -1.0]\nlook_at = [0.0, 0.0, 1.0]\nfov_y_deg = 53.13010235\nwidth = 32\nheight = 32\n\
         [materials.black]\ntype = \"diffuse\"\nalbedo = [0.0, 0.0, 0.0]\n\
         [materials.floor]\ntype = \"diffuse\"\nalbedo = [0.5, 0.5, 0.5]\n\
         [[objects]]\nname = \"emitter\"\nmaterial = \"black\"\n{emission_line}\n\
         quad = {{ corner = [1.0, -1.0, 1.0], edge1 = [-2.0, 0.0, 0.0], edge2 = [0.0, 2.0, 0.0] }}\n"
    );
    if floor {
        s += "[[objects]]\nname = \"floor\"\nmaterial = \"floor\"\n\
              quad = { corner = [-30.0, -1.5, -30.0], edge1 = [0.0, 0.0, 120.0], edge2 = [60.0, 0.0, 0.0] }\n";
    }
    s
}

#[test]
fn a_textured_emitter_shows_its_texture_times_its_emission() {
    let dir = scratch("emitter");
    // Red, green, blue and grey (sRGB 188 = linear 0.5029).
    let colours = blocks_png(&dir.join("blocks.png"), [[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [188, 188, 188]]]);
    let text = emitter_scene("emission = [2.0, 3.0, 4.0]\nemission_texture = \"blocks.png\"", false);
    let sc = Scene::from_toml(&text, Path::new("emitter.toml"), &dir).unwrap();
    let mut engine = Engine::new(&sc, settings(&sc, Method::Pbpm, 3));
    // The quad fills the 32 × 32 view exactly; u runs with the image's right (edge1 = −x), v upward. Each
    // block is pure between its texel centres: the middle 4 × 4 pixels of each image quadrant.
    for _ in 0..16 {
        engine.run_phase();
    }
    let emission = Vec3::new(2.0, 3.0, 4.0);
    for (by, row) in colours.iter().enumerate() {
        for (bx, colour) in row.iter().enumerate() {
            let expect = *colour * emission;
            for y in 0..4 {
                for x in 0..4 {
                    let (px, py) = (bx * 16 + 6 + x, by * 16 + 6 + y);
                    let p = &engine.sums().pixels[py * 32 + px];
                    let v = p.sum[Layer::VisibleLights as usize];
                    let n = p.phases as f64;
                    let got = Vec3::new((v[0] / n) as f32, (v[1] / n) as f32, (v[2] / n) as f32);
                    assert!(
                        (got - expect).abs().max_element() < 1e-4 * (1.0 + expect.max_element()),
                        "pixel ({px}, {py}): {got} but texture × emission is {expect}"
                    );
                }
            }
        }
    }
}

#[test]
fn a_textured_emitter_lights_a_floor_like_an_untextured_one_of_its_mean_emission() {
    let dir = scratch("lighting");
    // Diagonal blocks, so that every half of the emitter has the same mean: the floor's view of the emitter
    // varies across it (by about 5 % per metre here), which would otherwise weigh one half more.
    let colours = blocks_png(&dir.join("blocks.png"), [[[255, 0, 0], [0, 0, 255]], [[0, 0, 255], [255, 0, 0]]]);
    let mean = colours.iter().flatten().fold(Vec3::ZERO, |a, c| a + *c) / 4.0;
    let emission = Vec3::new(2.0, 3.0, 4.0);
    let flat = emission * mean;
    let floor_pixels: Vec<usize> = (0..32 * 32).collect();
    let mut out = Vec::new();
    for line in [
        "emission = [2.0, 3.0, 4.0]\nemission_texture = \"blocks.png\"".to_string(),
        format!("emission = [{}, {}, {}]", flat.x, flat.y, flat.z),
    ] {
        // The camera looks down at the floor in front of the emitter (which is behind it, out of view), far
        // enough below that the emitter's pattern averages out (to about 1e-3).
        let text =
            emitter_scene(&line, true).replace("corner = [-30.0, -1.5, -30.0]", "corner = [-30.0, -25.0, -90.0]");
        let text = text.replace("look_at = [0.0, 0.0, 1.0]", "look_at = [0.0, -25.0, -20.0]");
        let sc = Scene::from_toml(&text, Path::new("lighting.toml"), &dir).unwrap();
        let mut engine = Engine::new(&sc, settings(&sc, Method::Pbpm, 7));
        let samples = regions_phase_means(&mut engine, 400, &[(&floor_pixels, None)]).remove(0);
        out.push(mean_sem(&samples));
    }
    let ((a, sa), (b, sb)) = (out[0], out[1]);
    let sem = (sa * sa + sb * sb).sqrt();
    eprintln!("floor lit by the textured emitter {a:.4e} ± {sa:.1e}, by its mean {b:.4e} ± {sb:.1e}");
    assert!(a > 0.0 && (a - b).abs() < 4.0 * sem, "textured {a} ± {sa}, untextured mean {b} ± {sb}");
}
