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
}

impl PhaseNumbering {
    /// One renderer of every pixel: j is the pixel's own phase count plus one.
    pub const ALONE: PhaseNumbering = PhaseNumbering { groups: 1, group: 0, processes: 1, process: 0 };

    /// A pixel's next phase, for a pixel that had `before_deal` phases over every process when the current
    /// deal started (`ProcessShare::phases_before`), `own_before_deal` of them this process's, and has had
    /// `this_deal` phases of this group since.
    #[inline]
    pub fn next_phase(&self, before_deal: u64, own_before_deal: u64, this_deal: u64) -> PixelPhase {
        let own = this_deal * self.groups + self.group;
        PixelPhase { radius: before_deal + own * self.processes + self.process + 1, sample: own_before_deal + own + 1 }
    }
}

/// A pixel's next phase as two 1-based numbers. `radius` is its j among the phases the pixel has had over every
/// renderer, which sets the photon radius as if one process had rendered them all. `sample` is its j among this
/// process's own phases of the pixel, which picks the replicate and the point of the pixel's quasi-random
/// sequences: every process scrambles its own sequences, so its phases must walk them without gaps and cycle
/// through the replicates whatever the other processes do. One renderer alone has both equal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelPhase {
    pub radius: u64,
    pub sample: u64,
}

impl PixelPhase {
    /// Phase j of a lone renderer.
    #[inline]
    pub fn alone(j: u64) -> Self {
        PixelPhase { radius: j, sample: j }
    }
}

/// How one of several processes rendering an image counts a pixel's phases over all of them: from an anchor,
/// the pixel's phases over every process when the share began, each phase of this process standing for one
/// phase of every process (they progress alike). A share is planned (every pixel anchored at the phases a
/// resumed run had) or announced by the coordinator when the processes rendering the image change.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProcessShare {
    /// Processes rendering the image, and this one's rank among them.
    pub processes: u64,
    pub rank: u64,
    /// Per pixel, the phases over every process at the anchor (empty: `resumed` for every pixel).
    anchor: Vec<u32>,
    /// Per pixel, this process's own phases at the anchor (empty: none).
    own_at_anchor: Vec<u32>,
    resumed: u64,
}

impl ProcessShare {
    /// A lone process of a run never resumed.
    pub const ALONE: ProcessShare =
        ProcessShare { processes: 1, rank: 0, anchor: Vec::new(), own_at_anchor: Vec::new(), resumed: 0 };

    /// The share planned before the run: `processes` processes from the start, every pixel with `resumed`
    /// phases of earlier sessions.
    pub fn planned(processes: u32, rank: u32, resumed: u32) -> Self {
        let processes = processes.max(1) as u64;
        ProcessShare { processes, rank: (rank as u64).min(processes - 1), resumed: resumed as u64, ..Self::ALONE }
    }

    /// The share the coordinator announced: `processes` processes render from now on, this one with `rank`;
    /// `merged[p]` is pixel p's phases merged at the coordinator (every process's, earlier sessions' and lost
    /// processes' included), `own[p]` this process's phases of p now and `own_sent[p]` those of them already
    /// sent, which `merged` holds. The anchor adds this process's unsent phases to the merged ones. Pixels
    /// whose counts do not match the image are refused.
    pub fn announced(processes: u32, rank: u32, merged: &[u32], own: &[u32], own_sent: &[u32]) -> Result<Self, String> {
        if merged.len() != own.len() || own_sent.len() != own.len() {
            return Err(format!("the announced phases cover {} pixels, the image has {}", merged.len(), own.len()));
        }
        if processes == 0 || rank >= processes {
            return Err(format!("rank {rank} of {processes} processes"));
        }
        let anchor = (0..own.len()).map(|p| merged[p].saturating_add(own[p].saturating_sub(own_sent[p]))).collect();
        Ok(ProcessShare {
            processes: processes as u64,
            rank: rank as u64,
            anchor,
            own_at_anchor: own.to_vec(),
            resumed: 0,
        })
    }

