//! The layer partition (docs/estimator.md, "Layers") counts every light path exactly once: on a scene where all four layers
//! are non-zero, PBPM converges to the path tracer, layer by layer and in total.

use crate::common::{scene, settings};
use photonfarm::accumulation::relative_rmse;
use photonfarm::color::luminance_f64;
use photonfarm::integrator::Layer;
use photonfarm::render::images::total_image;
use photonfarm::render::{Engine, Method};

/// A Cornell box with a large ceiling light, a glass sphere (caustic, and lights seen through glass) and a
/// mirror box (caustic by reflection).
const SCENE: &str = r#"
[render]
max_depth = 10
[camera]
position = [0.278, 0.273, -0.8]
look_at = [0.278, 0.273, 0.0]
fov_y_deg = 39.3
width = 32
height = 32
[materials.white]
type = "diffuse"
albedo = [0.8, 0.8, 0.8]
[materials.red]
type = "diffuse"
albedo = [0.6, 0.1, 0.1]
[materials.green]
type = "diffuse"
albedo = [0.1, 0.6, 0.1]
[materials.glass]
type = "dielectric"
ior = 1.5
[materials.mirror]
type = "mirror"
reflectance = [0.9, 0.9, 0.9]
[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]
[[objects]]
mesh = "cornell/floor.obj"
material = "white"
[[objects]]
mesh = "cornell/ceiling.obj"
material = "white"
[[objects]]
mesh = "cornell/backwall.obj"
material = "white"
[[objects]]
mesh = "cornell/leftwall.obj"
material = "red"
[[objects]]
mesh = "cornell/rightwall.obj"
material = "green"
[[objects]]
mesh = "cornell/tallbox.obj"
material = "mirror"
[[objects]]
material = "glass"
sphere = { center = [0.17, 0.1, 0.2], radius = 0.1 }
[[objects]]
material = "black"
emission = [4.0, 4.0, 4.0]
quad = { corner = [0.128, 0.548, 0.142], edge1 = [0.3, 0.0, 0.0], edge2 = [0.0, 0.0, 0.275] }
"#;

#[test]
fn pbpm_total_converges_to_the_path_tracer_when_all_four_layers_are_lit() {
    check_partition(&scene(SCENE), 1500, 6000);
}

#[test]
fn with_a_dispersive_sphere_pbpm_and_the_path_tracer_converge_to_the_same_spectral_image() {
    // Dense flint: the sphere's caustic and the light seen through it are spectral (one wavelength per PBPM
    // phase, one per path tracer path); the rest of the image stays RGB. Both estimators must agree per layer
    // and per colour channel.
    let sc = scene(&SCENE.replace("ior = 1.5", "ior = 1.5\nabbe = 30.0"));
    assert!(sc.is_spectral());
    check_partition(&sc, 2000, 8000);
}

#[test]
fn with_glossy_vertices_pbpm_and_the_path_tracer_converge_layer_by_layer() {
    // The mirror box becomes rough aluminium whose lobe is stored (camera paths store backward photons on it),
    // a rough glass sphere's lobes are passed (paths sample through them), and a rough plastic sphere mixes
    // both classes: a stored base under a passed coat. The smooth glass sphere keeps the caustic layer lit.
    let glossy = SCENE.replace(
        "type = \"mirror\"\nreflectance = [0.9, 0.9, 0.9]",
        "type = \"conductor\"\nmaterial = \"Al\"\nalpha = 0.4\ndistribution = \"ggx\"",
    ) + "[materials.rough_glass]\ntype = \"dielectric\"\nior = 1.5\nalpha = 0.1\n\
         [materials.plastic]\ntype = \"plastic\"\ndiffuse_reflectance = [0.2, 0.3, 0.6]\nalpha = 0.1\n\
         [[objects]]\nmaterial = \"rough_glass\"\nsphere = { center = [0.42, 0.08, 0.12], radius = 0.07 }\n\
         [[objects]]\nmaterial = \"plastic\"\nsphere = { center = [0.1, 0.3, 0.1], radius = 0.07 }\n";
    let sc = scene(&glossy);
    assert!(sc.materials.iter().any(|m| matches!(m.front, photonfarm::material::Surface::RoughDielectric { .. })));
    check_partition(&sc, 1500, 6000);
}

