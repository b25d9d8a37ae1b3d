//! The lit-pixel mask is decided before the render from the scene alone: a pixel that sees a light through
//! glass is lit from the first phase on, whatever its samples, and the mask does not depend on the run.

use crate::common::{scene, settings};
use photonfarm::accumulation::LitMask;
use photonfarm::image_io::exr_file::{find_layer, read_exr};
use photonfarm::integrator::Layer;
use photonfarm::render::{Engine, Method};

/// A quad light in front of a diffuse wall, seen directly in the right half of the image and through a 10 cm
/// glass slab in the left half.
const LIGHT_BEHIND_GLASS: &str = r#"
[camera]
type = "pinhole"
position = [0.0, 0.0, 2.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 40
width = 32
height = 32

[materials.wall]
type = "diffuse"
albedo = [0.5, 0.5, 0.5]

[materials.glass]
type = "dielectric"
ior = 1.5

[materials.black]
type = "diffuse"
albedo = [0.0, 0.0, 0.0]

[[objects]]
name = "wall"
material = "wall"
quad = { corner = [-3.0, -3.0, -1.5], edge1 = [6.0, 0.0, 0.0], edge2 = [0.0, 6.0, 0.0] }

[[objects]]
name = "light"
material = "black"
emission = [5.0, 5.0, 5.0]
quad = { corner = [-0.3, -0.2, -1.0], edge1 = [0.6, 0.0, 0.0], edge2 = [0.0, 0.4, 0.0] }

[[objects]]
name = "slab"
material = "glass"
box = { min = [-3.0, -3.0, 0.5], max = [0.0, 3.0, 0.6] }
"#;

#[test]
fn a_pixel_that_sees_the_light_through_glass_is_lit_from_the_start_and_the_mask_holds_only_lit_pixels() {
    let sc = scene(LIGHT_BEHIND_GLASS);
    let s = settings(&sc, Method::Pbpm, 3);
    let mask = LitMask::of_scene(&sc, s.max_depth);
    let (w, h) = (sc.camera.width as usize, sc.camera.height as usize);
    let lit_in = |columns: std::ops::Range<usize>| {
        (0..h).flat_map(|y| columns.clone().map(move |x| y * w + x)).filter(|&i| mask.is_lit(i)).count()
    };
    let (through_glass, direct) = (lit_in(0..w / 2 - 1), lit_in(w / 2 + 1..w));
    eprintln!("lit pixels: {through_glass} through the slab, {direct} directly, {} in all", mask.lit_count());
    assert!(through_glass >= 20 && direct >= 20, "{through_glass} through glass, {direct} direct");

    // Rendered, the mask's pixels are those whose visible-lights layer holds light: none is lit without it,
    // and every pixel that saw the light in most of its phases is in the mask.
    let mut engine = Engine::new(&sc, s);
    let phases = 32;
    let mut seen = vec![0u32; w * h];
    for _ in 0..phases {
        let before: Vec<f64> = engine.sums().pixels.iter().map(|p| p.sum[Layer::VisibleLights as usize][1]).collect();
        engine.run_phase();
        for (i, p) in engine.sums().pixels.iter().enumerate() {
            seen[i] += (p.sum[Layer::VisibleLights as usize][1] > before[i]) as u32;
        }
    }
    let seen_near = |i: usize| {
        let (x, y) = (i % w, i / w);
        (y.saturating_sub(1)..(y + 2).min(h))
            .any(|ny| (x.saturating_sub(1)..(x + 2).min(w)).any(|nx| seen[ny * w + nx] > 0))
    };
    for (i, &seen) in seen.iter().enumerate() {
        if mask.is_lit(i) {
            assert!(
                seen_near(i),
                "pixel {i} is in the mask but neither it nor a neighbour saw the light in {phases} phases"
            );
        }
        if seen > phases / 2 {
            assert!(mask.is_lit(i), "pixel {i} saw the light in {seen} of {phases} phases but is not in the mask");
        }
    }
}

#[test]
fn the_mask_depends_on_the_scene_alone() {
    let sc = scene(LIGHT_BEHIND_GLASS);
    let a = LitMask::of_scene(&sc, 12);
    let b = LitMask::of_scene(&sc, 12);
    assert_eq!(a, b);
    assert!(a.lit_count() > 0);
    // Without specular segments to follow past the first hit only the directly seen light is left.
    let direct_only = LitMask::of_scene(&sc, 1);
    assert!(direct_only.lit_count() < a.lit_count());
}

/// How the mask compares with the pixels where the shipped path-traced reference's `visible_lights` layer holds
/// light.
struct Comparison {
    /// Lit pixels of the mask.
    mask: usize,
    /// The reference's lit pixels, and how many of them the mask holds.
    reference: usize,
    found: usize,
    /// The reference's lit pixels with their neighbours (as the mask grows its own), and how many of the mask's
    /// pixels lie among them.
    grown: usize,
    mask_in_grown: usize,
}

fn against_reference(scene_file: &str, reference_file: &str) -> Comparison {
    let sc = crate::common::shipped(scene_file);
    let mask = LitMask::of_scene(&sc, settings(&sc, Method::Pbpm, 1).max_depth);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/references").join(reference_file);
    let layers = read_exr(&path).unwrap();
    let visible = find_layer(&layers, &path, "visible_lights").unwrap();
    let seen: Vec<bool> = visible.rgb.iter().map(|p| p.iter().any(|&c| c > 0.0)).collect();
    let seen = LitMask::from_flags(sc.camera.width, sc.camera.height, seen, 0);
    let grown = seen.clone().with_neighbours_lit();
    let n = seen.len();
    let c = Comparison {
        mask: mask.lit_count() as usize,
        reference: seen.lit_count() as usize,
        found: (0..n).filter(|&i| seen.is_lit(i) && mask.is_lit(i)).count(),
        grown: grown.lit_count() as usize,
        mask_in_grown: (0..n).filter(|&i| grown.is_lit(i) && mask.is_lit(i)).count(),
    };
    eprintln!(
        "{scene_file}: {} lit in the mask; the reference's {} lit pixels: {} found; grown, {} of which {} in the mask",
        c.mask, c.reference, c.found, c.grown, c.mask_in_grown
    );
    c
}

#[test]
fn the_mask_finds_the_pixels_where_the_path_traced_reference_sees_a_light_on_cornell_and_through_the_caustic_sphere() {
    // The reference traced thousands of samples per pixel: every pixel that sees the light has its light.
    let c = against_reference("cornell.toml", "cornell-path.exr");
    assert_eq!(
        (c.found, c.mask, c.mask_in_grown),
        (c.reference, c.grown, c.grown),
        "the Cornell box's light, seen directly"
    );
    // Through the glass sphere of `caustic`, some pixels see the light only after internal reflections.
    let c = against_reference("caustic.toml", "caustic-path.exr");
    assert!(
        c.found as f64 >= 0.9 * c.reference as f64,
        "{} of the reference's {} lit pixels found",
        c.found,
        c.reference
    );
    assert!(
        c.mask - c.mask_in_grown <= c.reference / 10,
        "{} lit pixels far from any the reference saw lit",
        c.mask - c.mask_in_grown
    );
}
