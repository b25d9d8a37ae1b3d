//! The split of a lens's ghosts between light and camera paths (docs/estimator.md, "The ghost layer"): with
//! light paths registering the all-specular ghost chains on the sensor and camera paths leaving those chains to
//! them, both PBPM and the path tracer converge per pixel to the image of camera paths alone, ghost layer
//! included, on a scene where both halves of the ghost layer carry light; and so they do when light paths also
//! bring a light's image through the lens.

use photonfarm::accumulation::Accumulator;
use photonfarm::color::luminance_f64;
use photonfarm::ghost::GHOST_LAYER;
use photonfarm::light::ghost_aim::{RINGS, SECTORS};
use photonfarm::pbpm::{ghost_pairs, trace_ghost_paths, trace_light_path, ForwardStats, LightEvent, LightSettings};
use photonfarm::ray_map::Unrecorded;
use photonfarm::render::{Engine, Method};
use photonfarm::sampling::{Frame, Sampler};
use photonfarm::scene::ghost::GhostPair;
use photonfarm::scene::Scene;
use photonfarm::spectrum::PhaseSpectrum;

/// A 16 × 12 sensor behind a flat window of high-index glass (n = 3: each face reflects a quarter of the light
/// at normal incidence, so ghost chains are frequent from both sides), in a closed grey room lit by a ceiling
/// light, with a small bright lamp in the middle of the field facing the window. The lamp's light reflected
/// twice inside the window reaches the sensor through specular surfaces only: the light side's half of the
/// ghost layer. The room seen in the window's reflections, behind the sensor, is the camera side's half.
fn scene(ghost_light_paths: bool) -> Scene {
    scene_with_glass(ghost_light_paths, 3.0)
}

/// `scene` with a window of refractive index `ior`. Each ghost chain registers on its own pixel (`ghost_radius =
/// 0`): the partition is a property of the registrations, proved here without the sensor's disc.
fn scene_with_glass(ghost_light_paths: bool, ior: f32) -> Scene {
    scene_with_glass_and(ghost_light_paths, ior, 0.0, "")
}

/// `scene_with_glass` with ghost registrations spread over a sensor disc of `ghost_radius` pixels at the first
/// phase, and more of the scene file's text after it.
fn scene_with_glass_and(ghost_light_paths: bool, ior: f32, ghost_radius: f32, more: &str) -> Scene {
    // The lamp's chains reach the sensor from about one light path in 500: enough paths per phase that most
    // pixels get some in every batch of phases, so that their standard errors can be estimated.
    let light_paths = if ghost_light_paths { 16 } else { 1 };
    crate::common::scene(&format!(
        r#"
[render]
max_depth = 16
light_paths_per_pixel = {light_paths}
ghost_light_paths = {ghost_light_paths}
ghost_radius = {ghost_radius}

[camera]
type = "sensor"
position = [0.0, 0.0, -0.05]
look_at = [0.0, 0.0, 0.0]
sensor_width = 0.012
rear_element = "window back"
width = 16
height = 12

[materials.white]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]

[materials.air_to_glass]
type = "dielectric"
ior = {ior:?}

[materials.glass_to_air]
type = "dielectric"
ext_ior = {ior:?}
ior = 1.0

[[objects]]
name = "window front"
material = "air_to_glass"
lens_surface = {{ vertex = [0.0, 0.0, 0.0], axis = [0.0, 0.0, -1.0], curvature_radius = 0.0, aperture_radius = 0.01 }}

[[objects]]
name = "window back"
material = "glass_to_air"
lens_surface = {{ vertex = [0.0, 0.0, -0.004], axis = [0.0, 0.0, -1.0], curvature_radius = 0.0, aperture_radius = 0.01 }}

[[objects]]
name = "room"
material = "white"
box = {{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] }}

[[objects]]
name = "ceiling light"
material = "black"
emission = [10.0, 10.0, 10.0]
quad = {{ corner = [-0.2, 0.98, -0.2], edge1 = [0.4, 0.0, 0.0], edge2 = [0.0, 0.0, 0.4] }}

[[objects]]
name = "lamp"
material = "black"
emission = [200.0, 175.0, 125.0]
quad = {{ corner = [-0.02, -0.02, 0.3], edge1 = [0.0, 0.04, 0.0], edge2 = [0.04, 0.0, 0.0] }}
{more}
"#
    ))
}

