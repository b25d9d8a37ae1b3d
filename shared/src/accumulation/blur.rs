//! The photon discs' blur as a part of δ. Each phase, a pixel's gathered light is estimated twice, over its
//! photons' discs of radius r and over inner discs of radius r/√2 (`pbpm::inner_disc`), and the difference D
//! goes into the `blur` layer, D² into `blur_sq`. Where the light changes smoothly within r the bias of a
//! disc's average grows as r² (b(r) ≈ r²/8 · ∇²E), so b(r) = 2 (b(r) − b(r/√2)) and 2 E[D] estimates the
//! pixel's bias (one Richardson step). Its square, less D̄'s own variance so that noise alone adds nothing on
//! average, joins the SEM² in δ.

use super::AuxLayout;

/// The auxiliary layer of D; the EXR layer of the same name holds each pixel's estimated bias 2 D̄.
pub const BLUR_LAYER: &str = "blur";
/// The auxiliary layer of D², for D̄'s own variance; not written to the EXR.
pub const BLUR_SQUARES_LAYER: &str = "blur_sq";

/// Where the `blur` and `blur_sq` layers' channels lie among a pixel's auxiliary channels, if the layout has
/// them.
pub fn blur_offsets(layout: &AuxLayout) -> Option<(usize, usize)> {
    Some((layout.offset(BLUR_LAYER)?, layout.offset(BLUR_SQUARES_LAYER)?))
}

/// The bias of a disc of radius r over its difference from the inner disc's: b(r) / (b(r) − b(r/√2)) where b
/// grows as r².
pub const BIAS_PER_DIFFERENCE: f64 = 2.0;

/// D̄ and its variance from a pixel's `phases`, Σ D and Σ D²; None below two phases, where the variance is
/// unknown.
#[inline]
fn mean_and_its_variance(phases: u32, sum: f64, sum_sq: f64) -> Option<(f64, f64)> {
    if phases < 2 {
        return None;
    }
    let n = phases as f64;
    let mean = sum / n;
    Some((mean, (sum_sq / n - mean * mean).max(0.0) / (n - 1.0)))
}

/// The estimated squared bias of a pixel's mean from its `phases`, Σ D and Σ D²: (2 D̄)² less 4 × D̄'s
/// variance, which makes it unbiased and so sometimes negative (callers sum it over pixels before they clamp).
/// Zero below two phases, where D̄'s variance is unknown.
#[inline]
pub fn pixel_bias2(phases: u32, sum: f64, sum_sq: f64) -> f64 {
    mean_and_its_variance(phases, sum, sum_sq).map_or(0.0, |(mean, variance_of_mean)| {
        BIAS_PER_DIFFERENCE * BIAS_PER_DIFFERENCE * (mean * mean - variance_of_mean)
    })
}

/// The variance of `pixel_bias2`'s estimate at a pixel without blur, where only D̄'s noise makes it: with D̄ of
/// variance v about zero, 4 (D̄² − v̂) has variance 16 (2 v² + 2 v² / (n − 1)). A sum of estimates that stands
/// a few of these spreads above zero is blur; one within them may be noise alone. Zero below two phases.
#[inline]
pub fn pixel_bias2_noise(phases: u32, sum: f64, sum_sq: f64) -> f64 {
    mean_and_its_variance(phases, sum, sum_sq).map_or(0.0, |(_, v)| {
        let k2 = BIAS_PER_DIFFERENCE * BIAS_PER_DIFFERENCE;
        k2 * k2 * 2.0 * v * v * (1.0 + 1.0 / (phases as f64 - 1.0))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [−0.5, 0.5) from a seeded linear congruential generator.
    fn centred_uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        }
    }

    /// Σ D and Σ D² over `phases` draws of D.
    fn sums_of(phases: u32, mut draw: impl FnMut() -> f64) -> (f64, f64) {
        (0..phases).map(|_| draw()).fold((0.0, 0.0), |(s, s2), d| (s + d, s2 + d * d))
    }

    #[test]
    fn noise_alone_gives_no_bias_on_average_and_a_steady_difference_gives_twice_itself() {
        // D = ±1 in turn: mean 0, so the squared bias estimate averages out to about zero.
        let (n, sum, sum_sq) = (100u32, 0.0, 100.0);
        assert!(pixel_bias2(n, sum, sum_sq) < 0.0);
        // A steady D of 0.1: the bias is 0.2 and nothing is subtracted.
        let b2 = pixel_bias2(10, 1.0, 0.1);
        assert!((b2 - 0.04).abs() < 1e-12, "{b2}");
        assert_eq!(pixel_bias2(1, 5.0, 25.0), 0.0);
    }

    #[test]
    fn the_squared_bias_estimate_is_unbiased_for_noisy_differences() {
        // D = 0.3 + uniform noise of variance 1/12 over many pixels of 8 phases: the mean estimate is 0.36.
        let mut next = centred_uniform(12345);
        let pixels = 20_000;
        let mut total = 0.0;
        for _ in 0..pixels {
            let (s, s2) = sums_of(8, || 0.3 + next());
            total += pixel_bias2(8, s, s2);
        }
        let mean = total / pixels as f64;
        assert!((mean - 0.36).abs() < 0.01, "{mean}");
    }

    #[test]
    fn the_noise_of_the_squared_bias_estimate_is_its_spread_without_blur() {
        // Pixels whose D is pure noise (uniform, variance 1/12) over 8 phases: the estimates' spread matches
        // the predicted one.
        let mut next = centred_uniform(777);
        let (pixels, n) = (40_000, 8u32);
        let (mut sum, mut sum_sq, mut predicted) = (0.0, 0.0, 0.0);
        for _ in 0..pixels {
            let (s, s2) = sums_of(n, &mut next);
            let b = pixel_bias2(n, s, s2);
            sum += b;
            sum_sq += b * b;
            predicted += pixel_bias2_noise(n, s, s2);
        }
        let measured = sum_sq / pixels as f64 - (sum / pixels as f64).powi(2);
        let predicted = predicted / pixels as f64;
        assert!((measured / predicted - 1.0).abs() < 0.2, "measured {measured}, predicted {predicted}");
        assert_eq!(pixel_bias2_noise(1, 1.0, 1.0), 0.0);
    }
}
