//! The camera-lens scene (`scenes/lens.toml`): its lens surfaces are the published double Gauss, its sensor is
//! in focus, and both methods render it, ghosts included, with a ghost layer that holds exactly the light
//! reflected inside the lens. `cargo test --release -p photonfarm --test suite lens:: -- --nocapture` prints the
//! measured numbers.

use glam::{Vec2, Vec3};
use photonfarm::accumulation::blur::{BLUR_LAYER, BLUR_SQUARES_LAYER};
use photonfarm::accumulation::{non_finite_dropped, Accumulator, AuxLayout, PixelSums};
use photonfarm::bsdf::Transport;
use photonfarm::color::{luminance_f64, Rgb};
use photonfarm::geometry::{ray::offset_origin, Ray};
use photonfarm::ghost::GHOST_LAYER;
use photonfarm::integrator::Layer;
use photonfarm::integrator::LayerValues;
use photonfarm::light::Light;
use photonfarm::pbpm::PhotonMap;
use photonfarm::render::{Engine, Method};
use photonfarm::scene::Scene;
use photonfarm::spectrum::{Dispersive, Wavelength};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The prescription the scene cites (Kolb's dgauss.txt, from Smith, "Modern Lens Design", p. 312): per row the
/// radius of curvature (mm; None for the stop), the axial position relative to the previous row (mm), the index
/// behind the surface (None for the stop) and the clear-aperture diameter (mm).
const PRESCRIPTION: [(Option<f64>, f64, Option<f64>, f64); 11] = [
    (Some(58.950), 0.000, Some(1.670), 50.4),
    (Some(169.660), 7.520, Some(1.0), 50.4),
    (Some(38.550), 0.240, Some(1.670), 46.0),
    (Some(81.540), 8.050, Some(1.699), 46.0),
    (Some(25.500), 6.550, Some(1.0), 36.0),
    (None, 11.410, None, 34.2),
    (Some(-28.990), 9.000, Some(1.603), 34.0),
    (Some(81.540), 2.360, Some(1.658), 40.0),
    (Some(-40.770), 12.130, Some(1.0), 40.0),
    (Some(874.130), 0.380, Some(1.717), 40.0),
    (Some(-79.460), 6.440, Some(1.0), 40.0),
];

/// Abbe numbers V_d of the glasses by their index n_d (Kolb et al. Table 1's V-no column, as in the scene).
const ABBE: [(f64, f64); 5] = [(1.670, 47.1), (1.699, 30.1), (1.603, 38.0), (1.658, 57.3), (1.717, 48.0)];

/// A glass's index at `nm` by Cauchy's law through n_d and V_d, computed here from the table (air stays 1).
fn index_at(n_d: f64, nm: f64) -> f64 {
    let Some(&(_, v)) = ABBE.iter().find(|(n, _)| (n - n_d).abs() < 1e-9) else { return n_d };
    let (d, f, c) = (0.58756f64, 0.48613f64, 0.65627f64);
    let b = (n_d - 1.0) / (v * (1.0 / (f * f) - 1.0 / (c * c)));
    let um = nm * 1e-3;
    n_d + b * (1.0 / (um * um) - 1.0 / (d * d))
}

/// The scene's scale: the 100 mm design halved, in metres.
const SCALE_TO_METRES: f64 = 0.5e-3;

/// Object distance the sensor is focused for, in front of the front vertex (the vase's axis), metres.
const FOCUS_DISTANCE: f32 = 1.2;

/// Pixel pitch of the shipped scene: 36 mm over 360 pixels.
const PIXEL_PITCH: f32 = 0.036 / 360.0;

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/lens.toml")
}

/// The shipped scene, optionally at another resolution (the sensor keeps its size) and with every lens surface
/// given an ideal anti-reflection coating.
fn lens_scene(resolution: Option<(u32, u32)>, anti_reflection: bool) -> Scene {
    scene_from_text(&lens_scene_text(resolution, anti_reflection))
}

