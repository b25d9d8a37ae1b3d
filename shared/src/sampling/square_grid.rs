//! A piecewise-constant density over the unit square, learnt from weights per cell: how guided sampling draws
//! from where a pilot saw the light go.

use super::Discrete;
use glam::Vec2;

/// A density over the unit square, constant on each of `rows × columns` equal cells. Cell `row * columns +
/// column` covers x in [row, row + 1) / rows and y in [column, column + 1) / columns.
#[derive(Clone, Debug)]
pub struct SquareGrid {
    rows: usize,
    columns: usize,
    cells: Discrete,
}

/// How a grid is made from a pilot's weights per cell.
#[derive(Clone, Copy, Debug)]
pub struct GridShape {
    pub rows: usize,
    pub columns: usize,
    /// True when the last column borders the first (an angle).
    pub wrap_columns: bool,
    /// The share of the density spread evenly over the square: a region where the pilot saw nothing keeps a
    /// density, so an estimate divided by it stays unbiased whatever the pilot missed.
    pub even: f32,
    /// A cell next to a weighted one keeps at least this share of its neighbour's weight: a region that brings
    /// light is larger than the cells a pilot's few samples per cell happened to hit.
    pub neighbour_share: f64,
}

impl SquareGrid {
    /// The uniform density on a grid of this shape.
    pub fn uniform(rows: usize, columns: usize) -> Self {
        let cells = Discrete::new(&vec![1.0; rows * columns]).expect("a grid has cells");
        SquareGrid { rows, columns, cells }
    }

    /// The density whose cells take `shape.even` evenly and the rest in proportion to `weights` (one per
    /// cell), each first raised to `shape.neighbour_share` of its largest neighbour's. Uniform when no weight is
    /// positive.
    pub fn from_weights(shape: GridShape, weights: &[f64]) -> Self {
        let GridShape { rows, columns, wrap_columns, even, neighbour_share } = shape;
        assert_eq!(weights.len(), rows * columns, "one weight per cell");
        let weight = |r: usize, c: usize| weights[r * columns + c];
        let mut spread = weights.to_vec();
        for r in 0..rows {
            for c in 0..columns {
                let mut largest = 0.0f64;
                if r > 0 {
                    largest = largest.max(weight(r - 1, c));
                }
                if r + 1 < rows {
                    largest = largest.max(weight(r + 1, c));
                }
                if c > 0 || wrap_columns {
                    largest = largest.max(weight(r, (c + columns - 1) % columns));
                }
                if c + 1 < columns || wrap_columns {
                    largest = largest.max(weight(r, (c + 1) % columns));
                }
                let i = r * columns + c;
                spread[i] = spread[i].max(neighbour_share * largest);
            }
        }
        let total: f64 = spread.iter().sum();
        if total <= 0.0 || !total.is_finite() {
            return Self::uniform(rows, columns);
        }
        let n = (rows * columns) as f64;
        let p: Vec<f32> = spread.iter().map(|w| ((1.0 - even as f64) * w / total + even as f64 / n) as f32).collect();
        SquareGrid { rows, columns, cells: Discrete::new(&p).expect("positive weights") }
    }

    /// Cells of the grid.
    pub fn cells(&self) -> usize {
        self.rows * self.columns
    }

    /// The cell holding the point `u` of the unit square.
    #[inline]
    pub fn cell_of(&self, u: Vec2) -> usize {
        Self::cell_in(self.rows, self.columns, u)
    }

    /// The cell holding the point `u` of the unit square on a grid of `rows × columns`.
    #[inline]
    pub fn cell_in(rows: usize, columns: usize, u: Vec2) -> usize {
        let r = ((u.x * rows as f32) as usize).min(rows - 1);
        let c = ((u.y * columns as f32) as usize).min(columns - 1);
        r * columns + c
    }

    /// The probability of a cell.
    pub fn cell_probability(&self, cell: usize) -> f32 {
        self.cells.pmf(cell)
    }

    /// A point of the square drawn from the density with the uniform random numbers `u`, and the density there
    /// relative to the uniform one.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (cell, p, u_row) = self.cells.sample_remapped(u.x);
        let (r, c) = (cell / self.columns, cell % self.columns);
        let point = Vec2::new((r as f32 + u_row) / self.rows as f32, (c as f32 + u.y) / self.columns as f32);
        (point, p * self.cells() as f32)
    }

    /// The density at the point `u` of the square relative to the uniform one.
    #[inline]
    pub fn relative(&self, u: Vec2) -> f32 {
        self.cells.pmf(self.cell_of(u)) * self.cells() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    const SHAPE: GridShape = GridShape { rows: 4, columns: 8, wrap_columns: true, even: 0.2, neighbour_share: 0.5 };

    #[test]
    fn draws_land_in_each_cell_as_often_as_its_probability_and_carry_the_density_reported_there() {
        let mut weights = [0.0; 32];
        weights[8 + 7] = 4.0; // cell (1, 7)
        weights[3 * 8 + 2] = 1.0; // cell (3, 2)
        let grid = SquareGrid::from_weights(SHAPE, &weights);
        let total: f32 = (0..32).map(|c| grid.cell_probability(c)).sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        let even = 0.2 / 32.0;
        assert!(grid.cell_probability(8) > 10.0 * even, "the column wraps: cell (1, 0) borders (1, 7)");
        assert!(grid.cell_probability(2 * 8 + 7) > 10.0 * even, "cell (2, 7) borders (1, 7)");
        assert!((grid.cell_probability(0) - even).abs() < 1e-7, "a far cell keeps the even share");
        let mut counts = [0u32; 32];
        let mut sampler = Sampler::new(1, Pass::Ghost, 0, 0);
        let n = 200_000;
        let mut mean_inverse = 0.0f64;
        for _ in 0..n {
            let (u, relative) = grid.sample(sampler.next_2d());
            assert!((0.0..1.0).contains(&u.x) && (0.0..1.0).contains(&u.y), "{u}");
            assert_eq!(relative, grid.relative(u));
            counts[grid.cell_of(u)] += 1;
            mean_inverse += 1.0 / relative as f64;
        }
        for (c, &k) in counts.iter().enumerate() {
            let expected = grid.cell_probability(c) as f64 * n as f64;
            assert!((k as f64 - expected).abs() < 5.0 * expected.sqrt() + 1.0, "cell {c}: {k} against {expected}");
        }
        // E[1/ρ] under ρ is the square's area, 1: what an estimate divided by the density relies on.
        assert!((mean_inverse / n as f64 - 1.0).abs() < 0.02, "{}", mean_inverse / n as f64);
    }

    #[test]
    fn without_weights_the_grid_is_uniform() {
        let grid = SquareGrid::from_weights(SHAPE, &[0.0; 32]);
        assert_eq!(grid.cell_probability(5), 1.0 / 32.0);
        assert!((grid.relative(Vec2::new(0.3, 0.9)) - 1.0).abs() < 1e-6);
        assert_eq!(grid.cell_of(Vec2::new(0.99, 0.99)), 31);
    }
}
