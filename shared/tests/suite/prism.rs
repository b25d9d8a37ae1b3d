//! The dispersive prism (`scenes/prism.toml`): each wavelength leaves the prism at the deviation Snell's law
//! gives with the glass's dispersion, and the rendered spectrum's colours land where those deviations put
//! them. `cargo test --release -p photonfarm --test suite prism:: -- --nocapture` prints the measured numbers.

use glam::{Vec2, Vec3};
use photonfarm::bsdf::fresnel::fresnel_dielectric;
use photonfarm::bsdf::{Model, Transport};
use photonfarm::geometry::{ray::offset_origin, Ray};
use photonfarm::render::{Engine, Method};
use photonfarm::scene::Scene;
use photonfarm::spectrum::{rgb_matching, Dispersive, Wavelength, LAMBDA_MAX, LAMBDA_MIN};

/// The scene's glass as its file states it: N-SF11, n_d and Abbe number V_d.
const N_D: f64 = 1.78472;
const ABBE: f64 = 25.68;
/// The prism's apex angle.
const APEX_DEG: f64 = 60.0;

/// The spot light's position and direction in the scene file: the beam's central ray.
const LIGHT: Vec3 = Vec3::new(-0.527206, -0.285019, 0.0);
const BEAM: Vec3 = Vec3::new(0.83701, 0.54720, 0.0);

/// Cauchy's law through n_d with the Abbe number, computed here from the glass data, independently of the
/// renderer: n(λ) = A + B/λ², V_d = (n_d − 1)/(n_F − n_C).
fn cauchy_index(nm: f64) -> f64 {
    let (d, f, c) = (0.58756f64, 0.48613f64, 0.65627f64);
    let b = (N_D - 1.0) / (ABBE * (1.0 / (f * f) - 1.0 / (c * c)));
    let a = N_D - b / (d * d);
    let um = nm * 1e-3;
    a + b / (um * um)
}

/// The central ray followed through the scene at one wavelength, always refracting: the directions it leaves
/// each surface with, and where it meets the screen.
struct Traced {
    entry_normal: Vec3,
    incoming: Vec3,
    outgoing: Vec3,
    screen: Vec3,
    /// Fraction of the flux transmitted by both faces (Fresnel).
    transmitted: f64,
}

fn trace_central_ray(scene: &Scene, nm: f32) -> Traced {
    let w = Wavelength::with_pdf(nm, 1.0);
    let mut ray = Ray::new(LIGHT, BEAM.normalize());
    let mut transmitted = 1.0;
    let mut entry_normal = Vec3::ZERO;
    for surface in 0..2 {
        let hit = scene.geometry.intersect(&ray).expect("the beam meets the prism");
        let wo = -ray.direction;
        let m = scene.bsdf(&hit, wo).at_wavelength(&w);
        let Model::Dielectric(d) = m.model else { panic!("the beam's first two surfaces are the prism") };
        transmitted *= 1.0 - fresnel_dielectric(wo.dot(hit.ng).abs(), d.eta_o.d, d.eta_t.d) as f64;
        if surface == 0 {
            entry_normal = hit.ng;
        }
        // u = 1⁻ picks refraction whenever some light is transmitted.
        let s = m.sample(wo, Vec2::new(0.999_999, 0.0), Transport::Importance).expect("refracts");
        ray = Ray::new(offset_origin(hit.p, hit.ng, s.wi), s.wi);
    }
    let screen = scene.geometry.intersect(&ray).expect("the beam reaches the screen").p;
    Traced { entry_normal, incoming: BEAM.normalize(), outgoing: ray.direction, screen, transmitted }
}

/// Where on the screen (height y) each pixel centre looks; None for pixels that miss it.
fn screen_heights(scene: &Scene) -> Vec<Option<f64>> {
    let cam = &scene.camera;
    (0..cam.pixel_count())
        .map(|p| {
            let (x, y) = (p as u32 % cam.width, p as u32 / cam.width);
            let r = cam.generate_ray(x, y, Vec2::splat(0.5), Vec2::splat(0.5)).ray;
            scene.geometry.intersect(&r).filter(|h| h.p.x > 0.45).map(|h| h.p.y as f64)
        })
        .collect()
}