fn scene_from_text(text: &str) -> Scene {
    let path = scene_path();
    Scene::from_toml(text, &path, path.parent().unwrap()).unwrap_or_else(|e| panic!("{e}"))
}

/// The text of `lens_scene`.
fn lens_scene_text(resolution: Option<(u32, u32)>, anti_reflection: bool) -> String {
    let path = scene_path();
    let mut text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    if let Some((w, h)) = resolution {
        assert!(text.contains("width = 360\n") && text.contains("height = 240\n"), "the scene's resolution moved");
        text = text
            .replace("width = 360\n", &format!("width = {w}\n"))
            .replace("height = 240\n", &format!("height = {h}\n"));
    }
    if anti_reflection {
        text = text.replace("type = \"dielectric\"\n", "type = \"dielectric\"\nanti_reflection = true\n");
    }
    text
}

/// Paraxial (y–nu) trace of the prescription, scaled to the scene: a ray parallel to the axis at height 1 gives
/// the effective focal length −1/u' in the last medium (air), in metres.
fn paraxial_focal_length() -> f64 {
    paraxial_focal_length_at(587.56)
}

/// The paraxial focal length with every glass at its index for `nm`.
fn paraxial_focal_length_at(nm: f64) -> f64 {
    let (mut y, mut u, mut n) = (1.0f64, 0.0f64, 1.0f64);
    for (i, &(radius, position, index, _)) in PRESCRIPTION.iter().enumerate() {
        if i > 0 {
            y += u * position * SCALE_TO_METRES;
        }
        let (Some(r), Some(n_after)) = (radius, index) else { continue };
        let n_after = index_at(n_after, nm);
        // Refraction: n'u' = n u − y φ with the surface power φ = (n' − n)/R.
        let power = (n_after - n) / (r * SCALE_TO_METRES);
        u = (n * u - y * power) / n_after;
        n = n_after;
    }
    -1.0 / u
}

/// Follows a ray through the scene's lens by the geometry's intersections and the dielectric's refraction
/// (reflection excluded), until it leaves the lens toward the sensor. None when a mount or the stop blocks it.
fn through_lens(scene: &Scene, ray: Ray) -> Option<Ray> {
    through_lens_at(scene, ray, None)
}

/// `through_lens` with the glasses at one wavelength (None: the d line, as an RGB path sees them).
fn through_lens_at(scene: &Scene, mut ray: Ray, nm: Option<f32>) -> Option<Ray> {
    for _ in 0..64 {
        let Some(hit) = scene.geometry.intersect(&ray) else { return Some(ray) };
        if ray.direction.z >= 0.0 || hit.p.z > 0.01 || hit.p.z < -0.05 {
            // Anything but the lens (it spans z from 0 to −0.032 m) or a ray turned back.
            return None;
        }
        if !scene.material_at(&hit).is_dielectric() {
            return None;
        }
        let wo = -ray.direction;
        let mut bsdf = scene.bsdf(&hit, wo);
        if let Some(nm) = nm {
            bsdf = bsdf.at_wavelength(&Wavelength::with_pdf(nm, 1.0));
        }
        // u.x just below 1 selects refraction wherever the Fresnel reflectance is below 1.
        let s = bsdf.sample(wo, Vec2::new(1.0 - 1e-7, 0.5), Transport::Radiance)?;
        assert!(s.wi.dot(hit.ng) * wo.dot(hit.ng) < 0.0, "total internal reflection on a near-axial ray");
        ray = Ray::new(offset_origin(hit.p, hit.ng, s.wi), s.wi);
    }
    None
}

