//! Piecewise-constant densities over [0, 1) and [0, 1)², built from cell weights (a luminance image, say) and
//! sampled by inverting their cumulative sums; the 2D one is a marginal density over rows times a conditional
//! density within each row.

use glam::Vec2;
use thiserror::Error;

/// Why a set of weights cannot make a density.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DistributionError {
    #[error("a distribution needs at least one cell")]
    Empty,
    #[error("the weights are {expected} cells ({width} × {height}) but {given} were given")]
    WrongLength { width: usize, height: usize, expected: usize, given: usize },
    #[error("weight {index} is {value}: weights must be finite and non-negative")]
    InvalidWeight { index: usize, value: f32 },
    #[error("all weights are zero")]
    AllZero,
}

/// The largest f32 below 1, where a sample that rounds up to 1 is put back into [0, 1).
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// A piecewise-constant density over [0, 1) with `len()` equal cells, proportional to the given weights.
#[derive(Clone, Debug)]
pub struct Piecewise1d {
    weights: Vec<f32>,
    /// `len() + 1` entries from 0 to 1; a zero-weight cell has cdf[i] == cdf[i + 1] and is never chosen.
    cdf: Vec<f32>,
    /// The mean weight: the integral of the weights as a function over [0, 1).
    integral: f32,
}

impl Piecewise1d {
    /// The density proportional to `weights`, one cell each; an error for no cells, a negative or non-finite
    /// weight, or all weights zero.
    pub fn new(weights: &[f32]) -> Result<Self, DistributionError> {
        if weights.is_empty() {
            return Err(DistributionError::Empty);
        }
        if let Some((index, &value)) = weights.iter().enumerate().find(|(_, w)| !(w.is_finite() && **w >= 0.0)) {
            return Err(DistributionError::InvalidWeight { index, value });
        }
        let total: f64 = weights.iter().map(|&w| w as f64).sum();
        if total <= 0.0 {
            return Err(DistributionError::AllZero);
        }
        let mut cdf = Vec::with_capacity(weights.len() + 1);
        cdf.push(0.0);
        let mut acc = 0.0f64;
        for &w in weights {
            acc += w as f64;
            cdf.push((acc / total) as f32);
        }
        // Rounding must neither let u < 1 run past the last non-zero cell nor leave a zero cell after it
        // choosable: every cdf entry from there on is exactly 1.
        let last = weights.iter().rposition(|&w| w > 0.0).unwrap_or(0);
        for c in &mut cdf[last + 1..] {
            *c = 1.0;
        }
        let integral = (total / weights.len() as f64) as f32;
        Ok(Piecewise1d { weights: weights.to_vec(), cdf, integral })
    }

    /// A point x in [0, 1) with density `pdf(x)`, that density, and the cell it lies in.
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.weights.len();
        // A u outside [0, 1) would land in a zero cell before the first or after the last non-zero one.
        let u = u.clamp(0.0, ONE_MINUS_EPSILON);
        let cell = (self.cdf.partition_point(|&c| c <= u).max(1) - 1).min(n - 1);
        let (below, above) = (self.cdf[cell], self.cdf[cell + 1]);
        let within = if above > below { (u - below) / (above - below) } else { 0.5 };
        let mut x = ((cell as f32 + within.clamp(0.0, 1.0)) / n as f32).min(ONE_MINUS_EPSILON);
        // Rounding may carry x onto the next cell's edge; the point must stay in the cell whose density it gets.
        while self.cell_of(x) > cell {
            x = f32::from_bits(x.to_bits() - 1);
        }
        (x, self.weights[cell] / self.integral, cell)
    }

    /// The density at x (zero outside [0, 1)).
    pub fn pdf(&self, x: f32) -> f32 {
        if !(0.0..1.0).contains(&x) {
            return 0.0;
        }
        self.weights[self.cell_of(x)] / self.integral
    }

    /// The cell that holds x in [0, 1).
    pub fn cell_of(&self, x: f32) -> usize {
        ((x * self.weights.len() as f32) as usize).min(self.weights.len() - 1)
    }

    /// The integral over [0, 1) of the weights read as a step function (their mean).
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// The number of cells.
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// True when there are no cells (never, for a constructed distribution).
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }
}

/// A piecewise-constant density over [0, 1)² on a grid of width × height cells (x across a row, y down the
/// rows), sampled as a row by the marginal density and then a point within that row.
#[derive(Clone, Debug)]
pub struct Piecewise2d {
    /// One conditional density per row; `None` for a row whose weights are all zero (never chosen).
    rows: Vec<Option<Piecewise1d>>,
    marginal: Piecewise1d,
}

