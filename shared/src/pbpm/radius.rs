//! The photon radius: from the pixel footprint at the photon, shrunk per phase as Knaus & Zwicker (2011)
//! prescribe so that the average over phases converges.

/// Radius schedule r_j = r_1 · j^((α−1)/2) with r_1 = scale × pixel footprint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RadiusSchedule {
    /// Initial radius in pixel footprints.
    pub scale: f32,
    /// Knaus–Zwicker α in (0, 1): the fraction of the variance-to-bias trade kept per phase.
    pub alpha: f32,
    /// Angle of one pixel (radians).
    pub pixel_angle: f32,
}

impl RadiusSchedule {
    /// The radius of a photon at camera-path length `path_length` (m) in phase `phase` (1-based).
    #[inline]
    pub fn radius(&self, path_length: f32, phase: u64) -> f32 {
        let r1 = self.scale * self.pixel_angle * path_length;
        r1 * self.shrink(phase)
    }

    /// r_j / r_1 = j^((α−1)/2).
    #[inline]
    pub fn shrink(&self, phase: u64) -> f32 {
        (phase.max(1) as f32).powf((self.alpha - 1.0) * 0.5)
    }

    /// The exponent β with which a pixel's squared blur falls with its phases N under a schedule of this
    /// `alpha`: each phase's bias grows as r², which shrinks as j^(α−1), so the mean over N phases falls as
    /// N^(α−1) and its square as N^(−2 (1 − α)).
    pub fn blur_decay(alpha: f32) -> f64 {
        2.0 * (1.0 - alpha as f64)
    }
}

/// Who else renders a pixel's phases, so that the schedule's j counts every phase the pixel has had across
/// groups and processes (assuming they progress alike), as in a single-threaded run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhaseNumbering {
    /// Groups of one process rendering the same pixels in a deal (1 with tile masks), and this group's rank.
    pub groups: u64,
    pub group: u64,
    /// Processes rendering the same image (combination, three-level), and this process's rank.
    pub processes: u64,
    pub process: u64,
    /// Phases every pixel had before this run (a resumed run).
    pub resumed: u64,
}

impl PhaseNumbering {
    /// One renderer of every pixel: j is the pixel's own phase count plus one.
    pub const ALONE: PhaseNumbering = PhaseNumbering { groups: 1, group: 0, processes: 1, process: 0, resumed: 0 };

    /// The 1-based j of a pixel's next phase, for a pixel that had `before_deal` phases (merged over every
    /// renderer) when the current deal started and has had `this_deal` phases of this group since.
    #[inline]
    pub fn next_phase(&self, before_deal: u64, this_deal: u64) -> u64 {
        (before_deal + this_deal * self.groups + self.group) * self.processes + self.process + self.resumed + 1
    }
}

/// The mean of `next_phase` (a local pixel's j) over a phase's `pixels` local pixels, rounded; 1 for none.
pub fn mean_phase(pixels: usize, next_phase: impl Fn(usize) -> u64) -> u64 {
    if pixels == 0 {
        return 1;
    }
    let sum: u128 = (0..pixels).map(|i| next_phase(i) as u128).sum();
    ((sum + pixels as u128 / 2) / pixels as u128) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radius_area_shrinks_as_j_to_alpha_minus_one() {
        let s = RadiusSchedule { scale: 2.0, alpha: 2.0 / 3.0, pixel_angle: 0.01 };
        let r1 = s.radius(1.5, 1);
        assert!((r1 - 0.03).abs() < 1e-7);
        let r8 = s.radius(1.5, 8);
        assert!(((r8 * r8) / (r1 * r1) - 8f32.powf(-1.0 / 3.0)).abs() < 1e-5);
    }

    #[test]
    fn the_mean_phase_of_a_phases_pixels_is_rounded_and_one_without_pixels() {
        assert_eq!(mean_phase(4, |i| [3, 3, 4, 4][i]), 4);
        assert_eq!(mean_phase(3, |i| [3, 3, 4][i]), 3);
        assert_eq!(mean_phase(2, |_| u64::MAX / 2), u64::MAX / 2);
        assert_eq!(mean_phase(0, |_| unreachable!()), 1);
    }

    #[test]
    fn phase_numbers_of_sharers_interleave_without_gaps_or_repeats() {
        // Two groups over one image in two processes: their first three phases each take j = 1..12 once.
        let mut seen = Vec::new();
        for process in 0..2 {
            for group in 0..2 {
                let n = PhaseNumbering { groups: 2, group, processes: 2, process, resumed: 0 };
                seen.extend((0..3).map(|k| n.next_phase(0, k)));
            }
        }
        seen.sort_unstable();
        assert_eq!(seen, (1..=12).collect::<Vec<_>>());
        assert_eq!(PhaseNumbering::ALONE.next_phase(4, 2), 7);
        let resumed = PhaseNumbering { resumed: 10, ..PhaseNumbering::ALONE };
        assert_eq!(resumed.next_phase(0, 0), 11);
    }
}