#[test]
fn traced_focal_length_of_the_scene_lens_matches_the_paraxial_prescription_within_one_percent() {
    let scene = lens_scene(None, false);
    let expected = paraxial_focal_length();
    // A ray parallel to the axis, 0.5 mm above it (1/25 of the front aperture: paraxial), from in front of the
    // lens.
    let h = 0.5e-3f32;
    let out = through_lens(&scene, Ray::new(Vec3::new(0.0, h, 0.5), -Vec3::Z)).expect("the ray passes the lens");
    let d = out.direction;
    // The exit ray's slope gives the focal length: f = h / tan(u').
    let traced = h as f64 * (-d.z as f64) / (-d.y as f64);
    let rel = traced / expected - 1.0;
    println!(
        "effective focal length: traced {:.4} mm, paraxial y–nu {:.4} mm ({:+.3} %)",
        traced * 1e3,
        expected * 1e3,
        rel * 100.0
    );
    assert!((expected * 1e3 - 50.36).abs() < 0.01, "the prescription itself: {expected}");
    assert!(rel.abs() < 0.01, "traced {traced} m vs paraxial {expected} m");
}

#[test]
fn the_lens_chromatic_focal_shift_follows_its_glasses_dispersion() {
    let scene = lens_scene(None, false);
    assert!(scene.is_spectral(), "the lens's glasses carry Abbe numbers");
    let h = 0.5e-3f32;
    let traced_at = |nm: f32| {
        let out = through_lens_at(&scene, Ray::new(Vec3::new(0.0, h, 0.5), -Vec3::Z), Some(nm)).expect("passes");
        h as f64 * (-out.direction.z as f64) / (-out.direction.y as f64)
    };
    // The F (486.13 nm), d and C (656.27 nm) lines.
    let mut traced = Vec::new();
    for nm in [486.13f32, 587.56, 656.27] {
        let (t, p) = (traced_at(nm), paraxial_focal_length_at(nm as f64));
        println!("{nm} nm: focal length traced {:.4} mm, paraxial {:.4} mm", t * 1e3, p * 1e3);
        assert!((t / p - 1.0).abs() < 1e-3, "at {nm} nm traced {t} m, paraxial {p} m");
        traced.push(t);
    }
    // The chromatic focal shift f_C − f_F, traced against paraxial: the dispersion reaches every surface.
    let shift = traced[2] - traced[0];
    let expected = paraxial_focal_length_at(656.27) - paraxial_focal_length_at(486.13);
    println!("focal shift C − F: traced {:.2} µm, paraxial {:.2} µm", shift * 1e6, expected * 1e6);
    assert!(expected.abs() > 1e-6, "the prescription's glasses must disperse: {expected}");
    assert!((shift / expected - 1.0).abs() < 0.05, "focal shift traced {shift} m, paraxial {expected} m");
}

#[test]
fn on_axis_point_at_the_focus_distance_images_to_a_spot_below_one_pixel_rms() {
    let scene = lens_scene(None, false);
    let sensor_z = scene.camera.position.z;
    let source = Vec3::new(0.0, 0.0, FOCUS_DISTANCE);
    // Aim at a 64 × 64 grid over a disc wider than the front element: the stop decides which rays pass, so the
    // spot covers the whole pupil.
    let n = 64;
    let radius = 0.014f32;
    let mut points = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let q = Vec2::new((i as f32 + 0.5) / n as f32 * 2.0 - 1.0, (j as f32 + 0.5) / n as f32 * 2.0 - 1.0);
            if q.length() > 1.0 {
                continue;
            }
            let target = Vec3::new(q.x * radius, q.y * radius, 0.0);
            let dir = (target - source).normalize();
            // Start just in front of the lens: the source point itself lies inside the vase.
            let start = source + dir * ((0.05 - source.z) / dir.z);
            let Some(out) = through_lens(&scene, Ray::new(start, dir)) else { continue };
            let t = (sensor_z - out.origin.z) / out.direction.z;
            points.push(out.at(t).truncate());
        }
    }
    let count = points.len() as f32;
    let centroid = points.iter().copied().sum::<Vec2>() / count;
    let rms = (points.iter().map(|p| (*p - centroid).length_squared()).sum::<f32>() / count).sqrt();
    println!(
        "spot of an on-axis point at {FOCUS_DISTANCE} m: {} rays through the pupil, RMS radius {:.2} µm = {:.3} \
         pixels, centroid {:.2} µm from the sensor centre",
        points.len(),
        rms * 1e6,
        rms / PIXEL_PITCH,
        centroid.length() * 1e6
    );
    // The stop (radius 8.55 mm) passes a pupil of about 2/3 of the front element's radius: hundreds of rays.
    assert!(points.len() > 500, "only {} rays passed the lens", points.len());
    assert!(rms < PIXEL_PITCH, "RMS spot radius {rms} m is not below one pixel ({PIXEL_PITCH} m)");
    assert!(centroid.length() < 0.1 * PIXEL_PITCH, "the on-axis point images off the sensor centre: {centroid:?}");
}

