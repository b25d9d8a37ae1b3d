//! Every BSDF family against the same checks (`bsdfs/harness.rs`): sampled directions follow `pdf`
//! (chi-square), samples agree with `eval`/`pdf` per lobe class, reflection is reciprocal and refraction obeys
//! the adjoint rule, and no family returns more than it receives (the lossless smooth ones return all). Then
//! the properties of single families that the old material tests checked, the cut-out and two-sided
//! wrappers, and the named metals. docs/materials.md describes the families and their agreement with
//! Mitsuba 3.

#[path = "bsdfs/harness.rs"]
mod harness;

use glam::{Vec2, Vec3};
use harness::{chi_square, integrate, mean_sem, sample_and_check, wo, Rng};
use photonfarm::bsdf::conductor::ConductorFresnel;
use photonfarm::bsdf::fresnel::fresnel_dielectric;
use photonfarm::bsdf::microfacet::{Distribution, Microfacet};
use photonfarm::bsdf::plastic::{fresnel_diffuse_reflectance, Coat};
use photonfarm::bsdf::principled::PrincipledParams;
use photonfarm::bsdf::{
    Conductor, Dielectric, Diffuse, LobeFlags, Model, Plastic, Principled, Reflection, RoughDielectric, Scatter,
    ThinDielectric, Transport,
};
use photonfarm::color::Rgb;
use photonfarm::geometry::SurfaceHit;
use photonfarm::material::{Back, Material, Surface};
use photonfarm::spectrum::RefractiveIndex;
use photonfarm::texture::Texture;

/// Chi-square tests in this file, for the significance each must pass (Šidák's correction of 1% overall).
const TESTS: f64 = 200.0;
/// Samples per chi-square test.
const SAMPLES: u64 = 100_000;

/// A family with parameters, the directions it is checked from, and what its energy must satisfy.
struct Case {
    name: String,
    model: Model,
    wos: Vec<Vec3>,
    energy: Energy,
}

#[derive(Clone, Copy, PartialEq)]
enum Energy {
    /// Returns at most what it receives.
    Conserves,
    /// Returns exactly what it receives (every sample weighs 1 for light paths).
    Lossless,
}

fn case(name: impl Into<String>, model: Model, wos: &[Vec3]) -> Case {
    Case { name: name.into(), model, wos: wos.to_vec(), energy: Energy::Conserves }
}

/// A direction near the normal, an oblique one and a grazing one.
fn directions() -> [Vec3; 3] {
    [wo(0.25, 0.15, 0.95), wo(0.6, -0.3, 0.7), wo(-0.5, 0.85, 0.12)]
}

fn index(n: f32) -> RefractiveIndex {
    RefractiveIndex::constant(n)
}

fn conductors() -> Vec<Case> {
    let au = ConductorFresnel::named("Au").unwrap();
    let cu = ConductorFresnel::named("Cu").unwrap();
    let mut cases = Vec::new();
    for (d, ax, ay, fresnel, what) in [
        (Distribution::Ggx, 0.3, 0.3, au, "gold GGX 0.3"),
        (Distribution::Beckmann, 0.15, 0.15, cu, "copper Beckmann 0.15"),
        (Distribution::Ggx, 0.1, 0.4, ConductorFresnel::Perfect, "mirror GGX 0.1 × 0.4"),
        (Distribution::Beckmann, 0.5, 0.2, au, "gold Beckmann 0.5 × 0.2"),
    ] {
        let m = Conductor { fresnel, specular: Rgb::ONE, roughness: Some(Microfacet::new(d, ax, ay)) };
        cases.push(case(format!("rough conductor, {what}"), Model::Conductor(m), &directions()));
    }
    cases
}

fn rough_dielectrics() -> Vec<Case> {
    let mut cases = Vec::new();
    for (d, ax, ay) in
        [(Distribution::Ggx, 0.3, 0.3), (Distribution::Beckmann, 0.15, 0.15), (Distribution::Ggx, 0.1, 0.35)]
    {
        for (eta_o, eta_t, side) in [(1.0, 1.5, "outside"), (1.5, 1.0, "inside")] {
            let m = RoughDielectric {
                eta_o: index(eta_o),
                eta_t: index(eta_t),
                microfacet: Microfacet::new(d, ax, ay),
                specular_reflectance: Rgb::ONE,
                specular_transmittance: Rgb::ONE,
            };
            let name = format!("rough dielectric {d:?} {ax} × {ay}, from {side}");
            cases.push(case(name, Model::RoughDielectric(m), &directions()));
        }
    }
    cases
}

