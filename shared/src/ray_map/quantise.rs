//! The compact encodings of a vertex's normal (octahedral, two 16-bit numbers) and of a colour (RGB9E5, three
//! 9-bit mantissas with a shared exponent): 4 bytes each instead of 12.

use glam::{Vec2, Vec3};

/// A unit vector as two signed 16-bit octahedral coordinates (error below 0.01°); zero stays zero.
pub fn encode_normal(n: Vec3) -> u32 {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if l1 <= 0.0 || !l1.is_finite() {
        return 0;
    }
    let p = Vec2::new(n.x, n.y) / l1;
    let p = if n.z < 0.0 { Vec2::new((1.0 - p.y.abs()) * p.x.signum(), (1.0 - p.x.abs()) * p.y.signum()) } else { p };
    let q = |v: f32| ((v.clamp(-1.0, 1.0) * 32767.0).round() as i16) as u16 as u32;
    q(p.x) | q(p.y) << 16
}

/// The unit vector of `encode_normal` (zero for zero).
pub fn decode_normal(bits: u32) -> Vec3 {
    if bits == 0 {
        return Vec3::ZERO;
    }
    let x = (bits as u16 as i16) as f32 / 32767.0;
    let y = ((bits >> 16) as u16 as i16) as f32 / 32767.0;
    let z = 1.0 - x.abs() - y.abs();
    let t = (-z).max(0.0);
    let v = Vec3::new(x - t * x.signum(), y - t * y.signum(), z);
    v.normalize_or_zero()
}

const MANTISSA_BITS: i32 = 9;
const EXP_BIAS: i32 = 15;
const MAX_EXP: i32 = 31;

/// A non-negative RGB colour as RGB9E5 (relative error below 0.4% of the largest channel); negative and
/// non-finite channels become zero, values above 65408 saturate.
pub fn encode_rgb(c: [f32; 3]) -> u32 {
    let max_value = ((1 << MANTISSA_BITS) - 1) as f32 / (1 << MANTISSA_BITS) as f32 * 2f32.powi(MAX_EXP - EXP_BIAS);
    let clean = |v: f32| if v.is_finite() && v > 0.0 { v.min(max_value) } else { 0.0 };
    let [r, g, b] = c.map(clean);
    let m = r.max(g).max(b);
    if m <= 0.0 {
        return 0;
    }
    let mut exp = (m.log2().floor() as i32).max(-EXP_BIAS - 1) + 1 + EXP_BIAS;
    let mut scale = 2f32.powi(exp - EXP_BIAS - MANTISSA_BITS);
    if (m / scale).round() as i32 == 1 << MANTISSA_BITS {
        exp += 1;
        scale *= 2.0;
    }
    let exp = exp.clamp(0, MAX_EXP);
    let q = |v: f32| ((v / scale).round() as u32).min((1 << MANTISSA_BITS) - 1);
    q(r) | q(g) << 9 | q(b) << 18 | (exp as u32) << 27
}

/// The colour of `encode_rgb`.
pub fn decode_rgb(bits: u32) -> [f32; 3] {
    let exp = (bits >> 27) as i32;
    let scale = 2f32.powi(exp - EXP_BIAS - MANTISSA_BITS);
    [bits & 511, (bits >> 9) & 511, (bits >> 18) & 511].map(|m| m as f32 * scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_survive_octahedral_encoding_within_a_hundredth_of_a_degree() {
        for i in 0..2000 {
            let t = i as f32 * 0.7373;
            let n = Vec3::new(t.sin() * (t * 0.31).cos(), t.cos(), (t * 1.7).sin() - 0.2).normalize();
            let d = decode_normal(encode_normal(n));
            assert!(n.dot(d) > (0.01f32).to_radians().cos(), "{n} → {d}");
        }
        assert_eq!(decode_normal(encode_normal(Vec3::ZERO)), Vec3::ZERO);
        assert!(decode_normal(encode_normal(-Vec3::Z)).dot(-Vec3::Z) > 0.9999);
    }

    #[test]
    fn colours_survive_rgb9e5_within_half_a_percent_of_their_largest_channel() {
        for c in [[1.0, 0.5, 0.25], [1e-3, 2e-3, 0.0], [300.0, 1.0, 7.5], [0.999, 0.999, 0.999], [1e4, 0.0, 1.0]] {
            let d = decode_rgb(encode_rgb(c));
            let m = c.iter().cloned().fold(0.0, f32::max);
            for k in 0..3 {
                assert!((d[k] - c[k]).abs() <= 0.005 * m, "{c:?} → {d:?}");
            }
        }
        assert_eq!(decode_rgb(encode_rgb([-1.0, f32::NAN, 0.0])), [0.0; 3]);
    }
}