/// Mean luminance of the visible-lights layer (E S* L: the light seen through the lens surfaces, directly or
/// after reflections between them) per pixel.
fn visible_lights(sums: &Accumulator) -> Vec<f64> {
    (0..sums.pixels.len()).map(|p| photonfarm::color::luminance_f64(sums.mean(p, Layer::VisibleLights))).collect()
}

fn render(scene: &Scene, method: Method, phases: usize) -> Engine<'_> {
    let mut engine = Engine::new(scene, crate::common::settings(scene, method, 7));
    for _ in 0..phases {
        engine.run_phase();
    }
    engine
}

/// The lens scene at 72 × 48 pixels rendered once for the tests that share it: both coatings with both
/// methods, 64 phases each.
struct LensRenders {
    /// (anti-reflection coated, method, sums) for each of the four renders.
    runs: Vec<(bool, Method, Accumulator)>,
    /// Non-finite phase values the sums dropped while the renders ran.
    dropped: u64,
}

impl LensRenders {
    fn sums(&self, coated: bool, method: Method) -> &Accumulator {
        let run = self.runs.iter().find(|(c, m, _)| *c == coated && *m == method);
        &run.expect("every coating and method is rendered").2
    }
}

fn lens_renders() -> &'static LensRenders {
    static RENDERS: OnceLock<LensRenders> = OnceLock::new();
    RENDERS.get_or_init(|| {
        let dropped_before = non_finite_dropped();
        let mut runs = Vec::new();
        for coated in [false, true] {
            let scene = lens_scene(Some((72, 48)), coated);
            for method in [Method::Pbpm, Method::Path] {
                runs.push((coated, method, render(&scene, method, 64).sums().clone()));
            }
        }
        LensRenders { runs, dropped: non_finite_dropped() - dropped_before }
    })
}

#[test]
fn both_methods_render_the_lens_scene_finite_with_ghosts_outside_the_direct_image_of_the_light() {
    let (w, h) = (72u32, 48u32);
    let renders = lens_renders();
    for method in [Method::Pbpm, Method::Path] {
        let phases = 64;
        let (plain, ghosts) = (renders.sums(true, method), renders.sums(false, method));
        assert_eq!((plain.width, plain.height), (w, h));
        for sums in [plain, ghosts] {
            for p in 0..(w * h) as usize {
                for l in Layer::ALL {
                    assert!(sums.mean(p, l).iter().all(|v| v.is_finite()), "{method:?}: pixel {p} {l:?}");
                }
            }
        }
        // The direct image of the light: where the coated lens shows it, widened by two pixels for the pixels
        // whose share of the image this run did not sample.
        let direct = visible_lights(plain);
        let near_direct = |p: usize| {
            let (x, y) = ((p as u32 % w) as i64, (p as u32 / w) as i64);
            (-2..=2i64).any(|dy| {
                (-2..=2i64).any(|dx| {
                    let (nx, ny) = (x + dx, y + dy);
                    nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64 && direct[(ny * w as i64 + nx) as usize] > 0.0
                })
            })
        };
        let direct_pixels = (0..direct.len()).filter(|&p| direct[p] > 0.0).count();
        let with_ghosts = visible_lights(ghosts);
        let ghost_pixels: Vec<usize> =
            (0..with_ghosts.len()).filter(|&p| with_ghosts[p] > 0.0 && !near_direct(p)).collect();
        let ghost_light: f64 = ghost_pixels.iter().map(|&p| with_ghosts[p]).sum();
        let direct_light: f64 = direct.iter().sum();
        println!(
            "{method:?}, {w}×{h}, {phases} phases: the coated lens images the light onto {direct_pixels} pixels; the \
             uncoated one also onto {} pixels outside them (ghosts), carrying {:.3} % of the light's direct image",
            ghost_pixels.len(),
            100.0 * ghost_light / direct_light
        );
        assert!(direct_pixels > 0, "{method:?}: the light is not in the picture");
        assert!(ghost_pixels.len() >= 10, "{method:?}: only {} ghost pixels", ghost_pixels.len());
    }
    assert_eq!(renders.dropped, 0, "non-finite values were dropped");
}