fn plastics() -> Vec<Case> {
    let mut cases = Vec::new();
    let red = Rgb::new(0.8, 0.2, 0.1);
    for (diffuse, nonlinear, eta, coat, what) in [
        (Rgb::splat(0.5), false, 1.49, Coat::Smooth, "smooth, Mitsuba's defaults"),
        (red, true, 1.49, Coat::Smooth, "smooth, red, nonlinear"),
        (
            Rgb::splat(0.5),
            false,
            1.49,
            Coat::rough(Distribution::Beckmann, 0.1, 1.49),
            "rough Beckmann 0.1 (coat passed)",
        ),
        (red, true, 1.49, Coat::rough(Distribution::Ggx, 0.4, 1.49), "rough GGX 0.4 (coat stored), red, nonlinear"),
        (Rgb::splat(0.9), false, 1.7, Coat::rough(Distribution::Ggx, 0.2, 1.7), "rough GGX 0.2, η 1.7"),
    ] {
        let p = Plastic::new(diffuse, Rgb::ONE, eta, nonlinear, coat);
        cases.push(case(format!("plastic, {what}"), Model::Plastic(p), &directions()));
    }
    cases
}

fn principled_cases() -> Vec<Case> {
    let base = PrincipledParams::default();
    let mut cases = Vec::new();
    let sets = [
        ("Mitsuba's defaults", base),
        (
            "metal, rough 0.3, anisotropic 0.5",
            PrincipledParams {
                base_color: Rgb::new(0.9, 0.6, 0.3),
                metallic: 0.8,
                roughness: 0.3,
                anisotropic: 0.5,
                ..base
            },
        ),
        (
            "glass, spec_trans 0.7, rough 0.4",
            PrincipledParams { base_color: Rgb::new(0.8, 0.9, 0.7), spec_trans: 0.7, roughness: 0.4, ..base },
        ),
        (
            "clearcoat, sheen, tints, flatness",
            PrincipledParams {
                base_color: Rgb::new(0.2, 0.5, 0.7),
                roughness: 0.6,
                clearcoat: 0.8,
                clearcoat_gloss: 0.1,
                sheen: 0.5,
                sheen_tint: 0.5,
                spec_tint: 0.5,
                flatness: 0.3,
                ..base
            },
        ),
        (
            "rough 0.8 (specular stored), transmitting",
            PrincipledParams { roughness: 0.8, spec_trans: 0.3, metallic: 0.1, ..base },
        ),
    ];
    for (what, p) in sets {
        cases.push(case(format!("principled, {what}"), Model::Principled(Principled::new(&p, false)), &directions()));
        if p.spec_trans > 0.0 {
            let inside = Model::Principled(Principled::new(&p, true));
            cases.push(case(format!("principled, {what}, from inside"), inside, &directions()));
        }
    }
    cases
}

fn diffuse_case() -> Vec<Case> {
    vec![case("diffuse 0.8", Model::Diffuse(Diffuse { reflectance: Rgb::splat(0.8) }), &directions())]
}

