//! The forward pass's last step in the worker: adding gathered light into an `AtomicGatherBuffer` through its
//! sink (three f32 compare-and-swap loops per add), at random pixels of a 256×256 mask. One thread; two threads
//! into one shared buffer, as groups gathering into the same open map do; two threads into two separate buffers,
//! the same work without sharing; one thread through the sole-writer sink (a load and a store per value), as the
//! one foreign thread of two one-thread groups adds; and, as the baseline, plain non-atomic f32 adds on one
//! thread as the single-threaded engine does them.
//!
//! With random pixels over a 1.5 MB buffer two threads rarely hit the same pixel at once: the shared-buffer
//! cost is mostly cache lines moving between the cores, not retried compare-and-swaps.
//!
//! `cargo bench -p worker --bench atomic_accumulation` — criterion prints elements/s = adds/s over all threads.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use photonfarm::color::Rgb;
use photonfarm::integrator::Layer;
use photonfarm::pbpm::AtomicGatherBuffer;
use photonfarm::pbpm::Gather;
use photonfarm::sampling::{Pass, Sampler};
use std::hint::black_box;
use std::time::Duration;

const PIXELS: usize = 256 * 256;
/// Adds per thread per iteration: enough that spawning the second thread is a negligible part of an iteration.
const ADDS: usize = 1 << 20;

/// Random (pixel, layer, value) adds, a different stream per thread.
fn adds(thread: u64) -> Vec<(u32, Layer, Rgb)> {
    let mut s = Sampler::new(1, Pass::Light, 1, thread);
    (0..ADDS)
        .map(|_| {
            let pixel = ((s.next_f32() * PIXELS as f32) as u32).min(PIXELS as u32 - 1);
            let layer = if s.next_f32() < 0.1 { Layer::Caustic } else { Layer::Indirect };
            (pixel, layer, Rgb::new(s.next_f32(), s.next_f32(), s.next_f32()) * 1e-3)
        })
        .collect()
}

fn buffer() -> AtomicGatherBuffer {
    let mut b = AtomicGatherBuffer::default();
    b.reset(PIXELS, &photonfarm::accumulation::AuxLayout::default());
    b
}

fn add_all(buffer: &AtomicGatherBuffer, adds: &[(u32, Layer, Rgb)]) {
    let mut sink = buffer.sink();
    for &(pixel, layer, value) in adds {
        sink.add(black_box(pixel), layer, false, value);
    }
}

fn atomic_accumulation(c: &mut Criterion) {
    let (a, b) = (adds(0), adds(1));
    let (shared, first, second) = (buffer(), buffer(), buffer());

    let mut group = c.benchmark_group("gather_buffer_256x256");
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    group.throughput(Throughput::Elements(ADDS as u64));
    let mut plain = vec![[Rgb::ZERO; 2]; PIXELS];
    group.bench_function("single_thread_plain_f32", |bench| {
        bench.iter(|| {
            for &(pixel, layer, value) in &a {
                plain[black_box(pixel) as usize][(layer == Layer::Caustic) as usize] += value;
            }
        })
    });
    group.bench_function("single_thread_atomic", |bench| bench.iter(|| add_all(&shared, &a)));
    group.bench_function("single_thread_sole_writer", |bench| {
        bench.iter(|| {
            let mut sink = shared.sole_writer_sink();
            for &(pixel, layer, value) in &a {
                sink.add(black_box(pixel), layer, false, value);
            }
        })
    });

    group.throughput(Throughput::Elements(2 * ADDS as u64));
    // The calling thread is the second adder, so each iteration spawns one thread.
    group.bench_function("two_threads_shared_buffer", |bench| {
        bench.iter(|| {
            std::thread::scope(|s| {
                s.spawn(|| add_all(&shared, &b));
                add_all(&shared, &a);
            })
        })
    });
    group.bench_function("two_threads_separate_buffers", |bench| {
        bench.iter(|| {
            std::thread::scope(|s| {
                s.spawn(|| add_all(&second, &b));
                add_all(&first, &a);
            })
        })
    });
    group.finish();
}

criterion_group!(benches, atomic_accumulation);
criterion_main!(benches);
