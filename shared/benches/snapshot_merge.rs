//! What a coordinator pays per snapshot: encoding a worker's delta (worker side) and checking and merging it
//! into the whole image (coordinator side), at 256×256 and 1920×1080, with sums like a render's after a few
//! phases per pixel.
//!
//! `cargo bench -p photonfarm --bench snapshot_merge` — criterion prints the time per snapshot; the compressed
//! size is printed once per resolution.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use photonfarm::accumulation::delta::{apply_delta, encode_delta, Compression};
use photonfarm::accumulation::Accumulator;
use photonfarm::color::Rgb;
use photonfarm::sampling::{Pass, Sampler, REPLICATES};
use std::hint::black_box;

/// Sums of `phases` random phases per pixel.
fn sums(width: u32, height: u32, phases: u32, seed: u64) -> Accumulator {
    let mut a = Accumulator::new(width, height);
    let mut s = Sampler::new(seed, Pass::Camera, 0, 0);
    for i in 0..(width * height) as usize {
        for j in 0..phases as usize {
            let v = Rgb::new(s.next_f32(), s.next_f32(), s.next_f32());
            a.add_phase(i, &[Rgb::ZERO, v * 0.6, v * 0.3 * s.next_f32(), v * 0.1 * s.next_f32()], 1, j % REPLICATES);
        }
    }
    a
}

fn snapshot_merge(c: &mut Criterion) {
    let mut group = c.benchmark_group("snapshot");
    group.sample_size(10);
    for (w, h) in [(256u32, 256u32), (1920, 1080)] {
        let base = sums(w, h, 6, 1);
        let mut current = base.clone();
        current.merge(&sums(w, h, 6, 2));
        for compression in [Compression::Fast, Compression::Small] {
            let delta = encode_delta(&current, &base, compression);
            eprintln!(
                "{w}×{h}, {compression:?}: a snapshot of 6 new phases per pixel is {:.2} MB ({:.1} bytes per pixel, \
                 {:.0} raw)",
                delta.len() as f64 / 1e6,
                delta.len() as f64 / (w * h) as f64,
                8.0 + 8.0 * 17.0
            );
            let id = format!("{w}x{h}-{compression:?}").to_lowercase();
            group.bench_with_input(BenchmarkId::new("encode", id), &(), |b, _| {
                b.iter(|| black_box(encode_delta(&current, &base, compression)))
            });
        }
        let delta = encode_delta(&current, &base, Compression::Small);
        let mut target = Accumulator::new(w, h);
        group.bench_with_input(BenchmarkId::new("check_and_merge", format!("{w}x{h}")), &(), |b, _| {
            b.iter(|| black_box(apply_delta(&delta, &mut target).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, snapshot_merge);
criterion_main!(benches);