/// Runs every check on every case and direction; panics with all the failures.
fn check(cases: Vec<Case>) {
    let significance = 1.0 - 0.99f64.powf(1.0 / TESTS);
    let mut failures = Vec::new();
    for (k, c) in cases.iter().enumerate() {
        let s = c.model.scatter().unwrap();
        for (j, &wo) in c.wos.iter().enumerate() {
            let seed = 1000 * k as u64 + j as u64;
            let at = format!("{} from wo {wo}", c.name);
            let sampled = sample_and_check(s, wo, Transport::Importance, SAMPLES, seed);
            if sampled.worst > 2e-3 {
                failures.push(format!("{at}: {} (relative {:.2e})", sampled.worst_what, sampled.worst));
            }
            let radiance = sample_and_check(s, wo, Transport::Radiance, 4000, seed + 7);
            if radiance.worst > 2e-3 {
                failures.push(format!("{at}, radiance: {} ({:.2e})", radiance.worst_what, radiance.worst));
            }
            let integrals = integrate(s, wo, Transport::Importance, SAMPLES);
            let (p, what) = chi_square(&integrals, &sampled);
            println!("{at}: {what}");
            if p < significance {
                failures.push(format!("{at}: chi-square fails: {what}"));
            }
            // Energy for light paths (flux): what the samples weigh against the quadrature of f cos.
            let (quad_all, quad_stored) = (integrals.albedo, integrals.albedo_stored);
            let n = sampled.n;
            let (all, all_sem) = mean_sem(sampled.all, n);
            let (non_delta, nd_sem) = mean_sem(sampled.non_delta, n);
            let (stored, stored_sem) = mean_sem(sampled.stored, n);
            let tolerance = |sem: f64, q: f64| 5.0 * sem + 2e-3 + 3e-3 * q;
            println!(
                "    albedo {all:.4} ± {all_sem:.4}; non-delta sampled {non_delta:.4}, by quadrature {quad_all:.4}; \
                 stored sampled {stored:.4}, by quadrature {quad_stored:.4}"
            );
            if (non_delta - quad_all).abs() > tolerance(nd_sem, quad_all) {
                failures.push(format!("{at}: non-delta albedo sampled {non_delta} ± {nd_sem}, quadrature {quad_all}"));
            }
            if (stored - quad_stored).abs() > tolerance(stored_sem, quad_stored) {
                failures.push(format!("{at}: stored albedo sampled {stored} ± {stored_sem}, quadrature {quad_stored}"));
            }
            if all > 1.0 + 5.0 * all_sem + 2e-3 || quad_all > 1.0 + 3e-3 {
                failures
                    .push(format!("{at}: returns more than it receives: {all} ± {all_sem} (quadrature {quad_all})"));
            }
            if c.energy == Energy::Lossless && (all - 1.0).abs() > 1e-5 {
                failures.push(format!("{at}: a lossless family returns {all}"));
            }
        }
    }
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn rough_conductors_sample_their_pdf_agree_with_eval_and_conserve_energy() {
    check(conductors());
}

#[test]
fn rough_dielectrics_from_both_sides_sample_their_pdf_agree_with_eval_and_conserve_energy() {
    check(rough_dielectrics());
}

#[test]
fn plastics_sample_their_pdf_agree_with_eval_and_conserve_energy() {
    check(plastics());
}

#[test]
fn principled_surfaces_sample_their_pdf_agree_with_eval_and_conserve_energy() {
    check(principled_cases());
}

#[test]
fn diffuse_and_the_lossless_smooth_families_agree_and_the_lossless_ones_return_all() {
    let mut cases = diffuse_case();
    let lossless = [
        (
            "smooth dielectric from outside",
            Model::Dielectric(Dielectric { eta_o: index(1.0), eta_t: index(1.5), anti_reflection: false }),
        ),
        (
            "smooth dielectric from inside",
            Model::Dielectric(Dielectric { eta_o: index(1.5), eta_t: index(1.0), anti_reflection: false }),
        ),
        (
            "thin dielectric",
            Model::ThinDielectric(ThinDielectric {
                int_ior: index(1.5),
                ext_ior: index(1.0),
                specular_reflectance: Rgb::ONE,
                specular_transmittance: Rgb::ONE,
            }),
        ),
        ("perfect mirror", Model::Conductor(Conductor::mirror(Rgb::ONE))),
    ];
    for (name, model) in lossless {
        cases.push(Case { energy: Energy::Lossless, ..case(name, model, &directions()) });
    }
    check(cases);
}

/// Every case whose reflection lobes must be reciprocal.
fn reflecting_cases() -> Vec<Case> {
    let mut all = conductors();
    all.extend(rough_dielectrics());
    all.extend(plastics());
    all.extend(principled_cases());
    all.extend(diffuse_case());
    all
}

#[test]
fn reflection_is_reciprocal_in_every_family() {
    let mut rng = Rng::new(5);
    for c in reflecting_cases() {
        let s = c.model.scatter().unwrap();
        let mut worst = 0.0f32;
        for _ in 0..3000 {
            let (a, b) = (rng.direction(), rng.direction());
            let (a, b) = (Vec3::new(a.x, a.y, a.z.abs()), Vec3::new(b.x, b.y, b.z.abs()));
            for mode in [Transport::Radiance, Transport::Importance] {
                let (f, g) = (s.eval(a, b, mode, false), s.eval(b, a, mode, false));
                let d = (f - g).abs().max_element() / f.max_element().max(g.max_element()).max(1e-3);
                worst = worst.max(d);
            }
        }
        assert!(worst < 1e-3, "{}: f(wo, wi) and f(wi, wo) differ by {worst} relative", c.name);
    }
}

/// The transmitting cases seen from both sides: (name, from outside, from inside, η_outside / η_inside).
fn transmitting_pairs() -> Vec<(String, Model, Model, f32)> {
    let mut pairs = Vec::new();
    for (d, ax, ay) in
        [(Distribution::Ggx, 0.3, 0.3), (Distribution::Beckmann, 0.2, 0.2), (Distribution::Ggx, 0.1, 0.35)]
    {
        let side = |eta_o: f32, eta_t: f32| {
            Model::RoughDielectric(RoughDielectric {
                eta_o: index(eta_o),
                eta_t: index(eta_t),
                microfacet: Microfacet::new(d, ax, ay),
                specular_reflectance: Rgb::ONE,
                specular_transmittance: Rgb::ONE,
            })
        };
        pairs.push((format!("rough dielectric {d:?} {ax} × {ay}"), side(1.0, 1.5), side(1.5, 1.0), 1.0 / 1.5));
    }
    let p =
        PrincipledParams { spec_trans: 0.8, roughness: 0.4, base_color: Rgb::new(0.7, 0.8, 0.9), ..Default::default() };
    let eta = p.eta;
    pairs.push((
        "principled with spec_trans 0.8".into(),
        Model::Principled(Principled::new(&p, false)),
        Model::Principled(Principled::new(&p, true)),
        1.0 / eta,
    ));
    pairs
}

#[test]
fn refraction_obeys_the_adjoint_rule_between_radiance_and_importance() {
    let mut rng = Rng::new(9);
    let flip = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
    for (name, outside, inside, ratio) in transmitting_pairs() {
        let (a, b) = (outside.scatter().unwrap(), inside.scatter().unwrap());
        let (mut worst_adjoint, mut worst_scale, mut nonzero) = (0.0f32, 0.0f32, 0);
        for _ in 0..4000 {
            // wo outside (above), wi inside (below), where the BSDF samples it: random pairs rarely meet a
            // narrow refraction lobe.
            let u = rng.direction();
            let wo = Vec3::new(u.x, u.y, u.z.abs());
            let Some(smp) = a.sample(wo, rng.next_2d(), Transport::Radiance) else { continue };
            if smp.wi.z >= 0.0 {
                continue;
            }
            let wi = smp.wi;
            let radiance = a.eval(wo, wi, Transport::Radiance, false).x;
            let importance = a.eval(wo, wi, Transport::Importance, false).x;
            // The other side's local frame has z the other way: wi becomes its wo.
            let reverse = b.eval(flip(wi), flip(wo), Transport::Importance, false).x;
            if radiance > 0.0 {
                nonzero += 1;
            }
            let floor = radiance.max(reverse).max(1e-4);
            worst_adjoint = worst_adjoint.max((radiance - reverse).abs() / floor);
            // f_radiance = (η_o/η_t)² f_importance across the interface.
            worst_scale = worst_scale.max((radiance - ratio * ratio * importance).abs() / floor);
        }
        assert!(nonzero > 1000, "{name}: only {nonzero} transmitting pairs");
        assert!(worst_adjoint < 2e-3, "{name}: f_radiance(wo, wi) ≠ f_importance(wi, wo) by {worst_adjoint}");
        assert!(worst_scale < 2e-3, "{name}: f_radiance ≠ (η_o/η_t)² f_importance by {worst_scale}");
    }
}

#[test]
fn a_thin_pane_reflects_r_plus_its_inner_reflections_and_transmits_the_rest_from_both_sides() {
    let pane = ThinDielectric {
        int_ior: index(1.5),
        ext_ior: index(1.0),
        specular_reflectance: Rgb::ONE,
        specular_transmittance: Rgb::ONE,
    };
    for wo in directions() {
        let r = fresnel_dielectric(wo.z, 1.0, 1.5);
        let t = 1.0 - r;
        let expected = r + t * t * r / (1.0 - r * r);
        assert!((pane.reflectance(wo) - expected).abs() < 1e-6);
        let branches = pane.delta_branches(wo);
        assert_eq!(branches.len(), 2);
        let (reflected, transmitted) = (&branches[0], &branches[1]);
        assert!((reflected.1 - expected).abs() < 1e-6 && reflected.0.wi == Vec3::new(-wo.x, -wo.y, wo.z));
        assert!((transmitted.1 - (1.0 - expected)).abs() < 1e-6 && transmitted.0.wi == -wo);
        assert!(reflected.0.weight == Rgb::ONE && transmitted.0.weight == Rgb::ONE);
    }
    // A pane that is a surface of a scene scatters the same from behind.
    let m = Material::new(
        Surface::ThinDielectric {
            ior: index(1.5),
            ext_ior: index(1.0),
            specular_reflectance: Texture::grey(1.0),
            specular_transmittance: Texture::grey(1.0),
        },
        Back::Black,
        None,
    );
    let behind = m.bsdf(&flat_hit(Vec3::Z), Vec2::ZERO, -Vec3::Z);
    assert!(matches!(behind.model, Model::ThinDielectric(_)), "a pane has no black back");
}

#[test]
fn smooth_plastic_reflects_the_coats_fresnel_share_specularly_and_the_rest_diffusely() {
    let p = Plastic::new(Rgb::splat(0.5), Rgb::ONE, 1.49, false, Coat::Smooth);
    let wo = wo(0.5, 0.0, 0.8);
    let f = fresnel_dielectric(wo.z, 1.0, 1.49);
    let n = 20_000;
    let (mut specular, mut diffuse) = (0.0f64, 0.0f64);
    for i in 0..n {
        let u = Vec2::new((i as f32 + 0.5) / n as f32, ((i * 7919) % n) as f32 / n as f32);
        let s = p.sample(wo, u, Transport::Importance).unwrap();
        if s.is_delta() {
            assert_eq!(s.wi, Vec3::new(-wo.x, -wo.y, wo.z));
            specular += s.weight.x as f64 / n as f64;
        } else {
            diffuse += s.weight.x as f64 / n as f64;
        }
    }
    assert!((specular - f as f64).abs() < 1e-3, "specular reflection {specular} ≠ F = {f}");
    // The diffuse part, with the coat's internal reflections summed: ρ / (1 − F_dr(1/η)) · (1 − F(θ_o)) / η²
    // · ∫ (1 − F(θ_i)) cos/π dω_i, the last being 1 − F_dr(η).
    let eta2 = 1.49f64 * 1.49;
    let expected = 0.5 / (1.0 - fresnel_diffuse_reflectance(1.0 / 1.49) as f64) * (1.0 - f as f64) / eta2
        * (1.0 - fresnel_diffuse_reflectance(1.49) as f64);
    assert!((diffuse - expected).abs() < 0.01 * expected, "diffuse {diffuse}, expected {expected}");
    assert_eq!(p.delta_branches(wo).len(), 1);
}

#[test]
fn rough_plastics_coat_tends_to_the_smooth_coat_as_it_smooths() {
    let smooth = Plastic::new(Rgb::splat(0.5), Rgb::ONE, 1.5, false, Coat::Smooth);
    let coat = Coat::rough(Distribution::Ggx, 0.002, 1.5);
    let rough = Plastic::new(Rgb::splat(0.5), Rgb::ONE, 1.5, false, coat);
    let (a, b) = (wo(0.3, 0.1, 0.9), wo(-0.5, 0.2, 0.7));
    let (fs, fr) = (smooth.eval(a, b, Transport::Radiance, false), rough.eval(a, b, Transport::Radiance, false));
    // The rough coat's internal albedo is Mitsuba's mean over 64 points of cos θ, which lies about 1.5% below
    // the smooth coat's F_dr; with that factor taken out, the two agree.
    let Coat::Rough { table, .. } = coat else { unreachable!() };
    let internal = (1.0 - fresnel_diffuse_reflectance(1.0 / 1.5)) / (1.0 - table.internal_reflectance);
    assert!((table.internal_reflectance - fresnel_diffuse_reflectance(1.0 / 1.5)).abs() < 0.012);
    let expected = fs * internal;
    assert!(
        (expected - fr).abs().max_element() < 2e-3 * fs.max_element(),
        "smooth {expected}, nearly smooth rough {fr}"
    );
}

fn flat_hit(n: Vec3) -> SurfaceHit {
    SurfaceHit { t: 1.0, p: Vec3::ZERO, ng: n, ns: n, object: 0, triangle: 0 }
}

fn glass(anti_reflection: bool) -> Material {
    Material::two_sided(Surface::Dielectric { ior: index(1.5), ext_ior: index(1.0), anti_reflection })
}

#[test]
fn refraction_obeys_snell_and_radiance_scales_by_eta_squared() {
    let hit = flat_hit(Vec3::Z);
    let wo = Vec3::new(0.5, 0.0, 0.75f32.sqrt());
    let bsdf = glass(false).bsdf(&hit, Vec2::ZERO, wo);
    // u.x = 0.999 selects transmission (F is small here).
    let s = bsdf.sample(wo, Vec2::new(0.999, 0.0), Transport::Radiance).unwrap();
    let sin_t = (s.wi.x * s.wi.x + s.wi.y * s.wi.y).sqrt();
    assert!((0.5 - 1.5 * sin_t).abs() < 1e-5);
    assert!(s.wi.z < 0.0 && s.wi.x < 0.0);
    assert!((s.weight.x - 1.0 / 2.25).abs() < 1e-5 && (s.radiance_scale - 1.0 / 2.25).abs() < 1e-6);
    let s = bsdf.sample(wo, Vec2::new(0.999, 0.0), Transport::Importance).unwrap();
    assert!((s.weight.x - 1.0).abs() < 1e-5);
}

#[test]
fn a_raised_reflection_probability_keeps_the_expected_reflected_and_transmitted_weights() {
    let hit = flat_hit(Vec3::Z);
    let m = glass(false);
    for (wo, f) in [(Vec3::Z, 0.04f32), (Vec3::new(0.8, 0.0, 0.6), fresnel_dielectric(0.6, 1.0, 1.5))] {
        let bsdf = m.bsdf(&hit, Vec2::ZERO, wo);
        for (mode, refract) in [(Transport::Importance, 1.0), (Transport::Radiance, 1.0 / 2.25)] {
            let n = 4000;
            let (mut reflected, mut transmitted, mut reflections) = (0.0f64, 0.0f64, 0);
            for i in 0..n {
                let u = Vec2::new((i as f32 + 0.5) / n as f32, 0.5);
                let s = bsdf.sample_reflecting(wo, u, mode, Reflection::AtLeast(0.3)).unwrap();
                if s.wi.z > 0.0 {
                    reflected += s.weight.x as f64 / n as f64;
                    reflections += 1;
                } else {
                    transmitted += s.weight.x as f64 / n as f64;
                }
            }
            assert_eq!(reflections, (0.3 * n as f32).round() as usize, "reflects with the raised probability");
            assert!((reflected - f as f64).abs() < 1e-3, "E[reflected weight] {reflected} ≠ F {f}");
            let t = (1.0 - f as f64) * refract;
            assert!((transmitted - t).abs() < 1e-3, "E[transmitted weight] {transmitted} ≠ {t}");
        }
    }
    // Total internal reflection stays certain, weight 1.
    let inside = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
    let bsdf = m.bsdf(&hit, Vec2::ZERO, inside);
    let s = bsdf.sample_reflecting(inside, Vec2::new(0.999, 0.0), Transport::Importance, Reflection::AtLeast(0.3));
    let s = s.unwrap();
    assert!(s.wi.z < 0.0 && s.weight == Rgb::ONE, "total internal reflection, weight 1");
    assert!(s.lobe.contains(LobeFlags::TOTAL_INTERNAL));
}

#[test]
fn a_dielectric_told_never_to_reflect_refracts_with_weight_one_minus_f_and_ends_at_total_internal_reflection() {
    let hit = flat_hit(Vec3::Z);
    let m = glass(false);
    let wo = Vec3::new(0.8, 0.0, 0.6);
    let f = fresnel_dielectric(0.6, 1.0, 1.5);
    let bsdf = m.bsdf(&hit, Vec2::ZERO, wo);
    for u in [0.0, 0.5, 0.999] {
        let s = bsdf.sample_reflecting(wo, Vec2::new(u, 0.5), Transport::Importance, Reflection::Never).unwrap();
        assert!(s.wi.z < 0.0, "refracts whatever u");
        assert!((s.weight.x - (1.0 - f)).abs() < 1e-5, "weight {} ≠ 1 − F = {}", s.weight.x, 1.0 - f);
    }
    let inside = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
    let bsdf = m.bsdf(&hit, Vec2::ZERO, inside);
    let s = bsdf.sample_reflecting(inside, Vec2::new(0.0, 0.5), Transport::Importance, Reflection::Never);
    assert!(s.is_none(), "total internal reflection leaves nothing to refract");
}

#[test]
fn anti_reflection_coating_refracts_everything_but_total_internal_reflection() {
    let hit = flat_hit(Vec3::Z);
    let m = glass(true);
    // u.x = 0 would pick reflection whenever F > 0.
    let s = m.bsdf(&hit, Vec2::ZERO, Vec3::Z).sample(Vec3::Z, Vec2::ZERO, Transport::Radiance).unwrap();
    assert!(s.wi.z < 0.0, "refracted into the glass");
    let inside = Vec3::new(0.9, 0.0, -(1.0f32 - 0.81).sqrt());
    let s = m.bsdf(&hit, Vec2::ZERO, inside).sample(inside, Vec2::new(0.999, 0.0), Transport::Radiance).unwrap();
    assert!(s.wi.z < 0.0, "reflected back inside");
}

#[test]
fn diffuse_sampling_stays_on_the_side_of_the_outgoing_direction() {
    let m = Material::two_sided(Surface::Diffuse { reflectance: Texture::grey(0.5) });
    let hit = flat_hit(Vec3::Z);
    let bsdf = m.bsdf(&hit, Vec2::ZERO, -Vec3::Z);
    for i in 0..64 {
        let u = Vec2::new((i as f32 + 0.5) / 64.0, ((i * 37 % 64) as f32 + 0.5) / 64.0);
        let s = bsdf.sample(-Vec3::Z, u, Transport::Radiance).unwrap();
        assert!(s.wi.z < 0.0);
        assert_eq!(s.weight, Rgb::splat(0.5));
    }
}

#[test]
fn coating_splits_energy_between_reflection_and_transmission() {
    let m = Material::two_sided(Surface::Coating { reflectance: Rgb::splat(0.25), transmittance: Rgb::splat(0.7) });
    let hit = flat_hit(Vec3::Z);
    let wo = Vec3::new(0.0, 0.6, 0.8);
    let bsdf = m.bsdf(&hit, Vec2::ZERO, wo);
    let n = 1000;
    let mut sum = Rgb::ZERO;
    for i in 0..n {
        sum += bsdf.sample(wo, Vec2::new((i as f32 + 0.5) / n as f32, 0.5), Transport::Radiance).unwrap().weight;
    }
    assert!(((sum / n as f32).x - 0.95).abs() < 1e-3);
}

#[test]
fn a_ghosts_dielectric_reflection_is_told_apart_from_a_refraction_and_a_mirror() {
    let hit = flat_hit(Vec3::Z);
    let wo = Vec3::new(0.3, 0.0, 0.95).normalize();
    let glass = glass(false).bsdf(&hit, Vec2::ZERO, wo);
    let reflection = glass.sample(wo, Vec2::new(0.0, 0.5), Transport::Radiance).unwrap();
    let refraction = glass.sample(wo, Vec2::new(0.999, 0.5), Transport::Radiance).unwrap();
    assert!(reflection.wi.z > 0.0 && refraction.wi.z < 0.0);
    assert!(glass.is_dielectric_reflection(&reflection));
    assert!(!glass.is_dielectric_reflection(&refraction));
    let mirror = Material::two_sided(Surface::Conductor {
        fresnel: ConductorFresnel::Perfect,
        specular: Texture::grey(1.0),
        roughness: None,
    })
    .bsdf(&hit, Vec2::ZERO, wo);
    let s = mirror.sample(wo, Vec2::new(0.0, 0.5), Transport::Radiance).unwrap();
    assert!(s.wi.z > 0.0 && !mirror.is_dielectric_reflection(&s), "a mirror's reflection is no ghost's");
    // Nor is a rough dielectric's or a pane's: ghosts reflect at smooth lens surfaces only.
    let pane = Material::two_sided(Surface::ThinDielectric {
        ior: index(1.5),
        ext_ior: index(1.0),
        specular_reflectance: Texture::grey(1.0),
        specular_transmittance: Texture::grey(1.0),
    })
    .bsdf(&hit, Vec2::ZERO, wo);
    let s = pane.sample(wo, Vec2::new(0.0, 0.5), Transport::Radiance).unwrap();
    assert!(s.wi.z > 0.0 && !pane.is_dielectric_reflection(&s));
}

#[test]
fn a_cut_out_passes_its_holes_share_straight_through_and_scales_the_rest() {
    let m = Material::new(Surface::Diffuse { reflectance: Texture::grey(0.6) }, Back::Same, Some(Texture::grey(0.3)));
    assert!(m.has_delta(), "a cut-out is a delta transmission");
    let hit = flat_hit(Vec3::Z);
    let (wo, wi) = (wo(0.2, 0.1, 0.9), wo(-0.3, 0.4, 0.8));
    let bsdf = m.bsdf(&hit, Vec2::ZERO, wo);
    assert!(bsdf.flags().contains(LobeFlags::SPECULAR | LobeFlags::TRANSMISSION) && bsdf.has_pass());
    assert_eq!(bsdf.lambertian(), None, "a cut-out's photons carry their BSDF");
    assert!((bsdf.eval(wo, wi, Transport::Radiance).x - 0.3 * 0.6 / std::f32::consts::PI).abs() < 1e-6);
    assert!((bsdf.pdf(wo, wi) - 0.3 * wi.z / std::f32::consts::PI).abs() < 1e-6);
    let n = 10_000;
    let (mut through, mut reflected) = (0, 0.0f64);
    for i in 0..n {
        let u = Vec2::new((i as f32 + 0.5) / n as f32, ((i * 7919) % n) as f32 / n as f32);
        let s = bsdf.sample(wo, u, Transport::Radiance).unwrap();
        if s.is_delta() {
            assert!(s.wi == -wo && s.weight == Rgb::ONE, "straight through with weight 1");
            through += 1;
        } else {
            // The surface's own sample keeps its weight and its density is scaled by the opacity.
            assert!((s.weight.x - 0.6).abs() < 1e-5 && (s.pdf - bsdf.pdf(wo, s.wi)).abs() < 1e-4);
            reflected += s.weight.x as f64 / n as f64;
        }
    }
    assert_eq!(through, 7000, "the holes take 1 − opacity of the samples");
    assert!((reflected - 0.3 * 0.6).abs() < 1e-3);
    let branches = bsdf.delta_branches(wo);
    assert_eq!(branches.len(), 1);
    assert!((branches[0].1 - 0.7).abs() < 1e-6);
}

#[test]
fn a_one_sided_surface_is_black_behind_and_a_two_sided_one_scatters_there_as_in_front() {
    let hit = flat_hit(Vec3::Z);
    let below = wo(0.1, 0.2, -0.9);
    let plastic = Surface::Plastic {
        diffuse_reflectance: Texture::grey(0.5),
        specular_reflectance: Texture::grey(1.0),
        eta: 1.49,
        nonlinear: false,
        coat: Coat::Smooth,
    };
    let one_sided = Material::new(plastic.clone(), Back::Black, None);
    let b = one_sided.bsdf(&hit, Vec2::ZERO, below);
    assert!(b.is_black() && b.sample(below, Vec2::splat(0.5), Transport::Radiance).is_none());
    let two_sided = Material::new(plastic, Back::Same, None);
    let (front, back) = (two_sided.bsdf(&hit, Vec2::ZERO, -below), two_sided.bsdf(&hit, Vec2::ZERO, below));
    let wi = wo(-0.4, 0.1, 0.8);
    let (f_front, f_back) = (front.eval(-below, wi, Transport::Radiance), back.eval(below, -wi, Transport::Radiance));
    assert!(f_front.x > 0.0 && (f_front - f_back).abs().max_element() < 1e-6, "front {f_front}, back {f_back}");
    let s = back.sample(below, Vec2::splat(0.7), Transport::Radiance).unwrap();
    assert!(s.wi.z < 0.0, "the back scatters to its own side");
    let other = Material::new(
        Surface::Diffuse { reflectance: Texture::grey(0.5) },
        Back::Other(Box::new(Surface::Diffuse { reflectance: Texture::grey(0.2) })),
        None,
    );
    assert_eq!(other.bsdf(&hit, Vec2::ZERO, below).lambertian(), Some(Rgb::splat(0.2)));
    assert_eq!(other.bsdf(&hit, Vec2::ZERO, -below).lambertian(), Some(Rgb::splat(0.5)));
}

#[test]
fn a_principled_surface_that_transmits_has_an_inside_and_one_that_does_not_is_one_sided() {
    use photonfarm::material::PrincipledSurface;
    let hit = flat_hit(Vec3::Z);
    let below = wo(0.1, 0.2, -0.9);
    let opaque = Material::new(Surface::Principled(Box::default()), Back::Black, None);
    assert!(opaque.bsdf(&hit, Vec2::ZERO, below).is_black());
    let glassy = PrincipledSurface { spec_trans: Texture::grey(0.5), ..Default::default() };
    let m = Material::new(Surface::Principled(Box::new(glassy)), Back::Black, None);
    let b = m.bsdf(&hit, Vec2::ZERO, below);
    match b.model {
        Model::Principled(p) => assert!(p.inside),
        other => panic!("the inside of a transmitting principled surface is {other:?}"),
    }
    assert!(b.flags().contains(LobeFlags::TRANSMISSION) && !b.flags().contains(LobeFlags::DIFFUSE));
}

#[test]
fn named_metals_resolve_and_an_unknown_name_lists_the_known_ones() {
    for name in ["Au", "Ag", "Cu", "Al", "Cr"] {
        assert!(matches!(ConductorFresnel::named(name), Ok(ConductorFresnel::Complex { .. })), "{name}");
    }
    assert_eq!(ConductorFresnel::named("none"), Ok(ConductorFresnel::Perfect));
    let err = ConductorFresnel::named("Gold").unwrap_err().to_string();
    assert!(err.contains("`Gold`") && err.contains("Au") && err.contains("Cr"), "{err}");
    // Gold reflects red more than blue at normal incidence.
    let r = ConductorFresnel::named("Au").unwrap().at(1.0);
    assert!(r.x > 0.9 && r.z < 0.4, "{r}");
}

#[test]
fn the_chi_square_tail_and_gamma_function_have_their_known_values() {
    // Q(k/2, x/2) is the chi-square tail: for 10 degrees of freedom P(χ² > 18.307) = 0.05.
    assert!((harness::gamma_q(5.0, 18.307 / 2.0) - 0.05).abs() < 1e-4);
    assert!((harness::gamma_q(50.0, 124.342 / 2.0) - 0.05).abs() < 2e-4, "100 degrees of freedom");
    assert!((harness::ln_gamma(5.0) - 24.0f64.ln()).abs() < 1e-12);
    // A sampler that draws the wrong lobe width fails the test.
    let wrong = RoughDielectric {
        eta_o: index(1.0),
        eta_t: index(1.5),
        microfacet: Microfacet::new(Distribution::Ggx, 0.3, 0.3),
        specular_reflectance: Rgb::ONE,
        specular_transmittance: Rgb::ONE,
    };
    let right = RoughDielectric { microfacet: Microfacet::new(Distribution::Ggx, 0.33, 0.33), ..wrong };
    let wo = wo(0.3, 0.0, 0.9);
    let sampled = sample_and_check(&right, wo, Transport::Importance, SAMPLES, 3);
    let (p, what) = chi_square(&integrate(&wrong, wo, Transport::Importance, SAMPLES), &sampled);
    assert!(p < 1e-6, "samples of α = 0.33 pass against the pdf of α = 0.3: {what}");
}