/// Per pixel, the mean and standard error of the total's and the ghost layer's luminance.
struct PixelEstimates {
    total: Vec<(f64, f64)>,
    ghost: Vec<(f64, f64)>,
}

/// Luminance sums over phases of every pixel's total and ghost layer.
fn luminance_sums(sums: &Accumulator) -> (Vec<f64>, Vec<f64>) {
    (0..sums.pixels.len())
        .map(|p| {
            let s = &sums.pixels[p];
            let total: f64 = s.sum.iter().map(|l| luminance_f64(*l)).sum();
            let g = &sums.aux.pixel(p)[sums.aux.layout().offset(GHOST_LAYER).unwrap()..];
            (total, luminance_f64([g[0], g[1], g[2]]))
        })
        .unzip()
}

/// Renders `batches` × `per_batch` phases and estimates each pixel's mean with its standard error from the
/// spread of the batches' means: the batches are independent, unlike the quasi-random phases of one pixel.
fn render(scene: &Scene, method: Method, seed: u64, batches: usize, per_batch: usize) -> PixelEstimates {
    let mut engine = Engine::new(scene, crate::common::settings(scene, method, seed));
    let pixels = scene.camera.pixel_count();
    let (mut before_t, mut before_g) = (vec![0.0; pixels], vec![0.0; pixels]);
    let (mut means_t, mut means_g) = (vec![Vec::new(); pixels], vec![Vec::new(); pixels]);
    for _ in 0..batches {
        for _ in 0..per_batch {
            engine.run_phase();
        }
        let (t, g) = luminance_sums(engine.sums());
        for p in 0..pixels {
            means_t[p].push((t[p] - before_t[p]) / per_batch as f64);
            means_g[p].push((g[p] - before_g[p]) / per_batch as f64);
        }
        (before_t, before_g) = (t, g);
    }
    PixelEstimates {
        total: means_t.iter().map(|m| crate::common::mean_sem(m)).collect(),
        ghost: means_g.iter().map(|m| crate::common::mean_sem(m)).collect(),
    }
}

/// Mean over pixels of z² = (a − b)² / (SEM_a² + SEM_b²), over the pixels where either side has an error.
fn mean_z2(a: &[(f64, f64)], b: &[(f64, f64)]) -> (f64, usize) {
    let z2: Vec<f64> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.1 > 0.0 || y.1 > 0.0)
        .map(|(x, y)| (x.0 - y.0).powi(2) / (x.1 * x.1 + y.1 * y.1))
        .collect();
    (z2.iter().sum::<f64>() / z2.len() as f64, z2.len())
}

/// Σ over pixels of the means, with its standard error (pixels taken as independent).
fn image_sum(estimates: &[(f64, f64)]) -> (f64, f64) {
    let sum = estimates.iter().map(|e| e.0).sum();
    (sum, estimates.iter().map(|e| e.1 * e.1).sum::<f64>().sqrt())
}

/// The light side's half of the ghost layer over the image: the luminance the light paths (and their ghost
/// paths, `ghost_paths` per light path) register on the sensor per light path, summed over pixels, with its
/// standard error over the light paths, and the rays they cost.
fn light_half(scene: &Scene, paths: u64, ghost_paths: u32) -> ((f64, f64), u64) {
    let settings = LightSettings { max_depth: scene.render.max_depth, sensor: true, vertices: false, ghost_paths };
    let mut stats = ForwardStats::default();
    let mut values = Vec::with_capacity(paths as usize);
    for index in 0..paths {
        let mut s = Sampler::light(5, 1, index);
        let mut sum = 0.0;
        let mut visit = |e: &LightEvent| match e {
            LightEvent::Sensor(hit) if hit.ghost => {
                sum += luminance_f64([hit.value.x as f64, hit.value.y as f64, hit.value.z as f64])
            }
            _ => {}
        };
        trace_light_path(scene, settings, &PhaseSpectrum::RGB, index, &mut s, &mut stats, &mut visit, &mut Unrecorded);
        trace_ghost_paths(scene, settings, &PhaseSpectrum::RGB, index, 5, 1, &mut stats, &mut visit, None);
        values.push(sum);
    }
    (crate::common::mean_sem(&values), stats.rays)
}