#[test]
fn light_paths_bring_the_lens_image_of_the_small_bright_light_and_leave_the_large_ceiling_light_to_camera_paths() {
    let scene = lens_scene(None, false);
    let bright = |l: &Light| matches!(l, Light::Area { emission, .. } if emission.x > 1000.0);
    let lights = scene.lights.all();
    assert!(lights.iter().any(bright) && !lights.iter().all(bright));
    for (l, light) in lights.iter().enumerate() {
        assert_eq!(scene.lights.lens_image_by_light_paths(l as u32), bright(light), "light {l}: {light:?}");
    }
    // Camera paths alone (`ghost_light_paths = false`) keep every image.
    let text = lens_scene_text(None, false).replace("max_depth = 32\n", "max_depth = 32\nghost_light_paths = false\n");
    let camera_only = scene_from_text(&text);
    assert!((0..lights.len() as u32).all(|l| !camera_only.lights.lens_image_by_light_paths(l)));
}

/// Luminance of a pixel's mean ghost layer.
fn ghost_luminance(sums: &Accumulator, p: usize) -> f64 {
    luminance_f64(sums.aux_mean(p, GHOST_LAYER).expect("the scene has a ghost layer"))
}

/// Σ over pixels of the luminance of the ghost layer's sums and of the total's sums.
fn image_sums(sums: &Accumulator) -> (f64, f64) {
    sums.ghost_luminance_sums().expect("the scene has a ghost layer")
}

/// Renders `phases` phases and returns, per phase, the image's ghost and total luminance sums. Pixels of one
/// phase share light paths, so an error estimate of the image sum must come from these per-phase values.
fn phase_image_sums(scene: &Scene, method: Method, seed: u64, phases: usize) -> (Vec<f64>, Vec<f64>) {
    let mut engine = Engine::new(scene, crate::common::settings(scene, method, seed));
    let (mut ghost, mut total) = (Vec::with_capacity(phases), Vec::with_capacity(phases));
    let mut before = (0.0, 0.0);
    for _ in 0..phases {
        engine.run_phase();
        let after = image_sums(engine.sums());
        ghost.push(after.0 - before.0);
        total.push(after.1 - before.1);
        before = after;
    }
    (ghost, total)
}

/// Asserts that PBPM and the path tracer agree on the mean image ghost sum per phase within four combined
/// standard errors, and returns (PBPM, path) as (mean, SEM) pairs.
fn assert_methods_agree_on_the_ghost(scene: &Scene, phases: usize, what: &str) -> [(f64, f64); 2] {
    // The two methods' renders are independent single-threaded engines: run side by side.
    let renders = std::thread::scope(|s| {
        [Method::Pbpm, Method::Path]
            .map(|m| s.spawn(move || (m, phase_image_sums(scene, m, 11, phases))))
            .map(|h| h.join().unwrap())
    });
    let [pbpm, path] = renders.map(|(m, (ghost, total))| {
        let (g, t) = (crate::common::mean_sem(&ghost), crate::common::mean_sem(&total));
        println!(
            "{what}, {m:?}, {phases} phases: ghost {:.4e} ± {:.2e} per phase, {:.2} % of the total {:.4e}",
            g.0,
            g.1,
            100.0 * g.0 / t.0,
            t.0
        );
        g
    });
    let bound = 4.0 * (pbpm.1 * pbpm.1 + path.1 * path.1).sqrt();
    assert!(pbpm.0 > 0.0 && path.0 > 0.0, "{what}: no ghost light");
    assert!(
        (pbpm.0 - path.0).abs() <= bound,
        "{what}: PBPM's ghost {} and the path tracer's {} differ by more than 4 combined SEM ({bound})",
        pbpm.0,
        path.0
    );
    [pbpm, path]
}