fn angle_deg(a: Vec3, b: Vec3) -> f64 {
    (a.normalize().dot(b.normalize()) as f64).clamp(-1.0, 1.0).acos().to_degrees()
}

#[test]
fn prism_deviation_per_wavelength_matches_snell_with_the_glass_dispersion() {
    let scene = crate::common::shipped("prism.toml");
    assert!(scene.is_spectral(), "a glass with an Abbe number makes the scene spectral");
    let mut previous = f64::NEG_INFINITY;
    for nm in [400.0f32, 450.0, 486.13, 500.0, 550.0, 587.56, 600.0, 656.27, 700.0, 750.0] {
        let t = trace_central_ray(&scene, nm);
        let traced = angle_deg(t.incoming, t.outgoing);
        // Snell at both faces of a prism of apex A: sin θ₁ = n sin θ₂, θ₃ = A − θ₂, n sin θ₃ = sin θ₄,
        // deviation δ = θ₁ + θ₄ − A.
        let n = cauchy_index(nm as f64);
        let theta1 = angle_deg(-t.incoming, t.entry_normal).to_radians();
        let theta2 = (theta1.sin() / n).asin();
        let theta3 = APEX_DEG.to_radians() - theta2;
        let theta4 = (n * theta3.sin()).asin();
        let snell = (theta1 + theta4).to_degrees() - APEX_DEG;
        println!("{nm:7.2} nm: n = {n:.5}, deviation traced {traced:.4}°, Snell {snell:.4}°");
        assert!((traced - snell).abs() < 0.01, "at {nm} nm the prism deviates by {traced}°, Snell says {snell}°");
        // Normal dispersion: shorter wavelengths bend more.
        assert!(-traced > previous, "deviation must fall with wavelength");
        previous = -traced;
    }
    // At the d line the beam passes at minimum deviation, as the scene file designs it: 2θ₁ − A = 66.34°.
    let d = angle_deg(BEAM, trace_central_ray(&scene, 587.56).outgoing);
    assert!((d - 66.34).abs() < 0.02, "deviation at the d line {d}°");
}