impl Piecewise2d {
    /// The density proportional to `weights` (row-major, `width × height`); errors as `Piecewise1d::new`.
    pub fn new(weights: &[f32], width: usize, height: usize) -> Result<Self, DistributionError> {
        if width == 0 || height == 0 {
            return Err(DistributionError::Empty);
        }
        let expected = width * height;
        if weights.len() != expected {
            return Err(DistributionError::WrongLength { width, height, expected, given: weights.len() });
        }
        let mut rows = Vec::with_capacity(height);
        let mut row_integrals = Vec::with_capacity(height);
        for (y, row) in weights.chunks_exact(width).enumerate() {
            match Piecewise1d::new(row) {
                Ok(d) => {
                    row_integrals.push(d.integral());
                    rows.push(Some(d));
                }
                Err(DistributionError::AllZero) => {
                    row_integrals.push(0.0);
                    rows.push(None);
                }
                Err(DistributionError::InvalidWeight { index, value }) => {
                    return Err(DistributionError::InvalidWeight { index: y * width + index, value })
                }
                Err(e) => return Err(e),
            }
        }
        let marginal = Piecewise1d::new(&row_integrals)?;
        Ok(Piecewise2d { rows, marginal })
    }

    /// A point in [0, 1)² with density `pdf(point)`, and that density.
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (y, pdf_row, row) = self.marginal.sample(u.y);
        // The marginal never chooses a row of zero weight, so the row has its density.
        let conditional = self.rows[row].as_ref().expect("a chosen row has non-zero weight");
        let (x, pdf_x, _) = conditional.sample(u.x);
        (Vec2::new(x, y), pdf_row * pdf_x)
    }

    /// The density at `p` (zero outside [0, 1)²).
    pub fn pdf(&self, p: Vec2) -> f32 {
        if !(0.0..1.0).contains(&p.y) {
            return 0.0;
        }
        match &self.rows[self.marginal.cell_of(p.y)] {
            Some(row) => self.marginal.pdf(p.y) * row.pdf(p.x),
            None => 0.0,
        }
    }

    /// The integral over [0, 1)² of the weights read as a step function (their mean).
    pub fn integral(&self) -> f32 {
        self.marginal.integral()
    }

    /// The grid's (width, height) in cells.
    pub fn size(&self) -> (usize, usize) {
        (self.rows.iter().flatten().next().map_or(0, Piecewise1d::len), self.rows.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Pass, Sampler};

    /// Pearson's statistic of observed counts against expected ones, and a bound it exceeds with probability
    /// well below 10⁻⁴ (mean df plus 6 standard deviations √(2 df)).
    fn chi_square(observed: &[u32], expected: &[f64]) -> (f64, f64) {
        let mut stat = 0.0;
        let mut df = 0usize;
        for (&o, &e) in observed.iter().zip(expected) {
            if e > 0.0 {
                stat += (o as f64 - e).powi(2) / e;
                df += 1;
            } else {
                assert_eq!(o, 0, "a sample fell where the density is zero");
            }
        }
        let df = (df - 1) as f64;
        (stat, df + 6.0 * (2.0 * df).sqrt())
    }

    #[test]
    fn the_1d_pdf_integrates_to_one_and_matches_its_samples() {
        let d = Piecewise1d::new(&[1.0, 0.0, 3.0, 0.5, 2.0]).unwrap();
        let integral: f32 = (0..5000).map(|i| d.pdf((i as f32 + 0.5) / 5000.0) / 5000.0).sum();
        assert!((integral - 1.0).abs() < 1e-4, "{integral}");
        let mut rng = Sampler::new(1, Pass::Light, 0, 0);
        for _ in 0..1000 {
            let (x, pdf, cell) = d.sample(rng.next_f32());
            assert!((0.0..1.0).contains(&x));
            assert_eq!(d.cell_of(x), cell);
            assert_eq!(d.pdf(x), pdf);
            assert!(pdf > 0.0);
        }
    }

    #[test]
    fn the_1d_samples_follow_the_pdf_by_chi_square() {
        let d = Piecewise1d::new(&[1.0, 0.0, 3.0, 0.5, 2.0, 0.01]).unwrap();
        // Four bins per cell, so that the spread within a cell is checked too.
        let bins = 24;
        let n = 200_000;
        let mut observed = vec![0u32; bins];
        let mut rng = Sampler::new(2, Pass::Light, 0, 0);
        for _ in 0..n {
            let (x, _, _) = d.sample(rng.next_f32());
            observed[((x * bins as f32) as usize).min(bins - 1)] += 1;
        }
        let expected: Vec<f64> =
            (0..bins).map(|b| d.pdf((b as f32 + 0.5) / bins as f32) as f64 / bins as f64 * n as f64).collect();
        let (stat, bound) = chi_square(&observed, &expected);
        assert!(stat < bound, "chi-square {stat} above {bound}");
    }

    #[test]
    fn the_2d_pdf_integrates_to_one_and_its_samples_follow_it() {
        let (w, h) = (5, 4);
        let weights: Vec<f32> = (0..w * h).map(|i| if i % 7 == 3 { 0.0 } else { 1.0 + (i * i % 11) as f32 }).collect();
        let mut weights = weights;
        weights[w..2 * w].fill(0.0); // a whole row of zeros
        let d = Piecewise2d::new(&weights, w, h).unwrap();
        assert_eq!(d.size(), (w, h));
        let q = 200;
        let integral: f32 = (0..q * q)
            .map(|i| d.pdf(Vec2::new(((i % q) as f32 + 0.5) / q as f32, ((i / q) as f32 + 0.5) / q as f32)))
            .sum::<f32>()
            / (q * q) as f32;
        assert!((integral - 1.0).abs() < 1e-4, "{integral}");

        let (bx, by) = (2 * w, 2 * h);
        let n = 200_000;
        let mut observed = vec![0u32; bx * by];
        let mut rng = Sampler::new(3, Pass::Light, 0, 0);
        for _ in 0..n {
            let (p, pdf) = d.sample(rng.next_2d());
            assert!((0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y));
            assert!(pdf > 0.0 && (d.pdf(p) - pdf).abs() <= 1e-6 * pdf, "{pdf} vs {}", d.pdf(p));
            let (i, j) = (((p.x * bx as f32) as usize).min(bx - 1), ((p.y * by as f32) as usize).min(by - 1));
            observed[j * bx + i] += 1;
        }
        let expected: Vec<f64> = (0..bx * by)
            .map(|k| {
                let centre = Vec2::new(((k % bx) as f32 + 0.5) / bx as f32, ((k / bx) as f32 + 0.5) / by as f32);
                d.pdf(centre) as f64 / (bx * by) as f64 * n as f64
            })
            .collect();
        let (stat, bound) = chi_square(&observed, &expected);
        assert!(stat < bound, "chi-square {stat} above {bound}");
    }

    #[test]
    fn a_single_non_zero_cell_is_always_chosen() {
        let mut weights = vec![0.0f32; 6 * 3];
        weights[2 * 6 + 4] = 0.25;
        let d = Piecewise2d::new(&weights, 6, 3).unwrap();
        let d1 = Piecewise1d::new(&[0.0, 0.0, 7.0, 0.0]).unwrap();
        for i in 0..257 {
            let u = i as f32 / 256.0 * ONE_MINUS_EPSILON;
            let (p, pdf) = d.sample(Vec2::new(u, 1.0 - u - f32::EPSILON));
            assert_eq!((((p.x * 6.0) as usize), (p.y * 3.0) as usize), (4, 2));
            assert!((pdf - 18.0).abs() < 1e-3, "{pdf}");
            let (x, pdf, cell) = d1.sample(u);
            assert_eq!(cell, 2);
            assert!((0.5..0.75).contains(&x) && pdf == 4.0, "{x} {pdf}");
        }
    }

    #[test]
    fn bad_weights_are_errors() {
        assert_eq!(Piecewise1d::new(&[]).unwrap_err(), DistributionError::Empty);
        assert_eq!(Piecewise1d::new(&[0.0, 0.0]).unwrap_err(), DistributionError::AllZero);
        assert!(matches!(
            Piecewise1d::new(&[1.0, f32::NAN]).unwrap_err(),
            DistributionError::InvalidWeight { index: 1, .. }
        ));
        assert!(matches!(
            Piecewise2d::new(&[1.0, 1.0, 1.0, -1.0], 2, 2).unwrap_err(),
            DistributionError::InvalidWeight { index: 3, .. }
        ));
        assert!(matches!(
            Piecewise2d::new(&[1.0, f32::INFINITY, 1.0, 1.0], 2, 2).unwrap_err(),
            DistributionError::InvalidWeight { index: 1, .. }
        ));
        assert_eq!(Piecewise2d::new(&[0.0; 4], 2, 2).unwrap_err(), DistributionError::AllZero);
        assert!(matches!(Piecewise2d::new(&[1.0; 3], 2, 2).unwrap_err(), DistributionError::WrongLength { .. }));
    }
}