/// Asserts that ghost paths (two per light path) bring the ghost light that light paths alone bring, within 4
/// standard errors, and returns the variance × rays of each: light paths, then ghost paths.
fn assert_ghost_paths_bring_what_light_paths_bring(scene: &Scene) -> (f64, f64) {
    let (light_paths, light_rays) = light_half(scene, 6_400_000, 0);
    let (ghost_paths, ghost_rays) = light_half(scene, 200_000, 2);
    println!("light paths: {:.4e} ± {:.1e} ({light_rays} rays)", light_paths.0, light_paths.1);
    println!("ghost paths: {:.4e} ± {:.1e} ({ghost_rays} rays)", ghost_paths.0, ghost_paths.1);
    let bound = 4.0 * (light_paths.1.powi(2) + ghost_paths.1.powi(2)).sqrt();
    assert!((light_paths.0 - ghost_paths.0).abs() < bound, "the ghost light differs by more than 4 standard errors");
    (light_paths.1.powi(2) * light_rays as f64, ghost_paths.1.powi(2) * ghost_rays as f64)
}

/// Asserts that PBPM and the path tracer on `split` converge per pixel, in the total and in the ghost layer, to
/// the camera-only `reference` (mean z² within 4 standard deviations of 1), and that the image sums agree.
fn assert_converges_to_camera_only(split: &Scene, reference: &PixelEstimates) {
    // Over n pixels, a mean z² within 4 standard deviations of its expectation 1 (z² has variance 2).
    let n = reference.total.len() as f64;
    let bound = 1.0 + 4.0 * (2.0 / n).sqrt();
    for (method, seed) in [(Method::Pbpm, 2), (Method::Path, 3)] {
        let estimate = render(split, method, seed, 40, 25);
        for (what, a, b) in [("total", &estimate.total, &reference.total), ("ghost", &estimate.ghost, &reference.ghost)]
        {
            let (z2, pixels) = mean_z2(a, b);
            let (sum_a, sum_b) = (image_sum(a), image_sum(b));
            println!(
                "{method:?}, {what}: image {:.3} ± {:.3}, camera-only {:.3} ± {:.3}",
                sum_a.0, sum_a.1, sum_b.0, sum_b.1
            );
            let image_bound = 4.0 * (sum_a.1.powi(2) + sum_b.1.powi(2)).sqrt();
            assert!((sum_a.0 - sum_b.0).abs() < image_bound, "{method:?}, {what}: the image sums differ");
            println!("{method:?}, {what}: mean z² {z2:.3} over {pixels} pixels (bound {bound:.3})");
            assert!(pixels as f64 > 0.9 * n, "{method:?}, {what}: only {pixels} pixels have light");
            assert!(z2 < bound, "{method:?}, {what}: mean z² {z2} against the camera-only image exceeds {bound}");
        }
    }
}

#[test]
fn ghosts_and_a_lights_lens_image_from_light_paths_converge_per_pixel_to_the_camera_only_image_with_both_methods() {
    let (split, camera_only) = (scene(true), scene(false));
    // Both halves of the ghost layer carry light: the lamp's chains (light side) and the room in the window's
    // reflections (camera side). A flat window images nothing, so no light's image is the light side's here.
    let lights = split.lights.all().len();
    assert!((0..lights as u32).all(|l| !split.lights.lens_image_by_light_paths(l)));
    let reference = render(&camera_only, Method::Pbpm, 1, 40, 100);
    let ghost: f64 = reference.ghost.iter().map(|g| g.0).sum();
    let light = light_half(&split, 200_000, split.render.ghost_paths).0 .0;
    println!("ghost layer over the image {ghost:.4e}, of which the lamp's chains from light paths {light:.4e}");
    assert!(light > 0.05 * ghost && light < 0.95 * ghost, "one half of the ghost layer is empty: {light} of {ghost}");
    assert_converges_to_camera_only(&split, &reference);
    // The split holds whichever lights' images go to the light paths: here the lamp's (its two triangles, after
    // the ceiling light's), which covers most pixels, so that both halves of the image are checked everywhere.
    let mut lamp_image = split;
    lamp_image.lights.set_lens_images_by_light_paths((0..lights).map(|l| l == 2 || l == 3).collect());
    assert_converges_to_camera_only(&lamp_image, &reference);
}

