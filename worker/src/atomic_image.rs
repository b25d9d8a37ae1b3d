//! The intermediate image light paths gather into: f32 luminance per local pixel, added with atomic
//! compare-and-swap loops because threads of several groups may gather into the same map (paper §4.2).

use photonfarm::color::Rgb;
use photonfarm::integrator::Layer;
use photonfarm::pbpm::Gather;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Gathered (indirect, caustic) RGB per local pixel of a group's mask.
#[derive(Default)]
pub struct GatherBuffer {
    values: Vec<AtomicU32>,
    /// Merges counted by the gatherers, for the statistics and the stress test's bookkeeping.
    merges: AtomicU64,
}

#[inline]
fn add_f32(a: &AtomicU32, v: f32) {
    let mut current = a.load(Ordering::Relaxed);
    loop {
        let new = (f32::from_bits(current) + v).to_bits();
        match a.compare_exchange_weak(current, new, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return,
            Err(x) => current = x,
        }
    }
}

impl GatherBuffer {
    /// Zeroes the buffer for `pixels` local pixels (owner only, while its map is closed).
    pub fn reset(&mut self, pixels: usize) {
        self.values.resize_with(pixels * 6, || AtomicU32::new(0));
        self.values.truncate(pixels * 6);
        for v in &mut self.values {
            *v.get_mut() = 0;
        }
        *self.merges.get_mut() = 0;
    }

    /// Gathered (indirect, caustic) of a local pixel.
    pub fn get(&self, local: usize) -> [Rgb; 2] {
        let f = |k: usize| f32::from_bits(self.values[local * 6 + k].load(Ordering::Relaxed));
        [Rgb::new(f(0), f(1), f(2)), Rgb::new(f(3), f(4), f(5))]
    }

    /// Merges recorded since the last reset.
    pub fn merges(&self) -> u64 {
        self.merges.load(Ordering::Relaxed)
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        self.values.capacity() * 4
    }

    /// A sink that adds into this buffer.
    pub fn sink(&self) -> AtomicSink<'_> {
        AtomicSink { buffer: self }
    }

    /// Records merges made into this buffer (callers count them per light path and add them once).
    pub fn add_merges(&self, n: u64) {
        if n > 0 {
            self.merges.fetch_add(n, Ordering::Relaxed);
        }
    }
}

/// Adds gathered light into a `GatherBuffer` from any thread.
pub struct AtomicSink<'a> {
    buffer: &'a GatherBuffer,
}

impl Gather for AtomicSink<'_> {
    #[inline]
    fn add(&mut self, pixel: u32, layer: Layer, value: Rgb) {
        let base = pixel as usize * 6 + if layer == Layer::Caustic { 3 } else { 0 };
        add_f32(&self.buffer.values[base], value.x);
        add_f32(&self.buffer.values[base + 1], value.y);
        add_f32(&self.buffer.values[base + 2], value.z);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn concurrent_atomic_adds_lose_nothing() {
        let mut b = GatherBuffer::default();
        b.reset(2);
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    let mut sink = b.sink();
                    for _ in 0..10_000 {
                        sink.add(1, Layer::Caustic, Rgb::new(1.0, 2.0, 0.5));
                    }
                    b.add_merges(10_000);
                });
            }
        });
        assert_eq!(b.get(1)[1], Rgb::new(40_000.0, 80_000.0, 20_000.0));
        assert_eq!(b.get(0), [Rgb::ZERO; 2]);
        assert_eq!(b.merges(), 40_000);
    }
}