#[test]
fn the_ghost_layer_is_non_zero_through_the_uncoated_lens_and_exactly_zero_through_the_coated_one() {
    for (coated, method, sums) in &lens_renders().runs {
        assert!(sums.aux.layout().offset(GHOST_LAYER).is_some(), "{method:?}: no ghost layer");
        let pixels = (0..sums.pixels.len()).filter(|&p| ghost_luminance(sums, p) > 0.0).count();
        let (ghost, total) = image_sums(sums);
        println!(
            "{method:?}, {}: ghost light on {pixels} of {} pixels, {:.3} % of the image's light",
            if *coated { "anti-reflection coated" } else { "uncoated" },
            sums.pixels.len(),
            100.0 * ghost / total
        );
        if *coated {
            // Only total internal reflection can still reflect under the coating. It happens (about 3 camera
            // paths in 10⁵, all at s6, behind the stop), but such a path never reaches a surface other than
            // glass, so no light comes of it: the layer is exactly zero, not merely small.
            let ghost_values = (0..sums.pixels.len()).flat_map(|p| sums.aux.pixel(p)[..3].to_vec());
            assert!(ghost_values.into_iter().all(|v| v == 0.0), "{method:?}: ghost light through the coated lens");
        } else {
            assert!(pixels >= 100 && ghost > 0.0, "{method:?}: ghost light on only {pixels} pixels");
        }
    }
}

#[test]
fn the_ghost_layer_never_exceeds_the_total_in_any_pixel() {
    for (_, method, sums) in lens_renders().runs.iter().filter(|(coated, _, _)| !coated) {
        let mut largest: f64 = 0.0;
        for p in 0..sums.pixels.len() {
            // In luminance: the lens disperses, and a pure spectral colour has a negative channel (outside the
            // RGB gamut), but its luminance, ȳ weighted, is never negative.
            let ghost = photonfarm::color::luminance_f64(sums.aux_mean(p, GHOST_LAYER).unwrap());
            let total = photonfarm::color::luminance_f64(sums.mean_total(p));
            assert!(ghost >= 0.0, "{method:?}: pixel {p}: negative ghost light {ghost}");
            // Ghost light is added to its usual layer as well, so it is a part of the total. The two are summed
            // in f32 in different orders within a phase: a few ulps of rounding apart at most.
            assert!(ghost <= total * (1.0 + 1e-5), "{method:?}: pixel {p}: ghost {ghost} exceeds the total {total}");
            if ghost > 0.0 {
                largest = largest.max(ghost / total);
            }
        }
        println!("{method:?}: the ghost layer's largest share of a pixel's total is {largest:.8}");
        // Pixels lit by ghosts alone exist, so the bound is tested where it is tight.
        assert!(largest > 0.99, "{method:?}: no pixel is lit mostly by ghosts ({largest})");
    }
}

#[test]
fn pbpm_and_the_path_tracer_agree_on_the_ghost_veil_of_the_lens_lit_by_its_fill_light() {
    // The bright light's ghosts are single rare samples (one phase can carry more than the mean of the whole
    // image), too heavy-tailed for a standard error from a few hundred phases to be trusted; the lens's
    // reflections of the scene lit by the fill light (the veil, about 6 % of the image) are not.
    let bright = "emission = [50000.0, 45000.0, 37500.0]\n";
    let text = lens_scene_text(Some((72, 48)), false);
    assert!(text.contains(bright), "the bright light's emission moved");
    let scene = scene_from_text(&text.replace(bright, ""));
    assert_methods_agree_on_the_ghost(&scene, 200, "lens lit by its fill light");
}

