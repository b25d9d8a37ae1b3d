//! The compact encoding of a vertex's normal: octahedral, two 16-bit numbers, 4 bytes instead of 12.

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_survive_octahedral_encoding_within_a_hundredth_of_a_degree() {
        for i in 0..2000 {
            let t = i as f32 * 0.7373;
            let n = Vec3::new(t.sin() * (t * 0.31).cos(), t.cos(), (t * 1.7).sin() - 0.2).normalize();
            let d = decode_normal(encode_normal(n));
            // The angle from the cross product: near zero, a cosine in f32 cannot tell 0.01° from nothing.
            let angle = n.cross(d).length().atan2(n.dot(d)).to_degrees();
            assert!(angle < 0.01, "{n} → {d}: {angle}°");
        }
        assert_eq!(decode_normal(encode_normal(Vec3::ZERO)), Vec3::ZERO);
        assert!(decode_normal(encode_normal(-Vec3::Z)).dot(-Vec3::Z) > 0.9999);
    }
}
