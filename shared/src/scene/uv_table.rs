//! The texture coordinates of a scene's triangles, kept from the first triangle that has them: a large mesh
//! without them (the common case for scanned and generated meshes) costs nothing per triangle.

use glam::Vec2;

/// Texture coordinates by triangle index (the order triangles were added in); None where a triangle's shape has
/// none.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UvTable {
    /// The index of `uvs[0]`'s triangle: every triangle before it has none.
    first: u32,
    uvs: Vec<Option<[Vec2; 3]>>,
}

impl UvTable {
    /// Records triangle `index`'s coordinates; triangles must come in index order.
    pub fn push(&mut self, index: u32, uv: Option<[Vec2; 3]>) {
        if self.uvs.is_empty() {
            if uv.is_none() {
                return;
            }
            self.first = index;
        }
        debug_assert_eq!(index as usize, self.first as usize + self.uvs.len(), "triangles out of order");
        self.uvs.push(uv);
    }

    /// Triangle `index`'s coordinates, if it has them.
    pub fn get(&self, index: u32) -> Option<&[Vec2; 3]> {
        let i = index.checked_sub(self.first)? as usize;
        self.uvs.get(i)?.as_ref()
    }

    /// True when no triangle has coordinates.
    pub fn is_empty(&self) -> bool {
        self.uvs.is_empty()
    }

    /// Bytes held, for memory estimates.
    pub fn bytes(&self) -> usize {
        self.uvs.capacity() * std::mem::size_of::<Option<[Vec2; 3]>>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_before_the_first_with_coordinates_cost_nothing_and_read_as_none() {
        let uv = |x: f32| Some([Vec2::splat(x); 3]);
        let mut t = UvTable::default();
        for i in 0..1000 {
            t.push(i, None);
        }
        assert!(t.is_empty() && t.bytes() == 0);
        t.push(1000, uv(1.0));
        t.push(1001, None);
        t.push(1002, uv(2.0));
        assert_eq!(t.get(0), None);
        assert_eq!(t.get(999), None);
        assert_eq!(t.get(1000), uv(1.0).as_ref());
        assert_eq!(t.get(1001), None);
        assert_eq!(t.get(1002), uv(2.0).as_ref());
        assert_eq!(t.get(1003), None);
    }
}
