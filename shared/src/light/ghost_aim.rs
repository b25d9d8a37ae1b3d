//! Where on the front element a ghost path aims (docs/estimator.md, "The ghost layer"): a density over the front
//! element's disc, one per ghost pair, learnt by the pair table's pilot. Most of a pair's chains die on the stop
//! or the mounts; the regions of the disc through which the pair's chains reach the sensor get most of its
//! paths, as lens-design software traces a ghost through the part of the pupil that forms it.

use super::AimDensity;
use crate::sampling::{GridShape, SquareGrid};
use glam::Vec2;
use std::f32::consts::TAU;

/// The front element's grid: rings of equal area, and sectors of each ring, so its cells have equal areas.
pub const RINGS: usize = 8;
pub const SECTORS: usize = 16;

/// The share of a grid spread evenly: a region where the pilot saw nothing keeps a density, so the ghost layer
/// stays unbiased whatever the pilot missed.
pub const EVEN_AIM: f32 = 0.2;

/// A cell next to one the pilot saw bring light keeps half its neighbour's weight: a region that forms a ghost is
/// larger than the cells the pilot's few paths per cell happened to hit.
const NEIGHBOUR_SHARE: f64 = 0.5;

/// The shape of a pair's grid over the front element: rings by the square of the radius, sectors by the angle.
pub const AIM_SHAPE: GridShape =
    GridShape { rows: RINGS, columns: SECTORS, wrap_columns: true, even: EVEN_AIM, neighbour_share: NEIGHBOUR_SHARE };

/// A density over the unit disc on a polar grid of equal-area cells.
#[derive(Clone, Debug)]
pub struct AimGrid {
    grid: SquareGrid,
}

impl AimGrid {
    /// The density from a pilot's weights, one per cell as `cell_of` numbers them (`SquareGrid::from_weights`
    /// with `AIM_SHAPE`; uniform when none is positive).
    pub fn from_weights(weights: &[f64]) -> Self {
        AimGrid { grid: SquareGrid::from_weights(AIM_SHAPE, weights) }
    }

    /// The point of the grid's square a point of the unit disc lies at: the square of its radius, and its
    /// angle over a turn.
    #[inline]
    fn polar(p: Vec2) -> Vec2 {
        Vec2::new(p.length_squared().min(1.0), p.y.atan2(p.x).rem_euclid(TAU) / TAU)
    }

    /// The cell of a point of the unit disc.
    pub fn cell_of(p: Vec2) -> usize {
        SquareGrid::cell_in(RINGS, SECTORS, Self::polar(p))
    }

    /// The probability of a cell.
    pub fn cell_probability(&self, cell: usize) -> f32 {
        self.grid.cell_probability(cell)
    }
}

impl AimDensity for AimGrid {
    #[inline]
    fn sample(&self, u: Vec2) -> Vec2 {
        // Uniform in the square of the radius and in the angle is uniform in area.
        let (q, _) = self.grid.sample(u);
        let angle = q.y * TAU;
        q.x.sqrt() * Vec2::new(angle.cos(), angle.sin())
    }

    #[inline]
    fn relative(&self, p: Vec2) -> f32 {
        self.grid.relative(Self::polar(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    #[test]
    fn disc_draws_fall_in_the_cell_the_grid_weighs_and_the_density_integrates_to_the_disc() {
        let mut weights = [0.0; RINGS * SECTORS];
        weights[3 * SECTORS + 5] = 1.0;
        let grid = AimGrid::from_weights(&weights);
        let mut sampler = Sampler::new(2, Pass::Ghost, 0, 0);
        let (n, mut inside, mut mean_inverse) = (100_000, 0, 0.0f64);
        for _ in 0..n {
            let p = grid.sample(sampler.next_2d());
            assert!(p.length_squared() <= 1.0 + 1e-6);
            inside += (AimGrid::cell_of(p) == 3 * SECTORS + 5) as u32;
            mean_inverse += 1.0 / grid.relative(p) as f64;
        }
        let expected = grid.cell_probability(3 * SECTORS + 5) as f64 * n as f64;
        assert!((inside as f64 - expected).abs() < 5.0 * expected.sqrt(), "{inside} against {expected}");
        assert!((mean_inverse / n as f64 - 1.0).abs() < 0.02, "{}", mean_inverse / n as f64);
    }

    #[test]
    fn cells_number_the_disc_by_ring_then_sector() {
        assert_eq!(AimGrid::cell_of(Vec2::ZERO), 0);
        assert_eq!(AimGrid::cell_of(Vec2::new(0.0, -0.999)), RINGS * SECTORS - SECTORS / 4);
        assert!((AimGrid::from_weights(&[0.0; RINGS * SECTORS]).relative(Vec2::new(0.3, -0.4)) - 1.0).abs() < 1e-5);
    }
}