fn check_partition(sc: &photonfarm::scene::Scene, pbpm_phases: usize, path_phases: usize) {
    // Two independent single-threaded engines, run side by side.
    let render = |method, seed, phases| {
        let mut engine = Engine::new(sc, settings(sc, method, seed));
        for _ in 0..phases {
            engine.run_phase();
        }
        engine.sums().clone()
    };
    let (pbpm, path) = std::thread::scope(|s| {
        let pbpm = s.spawn(|| render(Method::Pbpm, 1, pbpm_phases));
        let path = render(Method::Path, 2, path_phases);
        (pbpm.join().unwrap(), path)
    });
    let (a, b) = (&pbpm, &path);
    let pixels = a.pixels.len();
    for layer in Layer::ALL {
        let mean = |s: &photonfarm::accumulation::Accumulator| {
            (0..pixels).map(|i| luminance_f64(s.mean(i, layer))).sum::<f64>() / pixels as f64
        };
        let (ma, mb) = (mean(a), mean(b));
        assert!(mb > 0.0, "layer {} is zero in the path tracer: the test scene must light every layer", layer.name());
        eprintln!("{:>15}: PBPM {ma:.5}  path {mb:.5}  ratio {:.4}", layer.name(), ma / mb);
        // Camera-side layers are unbiased; gathered layers carry the density-estimation bias of this coarse
        // 32×32 image's large photon radius (light lost at corners), a few per cent.
        let tolerance = if matches!(layer, Layer::VisibleLights | Layer::Direct) { 0.01 } else { 0.05 };
        assert!((ma / mb - 1.0).abs() < tolerance, "layer {}: PBPM {ma} vs path {mb}", layer.name());
        for c in 0..3 {
            let channel = |s: &photonfarm::accumulation::Accumulator| {
                (0..pixels).map(|i| s.mean(i, layer)[c]).sum::<f64>() / pixels as f64
            };
            let (ca, cb) = (channel(a), channel(b));
            assert!(
                (ca / cb - 1.0).abs() < tolerance * 2.0,
                "layer {} channel {c}: PBPM {ca} vs path {cb}",
                layer.name()
            );
        }
    }
    let rmse = relative_rmse(&total_image(a), &total_image(b), |_| true);
    let all = photonfarm::accumulation::LitMask::none(a.width, a.height);
    let e = a.error(&all);
    let f = b.error(&all);
    eprintln!("relative RMSE {rmse:.4}; δ PBPM {:.4}, δ path {:.4}", e.delta_all, f.delta_all);
    assert!(rmse < 0.02, "PBPM and the path tracer differ by {:.2}% relative RMSE", 100.0 * rmse);
}

#[test]
fn the_first_diffuse_vertex_s_direct_light_is_the_same_estimator_whatever_the_backward_depth() {
    // A path that ends at its first diffuse vertex still traces its BSDF ray to find the emitter it hits, so
    // that next-event estimation keeps its multiple-importance partner (eq. 5). With the same seed, both depths
    // draw the same numbers up to that ray: every pixel's direct layer must be the same.
    let sc = scene(SCENE);
    let direct = |depth| {
        let mut s = settings(&sc, Method::Pbpm, 5);
        s.backward_diffuse_depth = depth;
        let mut engine = Engine::new(&sc, s);
        for _ in 0..20 {
            engine.run_phase();
        }
        let sums = engine.sums();
        (0..sums.pixels.len()).map(|i| luminance_f64(sums.mean(i, Layer::Direct))).collect::<Vec<_>>()
    };
    let (one, two) = (direct(1), direct(2));
    let worst = one.iter().zip(&two).map(|(a, b)| (a - b).abs() / b.abs().max(1e-12)).fold(0.0, f64::max);
    assert!(two.iter().sum::<f64>() > 0.0, "the test scene's direct layer is dark");
    assert!(worst < 1e-9, "a pixel's direct light differs by {:.3e} (relative) between depths 1 and 2", worst);
}
