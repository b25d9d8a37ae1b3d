//! The elements of a `<transform>` (`translate`, `rotate`, `scale`, `matrix`, `lookat`) as 4×4 matrices,
//! computed in double precision as Mitsuba does; `xml` composes them in document order (each later element
//! applied after the earlier ones: M = T_last · … · T_first).

use super::error::MitsubaError;
use super::xml::Attributes;
use glam::{DMat3, DMat4, DVec3, DVec4};

/// The matrix of one transform element.
pub(super) fn element_matrix(element: &Attributes) -> Result<DMat4, MitsubaError> {
    match element.tag.as_str() {
        "translate" => {
            element.allow_only(&["x", "y", "z", "value"])?;
            Ok(DMat4::from_translation(components(element, 0.0)?))
        }
        "scale" => {
            element.allow_only(&["x", "y", "z", "value"])?;
            Ok(DMat4::from_scale(components(element, 1.0)?))
        }
        "rotate" => {
            element.allow_only(&["x", "y", "z", "value", "angle"])?;
            let axis = components(element, 0.0)?;
            let angle = element.required_number("angle")?;
            if axis == DVec3::ZERO {
                return Err(element.error("the rotation axis is zero: give x, y, z or value=\"x, y, z\""));
            }
            Ok(rotation(axis, angle))
        }
        "matrix" => {
            element.allow_only(&["value"])?;
            let values = element.required_numbers("value")?;
            match values.len() {
                16 => Ok(DMat4::from_cols_array(&values.try_into().expect("16 values")).transpose()),
                9 => {
                    let m = DMat3::from_cols_array(&values.try_into().expect("9 values")).transpose();
                    Ok(DMat4::from_mat3(m))
                }
                n => Err(element.error(format!("a matrix has 9 or 16 values (row by row), not {n}"))),
            }
        }
        "lookat" => {
            element.allow_only(&["origin", "target", "up"])?;
            let origin = element.required_vector("origin")?;
            let target = element.required_vector("target")?;
            let up = element.vector("up")?;
            look_at(origin, target, up).ok_or_else(|| {
                element.error("the camera direction is zero or parallel to `up`: no orientation follows from it")
            })
        }
        other => Err(element.error(format!(
            "<{other}> is not a transform element: a <transform> holds translate, rotate, scale, matrix and lookat"
        ))),
    }
}

/// The x, y, z attributes (missing ones take `default`) or a `value` of one or three numbers.
fn components(element: &Attributes, default: f64) -> Result<DVec3, MitsubaError> {
    let value = element.numbers("value")?;
    let has_xyz = ["x", "y", "z"].iter().any(|a| element.get(a).is_some());
    match value {
        Some(_) if has_xyz => Err(element.error("give either value or x, y, z, not both")),
        Some(v) if v.len() == 1 => Ok(DVec3::splat(v[0])),
        Some(v) if v.len() == 3 => Ok(DVec3::new(v[0], v[1], v[2])),
        Some(v) => Err(element.error(format!("value has one or three numbers, not {}", v.len()))),
        None => Ok(DVec3::new(
            element.number("x")?.unwrap_or(default),
            element.number("y")?.unwrap_or(default),
            element.number("z")?.unwrap_or(default),
        )),
    }
}

/// Rotation by `degrees` about `axis`, which Mitsuba does not normalise (a longer axis also scales).
fn rotation(axis: DVec3, degrees: f64) -> DMat4 {
    let (sin, cos) = degrees.to_radians().sin_cos();
    let a = axis;
    let outer = |i: usize| a * a[i] * (1.0 - cos);
    // Columns of cos·I + (1 − cos)·a·aᵀ + sin·[a]×.
    let c0 = outer(0) + DVec3::new(cos, a.z * sin, -a.y * sin);
    let c1 = outer(1) + DVec3::new(-a.z * sin, cos, a.x * sin);
    let c2 = outer(2) + DVec3::new(a.y * sin, -a.x * sin, cos);
    DMat4::from_mat3(DMat3::from_cols(c0, c1, c2))
}

/// Mitsuba's camera-to-world matrix: +z towards the target, +y towards `up` and +x = up × dir (to the left in
/// the image). Without `up`, Mitsuba takes the first tangent of its orthonormal basis around the direction.
fn look_at(origin: DVec3, target: DVec3, up: Option<DVec3>) -> Option<DMat4> {
    let dir = (target - origin).try_normalize()?;
    let up = up.unwrap_or_else(|| basis_tangent(dir));
    let left = up.cross(dir).try_normalize()?;
    let new_up = dir.cross(left);
    Some(DMat4::from_cols(
        left.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        DVec4::new(origin.x, origin.y, origin.z, 1.0),
    ))
}

/// The first tangent of the branchless orthonormal basis (Duff et al. 2017) that Mitsuba's
/// `coordinate_system` builds around the unit vector `n`.
fn basis_tangent(n: DVec3) -> DVec3 {
    let sign = 1f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x)
}
