//! Optional data of a scene's triangles (vertex normals, texture coordinates), kept only for the triangles that
//! have some: a large mesh without them (the common case for scanned and generated meshes) costs nothing per
//! triangle, wherever it comes among the scene's objects.

/// Values by triangle index (the order triangles were added in); None where a triangle has none.
#[derive(Clone, Debug, PartialEq)]
pub struct PerTriangle<T> {
    /// Runs of consecutive triangles with a value, in index order: one per stretch of objects that have them,
    /// so a lookup searches a handful.
    runs: Vec<Run<T>>,
}

/// The values of triangles `first..first + values.len()`.
#[derive(Clone, Debug, PartialEq)]
struct Run<T> {
    first: u32,
    values: Vec<T>,
}

impl<T> Default for PerTriangle<T> {
    fn default() -> Self {
        PerTriangle { runs: Vec::new() }
    }
}

impl<T> PerTriangle<T> {
    /// Records triangle `index`'s value; triangles must come in index order.
    pub fn push(&mut self, index: u32, value: Option<T>) {
        let Some(value) = value else { return };
        match self.runs.last_mut() {
            Some(run) if run.first as usize + run.values.len() == index as usize => run.values.push(value),
            last => {
                debug_assert!(
                    last.is_none_or(|r| (r.first as usize + r.values.len()) < index as usize),
                    "out of order"
                );
                self.runs.push(Run { first: index, values: vec![value] });
            }
        }
    }

    /// Triangle `index`'s value, if it has one.
    #[inline]
    pub fn get(&self, index: u32) -> Option<&T> {
        let after = self.runs.partition_point(|r| r.first <= index);
        let run = &self.runs[after.checked_sub(1)?];
        run.values.get((index - run.first) as usize)
    }

    /// True when no triangle has a value.
    pub fn is_empty(&self) -> bool {
        self.runs.is_empty()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.runs.iter().map(|r| r.values.capacity() * std::mem::size_of::<T>()).sum::<usize>()
            + self.runs.capacity() * std::mem::size_of::<Run<T>>()
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

    #[test]
    fn triangles_without_a_value_cost_nothing_after_ones_with_and_every_value_reads_back() {
        let uv = |x: u32| Some([Vec2::splat(x as f32); 3]);
        let mut t = PerTriangle::default();
        // Two quads with values, a large mesh without, one with values again, then single gaps.
        let has =
            |i: u32| i < 4 || (100_000..100_010).contains(&i) || (i > 100_010 && i.is_multiple_of(2) && i < 100_020);
        for i in 0..100_030 {
            t.push(i, if has(i) { uv(i) } else { None });
        }
        assert!(t.bytes() < 2_000, "{} bytes for 23 values", t.bytes());
        for i in 0..100_040 {
            assert_eq!(t.get(i), if has(i) { uv(i) } else { None }.as_ref(), "triangle {i}");
        }
        assert!(PerTriangle::<u8>::default().get(0).is_none());
    }
}
