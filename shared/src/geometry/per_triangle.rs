//! Optional data of a scene's triangles (vertex normals, texture coordinates), kept from the first triangle that
//! has some: a large mesh without them (the common case for scanned and generated meshes) costs nothing per
//! triangle.

/// Values by triangle index (the order triangles were added in); None where a triangle has none.
#[derive(Clone, Debug, PartialEq)]
pub struct PerTriangle<T> {
    /// The index of `values[0]`'s triangle: every triangle before it has none.
    first: u32,
    values: Vec<Option<T>>,
}

impl<T> Default for PerTriangle<T> {
    fn default() -> Self {
        PerTriangle { first: 0, values: Vec::new() }
    }
}

impl<T> PerTriangle<T> {
    /// Records triangle `index`'s value; triangles must come in index order.
    pub fn push(&mut self, index: u32, value: Option<T>) {
        if self.values.is_empty() {
            if value.is_none() {
                return;
            }
            self.first = index;
        }
        debug_assert_eq!(index as usize, self.first as usize + self.values.len(), "triangles out of order");
        self.values.push(value);
    }

    /// Triangle `index`'s value, if it has one.
    #[inline]
    pub fn get(&self, index: u32) -> Option<&T> {
        let i = index.checked_sub(self.first)? as usize;
        self.values.get(i)?.as_ref()
    }

    /// True when no triangle has a value.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.values.capacity() * std::mem::size_of::<Option<T>>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn triangles_before_the_first_with_a_value_cost_nothing_and_read_as_none() {
        let uv = |x: f32| Some([Vec2::splat(x); 3]);
        let mut t = PerTriangle::default();
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