#[test]
fn rendered_spectrum_puts_each_colour_where_snell_sends_its_wavelengths() {
    let scene = crate::common::shipped("prism.toml");
    let cam = &scene.camera;
    let pixel_y = screen_heights(&scene);

    // Prediction: each channel's centroid is the spectrum's height averaged with that channel's matching
    // function and the prism's transmission (the light is equal-energy white, the screen grey).
    let mut num = [0.0f64; 3];
    let mut den = [0.0f64; 3];
    let mut nm = LAMBDA_MIN + 0.5;
    while nm < LAMBDA_MAX {
        let t = trace_central_ray(&scene, nm);
        let rgb = rgb_matching(nm);
        for c in 0..3 {
            let w = rgb[c] as f64 * t.transmitted;
            num[c] += w * t.screen.y as f64;
            den[c] += w;
        }
        nm += 1.0;
    }
    let predicted: Vec<f64> = (0..3).map(|c| num[c] / den[c]).collect();

    // The rendering, in batches of phases: the spread of the batches' centroids gives their standard error.
    let mut engine = Engine::new(&scene, crate::common::settings(&scene, Method::Pbpm, 11));
    let (batches, per_batch) = (8, 60);
    let mut centroids = vec![Vec::new(); 3];
    let mut previous = vec![[0.0f64; 3]; cam.pixel_count()];
    for batch in 1..=batches {
        for _ in 0..per_batch {
            engine.run_phase();
        }
        // This batch's phases alone: running sums minus the previous batch's.
        let sums = engine.sums();
        let mut m = [0.0f64; 3];
        let mut w = [0.0f64; 3];
        for (p, y) in pixel_y.iter().enumerate() {
            let total = sums.mean_total(p).map(|v| v * (batch * per_batch) as f64);
            let this = [total[0] - previous[p][0], total[1] - previous[p][1], total[2] - previous[p][2]];
            previous[p] = total;
            if let Some(y) = y {
                for c in 0..3 {
                    m[c] += this[c] * y;
                    w[c] += this[c];
                }
            }
        }
        for c in 0..3 {
            centroids[c].push(m[c] / w[c]);
        }
    }
    // A quarter of a pixel's footprint on the screen (4.4 mm) for what the prediction leaves out: the beam's
    // cone, pixel sampling and the photons' gather radius smear the spectrum almost, but not exactly,
    // symmetrically.
    let systematic = 1.1e-3;
    for (c, name) in ["red", "green", "blue"].iter().enumerate() {
        let (mean, sem) = crate::common::mean_sem(&centroids[c]);
        println!(
            "{name}: centroid at y = {:.2} mm (SEM {:.2} mm), predicted {:.2} mm",
            mean * 1e3,
            sem * 1e3,
            predicted[c] * 1e3
        );
        assert!(
            (mean - predicted[c]).abs() < 4.0 * sem + systematic,
            "{name} lands at {mean} m, Snell's law puts it at {} m",
            predicted[c]
        );
    }
    // Red is deviated least (highest on the screen), blue most.
    let (r, g, b) = (
        crate::common::mean_sem(&centroids[0]).0,
        crate::common::mean_sem(&centroids[1]).0,
        crate::common::mean_sem(&centroids[2]).0,
    );
    assert!(r > g && g > b, "spectrum order red {r}, green {g}, blue {b}");
}

#[test]
fn spectral_output_bands_each_land_where_snell_sends_their_wavelengths() {
    let scene = crate::common::shipped("prism.toml");
    let bands = 8u32;
    let mut settings = crate::common::settings(&scene, Method::Pbpm, 5);
    settings.spectral_bands = bands;
    let mut engine = Engine::new(&scene, settings);
    for _ in 0..400 {
        engine.run_phase();
    }
    let sums = engine.sums();
    let pixel_y = screen_heights(&scene);
    let width = (LAMBDA_MAX - LAMBDA_MIN) / bands as f32;
    let mut previous = f64::NEG_INFINITY;
    for b in 0..bands {
        let name = photonfarm::spectrum::band_name(b, bands);
        let (mut m, mut w) = (0.0, 0.0);
        for (p, y) in pixel_y.iter().enumerate() {
            let v = sums.aux_mean(p, &name).expect("a layer per band")[0];
            assert!(v.is_finite() && v >= 0.0, "{name}: pixel {p} reads {v}");
            if let Some(y) = y {
                m += v * y;
                w += v;
            }
        }
        let centroid = m / w;
        let (lo, hi) = (LAMBDA_MIN + b as f32 * width, LAMBDA_MIN + (b + 1) as f32 * width);
        let (y_lo, y_hi) =
            (trace_central_ray(&scene, lo).screen.y as f64, trace_central_ray(&scene, hi).screen.y as f64);
        println!(
            "{name}: centroid {:.2} mm, Snell puts the band at {:.2} … {:.2} mm",
            centroid * 1e3,
            y_lo * 1e3,
            y_hi * 1e3
        );
        // Within the band's own spread on the screen, and a pixel's footprint for the beam's width.
        let slack = 4.4e-3;
        assert!(
            centroid < y_hi.max(y_lo) + slack && centroid > y_hi.min(y_lo) - slack,
            "{name} lands at {centroid} m, outside {y_lo} … {y_hi} m"
        );
        // Longer wavelengths are deviated less: higher on the screen.
        assert!(centroid > previous, "{name} is not above the band before it");
        previous = centroid;
    }
}
