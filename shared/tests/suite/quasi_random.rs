//! The quasi-random camera and light streams: a pixel's phases stratify its first dimensions, its replicates
//! are independent scramblings, and the SEM from the spread of the replicate means matches the true error where
//! the per-phase SEM, which assumes independent phases, overstates it.

use photonfarm::accumulation::Accumulator;
use photonfarm::color::Rgb;
use photonfarm::sampling::{replicate_of, Sampler, REPLICATES};

/// The camera stream of phase `j` of `pixel`, with a phase key that changes every phase as a render's does.
fn camera(pixel: u64, j: u64) -> Sampler {
    Sampler::camera(7, 1000 + j, pixel, j)
}

/// The phase numbers j of a pixel that replicate `r` draws, in order.
fn phases_of_replicate(r: usize, count: usize) -> impl Iterator<Item = u64> {
    (1..).filter(move |&j| replicate_of(j).0 == r).take(count)
}

#[test]
fn the_first_phases_of_a_replicate_put_one_jitter_point_in_every_stratum() {
    for pixel in [0, 17, 40_000] {
        for r in 0..REPLICATES {
            let points: Vec<(f32, f32)> = phases_of_replicate(r, 16)
                .map(|j| {
                    let mut s = camera(pixel, j);
                    (s.next_f32(), s.next_f32())
                })
                .collect();
            // 16 points of a (0, 4, 2)-net: one in each cell of the 4 × 4, 16 × 1 and 1 × 16 grids.
            for (nx, ny) in [(4, 4), (16, 1), (1, 16), (2, 8), (8, 2)] {
                let mut cells = vec![0; nx * ny];
                for &(x, y) in &points {
                    cells[(x * nx as f32) as usize + nx * (y * ny as f32) as usize] += 1;
                }
                assert!(cells.iter().all(|&c| c == 1), "pixel {pixel}, replicate {r}, {nx} × {ny}: {cells:?}");
            }
        }
    }
}

#[test]
fn streams_repeat_for_the_same_pixel_and_phase_and_differ_between_pixels() {
    let draw = |mut s: Sampler| (0..20).map(|_| s.next_f32()).collect::<Vec<_>>();
    assert_eq!(draw(camera(5, 9)), draw(camera(5, 9)));
    assert_ne!(draw(camera(5, 9)), draw(camera(6, 9)));
    assert_eq!(draw(Sampler::light(3, 11, 42)), draw(Sampler::light(3, 11, 42)));
    assert_ne!(draw(Sampler::light(3, 11, 42)), draw(Sampler::light(3, 12, 42)), "phases scramble anew");
    // Past the Sobol dimensions the stream goes on pseudo-randomly, in [0, 1).
    assert!(draw(camera(5, 9)).iter().all(|u| (0.0..1.0).contains(u)));
}

#[test]
fn runs_with_neighbouring_seeds_share_no_scrambling() {
    // A run's repeats take seeds s, s + 1, ...: each (seed, replicate) must draw its own Sobol points, so the
    // first jitter of a pixel's first phase in every replicate differs over all of them.
    let mut firsts: Vec<(u32, u32)> = (0..8u64)
        .flat_map(|seed| {
            (0..REPLICATES).map(move |r| {
                let j = phases_of_replicate(r, 1).next().unwrap();
                let mut s = Sampler::camera(seed, 1000 + j, 17, j);
                (s.next_f32().to_bits(), s.next_f32().to_bits())
            })
        })
        .collect();
    let drawn = firsts.len();
    firsts.sort_unstable();
    firsts.dedup();
    assert_eq!(firsts.len(), drawn, "two (seed, replicate) pairs share a scrambling");
}

#[test]
fn replicates_of_a_pixel_are_uncorrelated_scramblings() {
    // The first point of replicates 0 and 1 over many pixels: independent scramblings leave no correlation.
    let pixels = 20_000u64;
    let (a, b): (Vec<f64>, Vec<f64>) = (0..pixels)
        .map(|p| {
            let first = |r| camera(p, phases_of_replicate(r, 1).next().unwrap()).next_f32() as f64;
            (first(0), first(1))
        })
        .unzip();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (ma, mb) = (mean(&a), mean(&b));
    let cov = a.iter().zip(&b).map(|(x, y)| (x - ma) * (y - mb)).sum::<f64>() / pixels as f64;
    let correlation = cov / (1.0 / 12.0);
    // Four standard errors of a correlation of independent uniforms.
    assert!(correlation.abs() < 4.0 / (pixels as f64).sqrt(), "correlation {correlation:.4}");
    assert!((ma - 0.5).abs() < 0.01 && (mb - 0.5).abs() < 0.01, "first points are uniform: {ma:.4}, {mb:.4}");
}

#[test]
fn replicate_sem_matches_the_true_error_where_the_per_phase_sem_overstates_it() {
    // Each "pixel" estimates the area under an edge, u + v < 0.8 (0.32), from its camera stream's jitter, as a
    // pixel on the edge of a directly seen light does.
    let (pixels, phases) = (4000usize, 64u64);
    let mut sums = Accumulator::new(pixels as u32, 1);
    for p in 0..pixels {
        for j in 1..=phases {
            let mut s = camera(p as u64, j);
            let value = if s.next_f32() + s.next_f32() < 0.8 { 1.0 } else { 0.0 };
            sums.add_phase(p, &[Rgb::splat(value), Rgb::ZERO, Rgb::ZERO, Rgb::ZERO], 1, replicate_of(j).0);
        }
    }
    let truth = 0.32;
    let (mut err2, mut replicate_sem2, mut phase_sem2) = (0.0, 0.0, 0.0);
    for p in 0..pixels {
        let m = sums.mean_total(p)[1];
        err2 += (m - truth) * (m - truth);
        replicate_sem2 += sums.replicate_sem2(p);
        phase_sem2 += sums.sem2(p);
    }
    let calibration = (err2 / replicate_sem2).sqrt();
    let overstatement = (phase_sem2 / err2).sqrt();
    eprintln!("true error / replicate SEM {calibration:.3}; per-phase SEM / true error {overstatement:.2}");
    // err2 and replicate_sem2 each average 4000 pixels: their ratio is known to a few per cent.
    assert!((0.9..1.1).contains(&calibration), "true error / replicate SEM = {calibration:.3}");
    assert!(overstatement > 2.0, "quasi-random phases are no better than random ones: {overstatement:.2}");
}