/// Mean and standard error over `n` emitted light paths of their flux, and of their flux leaving toward the
/// front element's disc.
fn emitted_flux(scene: &Scene, n: u64) -> [(f64, f64); 2] {
    let disc = scene.lights.aim().unwrap_or(photonfarm::camera::RearElement {
        center: glam::Vec3::ZERO,
        axis: -glam::Vec3::Z,
        radius: 0.01,
    });
    let (mut all, mut toward) = (Vec::with_capacity(n as usize), Vec::with_capacity(n as usize));
    for i in 0..n {
        let mut s = Sampler::light(9, 2, i);
        let (u_select, u_pos, u_dir) = (s.next_f32(), s.next_2d(), s.next_2d());
        let (flux, hits) = match scene.lights.sample_emission(&scene.geometry, u_select, u_pos, u_dir) {
            Some(e) => {
                let along = e.direction.dot(disc.axis);
                let t = (disc.center - e.origin).dot(disc.axis) / along;
                let p = e.origin + e.direction * t;
                (luminance_f64(e.beta.to_array().map(f64::from)), t > 0.0 && (p - disc.center).length() <= disc.radius)
            }
            None => (0.0, false),
        };
        all.push(flux);
        toward.push(if hits { flux } else { 0.0 });
    }
    [crate::common::mean_sem(&all), crate::common::mean_sem(&toward)]
}

#[test]
fn light_paths_aimed_at_the_front_element_carry_the_same_flux_overall_and_toward_it() {
    let (aimed, plain) = (scene(true), scene(false));
    assert!(aimed.lights.aim().is_some() && plain.lights.aim().is_none());
    let (a, p) = (emitted_flux(&aimed, 400_000), emitted_flux(&plain, 400_000));
    for (what, a, p) in [("all", a[0], p[0]), ("toward the window", a[1], p[1])] {
        println!("{what}: aimed {:.5e} ± {:.1e}, by the cosine {:.5e} ± {:.1e}", a.0, a.1, p.0, p.1);
        assert!((a.0 - p.0).abs() < 4.0 * (a.1 * a.1 + p.1 * p.1).sqrt(), "{what}: the flux differs");
    }
    // Aiming is the point: the estimate of the flux toward the window is much better.
    assert!(a[1].1 < 0.2 * p[1].1, "aiming did not help: {} against {}", a[1].1, p[1].1);
}

#[test]
fn ghost_paths_bring_the_ghost_light_that_light_paths_bring_through_weakly_reflecting_glass() {
    // At n = 1.5 a face reflects 4%: a ghost path reflects at its pair's surfaces with probability 0.95 and
    // refracts at the others, so its chains carry the weights F / q, (1 − F) / (1 − q) and 1 / P(pair): the
    // expectation must not move.
    let (a, b) = assert_ghost_paths_bring_what_light_paths_bring(&scene_with_glass(true, 1.5));
    // Ghost paths are the better estimator per ray, or they would not be worth tracing.
    println!("variance × rays: light paths {a:.3e}, ghost paths {b:.3e}");
    assert!(b < a, "ghost paths gain nothing per ray");
}

#[test]
fn the_pair_table_gives_every_pair_a_probability_and_most_to_the_pair_that_makes_the_windows_ghost() {
    let scene = scene_with_glass(true, 1.5);
    let table: Vec<(GhostPair, f32)> = ghost_pairs(&scene).expect("a table for a sensor scene").iter().collect();
    let name = |o: u32| scene.objects[o as usize].name.as_str();
    // Two surfaces: each alone and each ordered pair, the surface twice included.
    assert_eq!(table.len(), 6);
    let total: f32 = table.iter().map(|(_, p)| p).sum();
    assert!((total - 1.0).abs() < 1e-5, "probabilities sum to {total}");
    let even = photonfarm::pbpm::ghost_paths::EVEN_SHARE / table.len() as f32;
    assert!(table.iter().all(|&(_, p)| p >= 0.99 * even), "a pair lost its share: {table:?}");
    // The lamp's light enters the front face, reflects at the back one, then at the front one, and leaves.
    let (best, _) = table.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    assert_eq!((name(best.first), best.second.map(name)), ("window back", Some("window front")));
    // Decided by fixed seeds: every process that loads the scene draws from the same table.
    let again: Vec<(GhostPair, f32)> = ghost_pairs(&scene_with_glass(true, 1.5)).unwrap().iter().collect();
    assert_eq!(table, again);
}

