//! The intermediate image light paths gather into: f32 luminance per local pixel, added with atomic
//! compare-and-swap loops because threads of several groups may gather into the same map (paper §4.2).

use photonfarm::accumulation::AuxLayout;
use photonfarm::color::Rgb;
use photonfarm::ghost::GHOST_LAYER;
use photonfarm::integrator::Layer;
use photonfarm::pbpm::Gather;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Gathered (indirect, caustic) RGB per local pixel of a group's mask, followed by the pixel's auxiliary
/// channels (the ghost layer's gathered light) when the image has auxiliary layers.
#[derive(Default)]
pub struct GatherBuffer {
    values: Vec<AtomicU32>,
    /// Values per pixel: 6, plus the auxiliary channels.
    stride: usize,
    /// Where the ghost layer's channels start among a pixel's values, when there is one.
    ghost: Option<usize>,
    /// Merges counted by the gatherers, for the statistics and the stress test's bookkeeping.
    merges: AtomicU64,
    /// Every value is zero (set by `clear_parallel`, cleared when a phase starts adding).
    clean: bool,
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
    /// Readies the buffer for `pixels` local pixels with the auxiliary channels of `aux` (owner only, while its
    /// map is closed): zeroed, unless `clear_parallel` already zeroed it at this size.
    pub fn reset(&mut self, pixels: usize, aux: &AuxLayout) {
        let stride = 6 + aux.channels();
        let ghost = aux.offset(GHOST_LAYER).map(|o| 6 + o);
        if !(self.clean && self.stride == stride && self.ghost == ghost && self.values.len() == pixels * stride) {
            self.stride = stride;
            self.ghost = ghost;
            self.values.resize_with(pixels * stride, || AtomicU32::new(0));
            self.values.truncate(pixels * stride);
            for v in &mut self.values {
                *v.get_mut() = 0;
            }
        }
        self.clean = false;
        *self.merges.get_mut() = 0;
    }

    /// Zeroes the buffer with the threads of the current rayon pool once the phase has read it (owner only, while
    /// its map is closed), so that the next `reset` has nothing to do on the group's first thread alone.
    pub fn clear_parallel(&mut self) {
        self.values.par_iter_mut().for_each(|v| *v.get_mut() = 0);
        self.clean = true;
    }

    /// Gathered (indirect, caustic) of a local pixel.
    pub fn get(&self, local: usize) -> [Rgb; 2] {
        let f = |k: usize| f32::from_bits(self.values[local * self.stride + k].load(Ordering::Relaxed));
        [Rgb::new(f(0), f(1), f(2)), Rgb::new(f(3), f(4), f(5))]
    }

    /// Gathered auxiliary channel `channel` of a local pixel.
    pub fn get_aux(&self, local: usize, channel: usize) -> f32 {
        f32::from_bits(self.values[local * self.stride + 6 + channel].load(Ordering::Relaxed))
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
    fn add(&mut self, pixel: u32, layer: Layer, ghost: bool, value: Rgb) {
        let pixel_base = pixel as usize * self.buffer.stride;
        let base = pixel_base + if layer == Layer::Caustic { 3 } else { 0 };
        add_f32(&self.buffer.values[base], value.x);
        add_f32(&self.buffer.values[base + 1], value.y);
        add_f32(&self.buffer.values[base + 2], value.z);
        if let (true, Some(g)) = (ghost, self.buffer.ghost) {
            add_f32(&self.buffer.values[pixel_base + g], value.x);
            add_f32(&self.buffer.values[pixel_base + g + 1], value.y);
            add_f32(&self.buffer.values[pixel_base + g + 2], value.z);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn concurrent_atomic_adds_lose_nothing() {
        let mut b = GatherBuffer::default();
        b.reset(2, &AuxLayout::default());
        std::thread::scope(|s| {
            for _ in 0..4 {
                s.spawn(|| {
                    let mut sink = b.sink();
                    for _ in 0..10_000 {
                        sink.add(1, Layer::Caustic, true, Rgb::new(1.0, 2.0, 0.5));
                    }
                    b.add_merges(10_000);
                });
            }
        });
        assert_eq!(b.get(1)[1], Rgb::new(40_000.0, 80_000.0, 20_000.0));
        assert_eq!(b.get(0), [Rgb::ZERO; 2]);
        assert_eq!(b.merges(), 40_000);
        assert_eq!(b.capacity_bytes(), 2 * 6 * 4, "no ghost channels without a ghost layer");
    }

    #[test]
    fn ghost_light_lands_in_its_layer_and_its_usual_layer_but_other_light_only_in_its_usual_layer() {
        let ghost = AuxLayout::new(vec![
            photonfarm::accumulation::AuxLayer { name: "band".into(), channels: 1 },
            photonfarm::accumulation::AuxLayer { name: GHOST_LAYER.into(), channels: 3 },
        ]);
        let mut b = GatherBuffer::default();
        b.reset(3, &ghost);
        let mut sink = b.sink();
        sink.add(2, Layer::Indirect, true, Rgb::new(1.0, 2.0, 3.0));
        sink.add(2, Layer::Caustic, false, Rgb::splat(10.0));
        sink.add(1, Layer::Caustic, true, Rgb::splat(0.5));
        assert_eq!(b.get(2), [Rgb::new(1.0, 2.0, 3.0), Rgb::splat(10.0)]);
        assert_eq!([0, 1, 2, 3].map(|c| b.get_aux(2, c)), [0.0, 1.0, 2.0, 3.0]);
        assert_eq!([0, 1, 2, 3].map(|c| b.get_aux(1, c)), [0.0, 0.5, 0.5, 0.5]);
        assert_eq!(b.get(0), [Rgb::ZERO; 2]);
        assert_eq!([0, 1, 2, 3].map(|c| b.get_aux(0, c)), [0.0; 4]);
    }

    #[test]
    fn a_reset_starts_every_phase_from_zero_whether_or_not_the_last_phase_cleared_the_buffer() {
        let ghost = AuxLayout::new(vec![photonfarm::accumulation::AuxLayer { name: GHOST_LAYER.into(), channels: 3 }]);
        // Each sequence adds light at some point and ends with a reset, at 2 pixels without auxiliary layers:
        // adds left over without a clear, adds cleared in parallel, and adds after a clear whose reset came.
        let sequences: [&[&str]; 3] =
            [&["reset", "add", "reset"], &["reset", "add", "clear", "reset"], &["clear", "reset", "add", "reset"]];
        for steps in sequences {
            let mut b = GatherBuffer::default();
            b.reset(2, &AuxLayout::default());
            for &step in steps {
                match step {
                    "reset" => b.reset(2, &AuxLayout::default()),
                    "clear" => b.clear_parallel(),
                    _ => b.sink().add(1, Layer::Indirect, true, Rgb::ONE),
                }
            }
            assert_eq!(b.get(1), [Rgb::ZERO; 2], "{steps:?}");
        }
        // A new layout after a clear: sized and zeroed for it.
        let mut b = GatherBuffer::default();
        b.reset(2, &AuxLayout::default());
        b.sink().add(1, Layer::Indirect, true, Rgb::ONE);
        b.clear_parallel();
        b.reset(3, &ghost);
        assert!(b.capacity_bytes() >= 3 * 9 * 4);
        assert_eq!((b.get(2), [0, 1, 2].map(|c| b.get_aux(2, c))), ([Rgb::ZERO; 2], [0.0; 3]));
    }
}
