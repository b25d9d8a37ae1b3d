//! Fresnel reflectance of smooth interfaces: between two dielectrics, and of a conductor with a complex index
//! of refraction η + i k.

use crate::color::Rgb;

/// Unpolarised Fresnel reflectance at a smooth interface for light arriving at cos θ_i from the medium of
/// index `eta_i` (1 under total internal reflection).
pub fn fresnel_dielectric(cos_i: f32, eta_i: f32, eta_t: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t = eta_i / eta_t * (1.0 - cos_i * cos_i).max(0.0).sqrt();
    if sin_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t * sin_t).max(0.0).sqrt();
    let r_parl = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    let r_perp = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Unpolarised Fresnel reflectance of a conductor of relative index η + i k (the metal's over the outside
/// medium's) for light arriving at cos θ_i, exact for complex indices (as in pbrt-v4 and Mitsuba 3).
pub fn fresnel_conductor(cos_i: f32, eta: f32, k: f32) -> f32 {
    let c = cos_i.clamp(0.0, 1.0) as f64;
    let (eta, k) = (eta as f64, k as f64);
    let c2 = c * c;
    let s2 = 1.0 - c2;
    let (eta2, k2) = (eta * eta, k * k);
    // a² + b² = |η̃² − sin²θ|, from which the s and p amplitudes follow.
    let t0 = eta2 - k2 - s2;
    let a2pb2 = (t0 * t0 + 4.0 * eta2 * k2).sqrt();
    let a = (0.5 * (a2pb2 + t0)).max(0.0).sqrt();
    let t1 = a2pb2 + c2;
    let t2 = 2.0 * c * a;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = c2 * a2pb2 + s2 * s2;
    let t4 = t2 * s2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    (0.5 * (rp + rs)) as f32
}

/// `fresnel_conductor` per colour channel.
pub fn fresnel_conductor_rgb(cos_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    Rgb::new(
        fresnel_conductor(cos_i, eta.x, k.x),
        fresnel_conductor(cos_i, eta.y, k.y),
        fresnel_conductor(cos_i, eta.z, k.z),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_at_normal_incidence_is_four_percent_for_glass() {
        assert!((fresnel_dielectric(1.0, 1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(1.0, 1.5, 1.0) - 0.04).abs() < 1e-6);
        assert_eq!(fresnel_dielectric(0.1, 1.5, 1.0), 1.0, "total internal reflection");
    }

    #[test]
    fn a_conductor_without_absorption_reflects_as_a_dielectric_and_normal_incidence_has_its_closed_form() {
        for cos in [1.0, 0.8, 0.5, 0.2, 0.05] {
            let d = fresnel_dielectric(cos, 1.0, 1.7);
            let c = fresnel_conductor(cos, 1.7, 0.0);
            assert!((d - c).abs() < 1e-5, "cos {cos}: dielectric {d}, conductor {c}");
        }
        // |(η − 1 + ik) / (η + 1 + ik)|² at normal incidence.
        let (eta, k) = (0.2f32, 3.9f32);
        let r0 = ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor(1.0, eta, k) - r0).abs() < 1e-5);
        assert!((fresnel_conductor(0.0, eta, k) - 1.0).abs() < 1e-5, "grazing incidence reflects all");
    }
}