#[test]
fn ghost_paths_aim_where_the_pilot_saw_their_pair_reach_the_sensor_and_keep_the_expectation() {
    // A black screen just in front of the window hides its half at x < 0 from the lamp: no ghost chain starts
    // there, and the grid of the window's ghost pair must send few paths there. Light paths, which aim
    // evenly, still decide what the ghost paths must bring.
    let screen = r#"
[[objects]]
name = "screen"
material = "black"
quad = { corner = [-0.5, -0.5, 0.002], edge1 = [0.0, 1.0, 0.0], edge2 = [0.5, 0.0, 0.0] }
"#;
    let scene = scene_with_glass_and(true, 1.5, 0.0, screen);
    let pairs = ghost_pairs(&scene).expect("a table for a sensor scene");
    let (best, _) = pairs.iter().enumerate().max_by(|a, b| a.1 .1.total_cmp(&b.1 .1)).expect("pairs");
    let grid = pairs.aim(best);
    let front = scene.lights.aim().expect("the window's front face");
    let frame = Frame::from_normal(front.axis);
    // A cell of the polar grid lies on the side of its centre.
    let hidden_cells: Vec<usize> = (0..RINGS * SECTORS)
        .filter(|&c| {
            let (ring, sector) = (c / SECTORS, c % SECTORS);
            let radius = ((ring as f32 + 0.5) / RINGS as f32).sqrt() * front.radius;
            let angle = (sector as f32 + 0.5) / SECTORS as f32 * std::f32::consts::TAU;
            (front.center + (frame.s * angle.cos() + frame.t * angle.sin()) * radius).x < 0.0
        })
        .collect();
    assert_eq!(hidden_cells.len(), RINGS * SECTORS / 2, "the screen's edge runs between sectors");
    let hidden: f32 = hidden_cells.iter().map(|&c| grid.cell_probability(c)).sum();
    println!("{hidden:.3} of the best pair's aimed paths go to the hidden half of the window");
    assert!(hidden < 0.3, "the hidden half keeps {hidden} of the aimed paths");
    assert_ghost_paths_bring_what_light_paths_bring(&scene);
}

#[test]
fn ghost_chains_spread_over_the_sensors_disc_keep_the_ghost_layers_light_with_less_noise_and_a_measured_blur() {
    // A disc of 6 pixels at the first phase on the 16 × 12 sensor, still 2 pixels after the 400 phases. Both
    // runs draw the same paths (same seed), so a disc that keeps each registration's light gives the same sum.
    let (spread, point) = (scene_with_glass_and(true, 3.0, 6.0, ""), scene(true));
    let (a, b) = (render(&spread, Method::Pbpm, 4, 40, 10), render(&point, Method::Pbpm, 4, 40, 10));
    let (sum_a, sum_b) = (image_sum(&a.ghost), image_sum(&b.ghost));
    println!(
        "ghost layer over the image: disc {:.6} ± {:.4}, own pixel {:.6} ± {:.4}",
        sum_a.0, sum_a.1, sum_b.0, sum_b.1
    );
    assert!((sum_a.0 - sum_b.0).abs() < 1e-5 * sum_b.0, "the disc changed the ghost light over the image");
    // Each pixel averages the chains of its disc: the per-pixel noise falls.
    let noise = |e: &PixelEstimates| e.ghost.iter().map(|g| g.1 * g.1).sum::<f64>();
    println!("Σ SEM² of the ghost layer: disc {:.4e}, own pixel {:.4e}", noise(&a), noise(&b));
    assert!(noise(&a) < 0.5 * noise(&b), "the disc did not lower the ghost layer's noise");
    // The disc's blur of the lamp's ghost shows in the blur the run measures: Σ blur² over the pixels, and the
    // spread that sum would have without blur.
    let blur = |scene: &Scene| {
        let mut engine = Engine::new(scene, crate::common::settings(scene, Method::Pbpm, 6));
        for _ in 0..100 {
            engine.run_phase();
        }
        let sums = engine.sums();
        let by_pixel = sums.blur2_by_pixel();
        let (blur, noise) = (0..sums.pixels.len()).map(&by_pixel).fold((0.0, 0.0), |(b, n), p| (b + p.0, n + p.1));
        (blur, noise.sqrt())
    };
    let (disc, own) = (blur(&spread), blur(&point));
    println!(
        "Σ blur² after 100 phases (and its spread without blur): disc {:.4e} ({:.1e}), own pixel {:.4e} ({:.1e})",
        disc.0, disc.1, own.0, own.1
    );
    assert!(disc.0 > 4.0 * disc.1, "the disc's blur does not stand out of its noise");
    assert!(disc.0 > 10.0 * own.0.max(own.1), "the disc's blur is not measured");
}