#[test]
fn ghost_light_gathered_into_ghost_photons_reaches_the_ghost_layer_as_the_path_tracer_sees_it() {
    // A closed white room seen through a flat glass window; the window's reflections see the room behind the
    // sensor. Light bounced at least twice (a fraction 0.8² of the room's light) reaches camera paths only
    // through the photons of PBPM's forward pass: without their ghost bit PBPM's ghost layer here falls to half
    // of the path tracer's (measured: 0.289 against 0.577 per phase, 45 times the 4-SEM bound's SEM).
    let scene = crate::common::shipped("ghost-room.toml");
    let [(pbpm, pbpm_sem), (path, _)] = assert_methods_agree_on_the_ghost(&scene, 1000, "room behind a window");
    assert!(pbpm_sem < 0.05 * pbpm, "the comparison is too noisy to see a missing half: SEM {pbpm_sem} of {pbpm}");
    println!("room behind a window: PBPM's ghost / the path tracer's = {:.4}", pbpm / path);
}

/// The two grey blur layers: their f64 sums and two per-phase f32 buffers (the camera pass's and the gathered).
const BLUR_BYTES_PER_PIXEL: f64 = 2.0 * (8.0 + 4.0 + 4.0);

/// The bytes per pixel the single-threaded engine holds without auxiliary layers: sums, phase values and
/// replicate, gathered light, and a photon map reserved for one photon per diffuse vertex of each camera path.
fn bytes_per_pixel_without_auxiliary_layers(scene: &Scene) -> f64 {
    let pixels = scene.camera.pixel_count();
    let mut map = PhotonMap::new();
    let depth = crate::common::settings(scene, Method::Pbpm, 1).backward_diffuse_depth;
    map.reserve(pixels * depth as usize);
    let per_pixel = std::mem::size_of::<PixelSums>() + std::mem::size_of::<LayerValues>() + 1 + 2 * 12;
    assert_eq!(std::mem::size_of::<[Rgb; 2]>(), 2 * 12);
    (pixels * per_pixel + map.capacity_bytes()) as f64 / pixels as f64
}

#[test]
fn only_a_sensor_behind_glass_gets_ghost_planes_and_other_scenes_keep_their_bytes_per_pixel() {
    // Pinhole cameras, with (caustic) and without (cornell) glass in the scene: no lens to reflect in, only the
    // two grey blur layers every image keeps.
    for name in ["cornell.toml", "caustic.toml"] {
        let scene = crate::common::shipped(name);
        let layout = AuxLayout::for_scene(&scene, 0);
        let layers: Vec<&str> = layout.layers().iter().map(|l| l.name.as_str()).collect();
        assert_eq!(layers, [BLUR_LAYER, BLUR_SQUARES_LAYER], "{name}");
        let engine = Engine::new(&scene, crate::common::settings(&scene, Method::Pbpm, 1));
        assert_eq!(engine.sums().aux.values().len(), 2 * scene.camera.pixel_count(), "{name}");
        let expected = bytes_per_pixel_without_auxiliary_layers(&scene) + BLUR_BYTES_PER_PIXEL;
        println!("{name}: {:.1} bytes per pixel", engine.bytes_per_pixel());
        assert_eq!(engine.bytes_per_pixel(), expected, "{name}: bytes per pixel changed");
    }
    // The sensor behind the lens, coated or not (total internal reflection survives a coating): the ghost
    // layer's sums (3 × f64), two per-phase buffers (3 × f32 each) and the visible light registered on the
    // sensor (3 × f32) per pixel, nothing else.
    for coated in [false, true] {
        let scene = lens_scene(None, coated);
        let engine = Engine::new(&scene, crate::common::settings(&scene, Method::Pbpm, 1));
        assert_eq!(engine.sums().aux.layout().offset(GHOST_LAYER), Some(0));
        let expected =
            bytes_per_pixel_without_auxiliary_layers(&scene) + BLUR_BYTES_PER_PIXEL + 3.0 * (8.0 + 4.0 + 4.0 + 4.0);
        println!("lens (coated: {coated}): {:.1} bytes per pixel", engine.bytes_per_pixel());
        assert_eq!(engine.bytes_per_pixel(), expected, "lens (coated: {coated})");
    }
}