    /// The phases pixel `pixel` has had over every process, given this process's own `own` phases of it.
    #[inline]
    pub fn phases_before(&self, pixel: usize, own: u32) -> u64 {
        let anchor = self.anchor.get(pixel).map_or(self.resumed, |&a| a as u64);
        let own_at_anchor = self.own_at_anchor.get(pixel).copied().unwrap_or(0);
        anchor + own.saturating_sub(own_at_anchor) as u64 * self.processes
    }

    /// The numbering of a group of this process (`groups` groups sharing a pixel, this one `group`).
    pub fn numbering(&self, groups: u64, group: u64) -> PhaseNumbering {
        PhaseNumbering { groups, group, processes: self.processes, process: self.rank }
    }

    /// Bytes per image pixel an announced share holds.
    pub const BYTES_PER_PIXEL: usize = 8;
}

/// The mean of `next_phase` (a local pixel's radius j) over a phase's `pixels` local pixels, rounded; 1 for
/// none.
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
                let n = ProcessShare::planned(2, process, 0).numbering(2, group as u64);
                seen.extend((0..3).map(|k| n.next_phase(0, 0, k).radius));
            }
        }
        seen.sort_unstable();
        assert_eq!(seen, (1..=12).collect::<Vec<_>>());
        assert_eq!(PhaseNumbering::ALONE.next_phase(4, 4, 2), PixelPhase::alone(7));
        let resumed = ProcessShare::planned(1, 0, 10);
        assert_eq!(resumed.numbering(1, 0).next_phase(resumed.phases_before(0, 0), 0, 0).radius, 11);
    }

    #[test]
    fn a_process_s_own_phases_walk_its_sequences_without_gaps_through_every_replicate() {
        // Three processes, two groups without masks in each: process 1's sample numbers are its own phases of
        // the pixel, 1, 2, 3, …, while their radius numbers step by three.
        let share = ProcessShare::planned(3, 1, 0);
        let mut samples = Vec::new();
        let mut radii = Vec::new();
        for group in 0..2 {
            let n = share.numbering(2, group);
            samples.extend((0..4).map(|k| n.next_phase(0, 0, k).sample));
            radii.extend((0..4).map(|k| n.next_phase(0, 0, k).radius));
        }
        samples.sort_unstable();
        radii.sort_unstable();
        assert_eq!(samples, (1..=8).collect::<Vec<_>>());
        assert_eq!(radii, (0..8).map(|i| 3 * i + 2).collect::<Vec<_>>());
    }

    #[test]
    fn an_announced_share_counts_from_the_merged_phases_and_this_process_s_unsent_ones() {
        // Pixel 0 had 10 phases merged, 4 of them this process's; it has rendered 2 more since its last snapshot.
        // From now on two processes share the image: each of its phases stands for two.
        let share = ProcessShare::announced(2, 1, &[10, 0], &[6, 0], &[4, 0]).unwrap();
        assert_eq!(share.phases_before(0, 6), 12);
        assert_eq!(share.phases_before(0, 9), 18);
        let next = share.numbering(1, 0).next_phase(share.phases_before(0, 9), 9, 0);
        assert_eq!(next, PixelPhase { radius: 20, sample: 10 });
        // A process that joins late starts at the pixel's merged phases, not at zero, and samples from the start
        // of its own sequences.
        let late = ProcessShare::announced(2, 0, &[30], &[0], &[0]).unwrap();
        assert_eq!(
            late.numbering(1, 0).next_phase(late.phases_before(0, 0), 0, 0),
            PixelPhase { radius: 31, sample: 1 }
        );
        assert!(ProcessShare::announced(2, 0, &[1, 2], &[0], &[0]).is_err());
        assert!(ProcessShare::announced(2, 2, &[1], &[0], &[0]).is_err());
    }
}
