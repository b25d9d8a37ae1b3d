//! Where the forward pass's gathered light waits for the phase to close: f32 (indirect, caustic) RGB per local
//! pixel of the phase, then the pixel's auxiliary channels (the ghost layer's gathered light, the blur
//! difference D), then, in an image with a ghost layer, the visible light that ghost chains brought to the
//! sensor. A plain buffer takes the adds of one thread; an atomic one takes adds from any thread, for light paths of other groups
//! gathering into an open map (paper §4.2) and for groups whose threads share their own map.

use super::forward_pass::Gather;
use crate::accumulation::blur::BLUR_LAYER;
use crate::accumulation::AuxLayout;
use crate::color::Rgb;
use crate::ghost::GHOST_LAYER;
use crate::integrator::Layer;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Values per pixel before the auxiliary channels: (indirect, caustic) × RGB.
const FIXED: usize = 6;

/// How a pixel's values are laid out: their count, where the ghost layer's channels start, and where the
/// visible light of ghost chains registered on the sensor goes (an image without a ghost layer has none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Stride {
    values: usize,
    ghost: Option<usize>,
    blur: Option<usize>,
    visible: Option<usize>,
}

impl Stride {
    fn of(aux: &AuxLayout) -> Self {
        let ghost = aux.offset(GHOST_LAYER).map(|o| FIXED + o);
        let blur = aux.offset(BLUR_LAYER).map(|o| FIXED + o);
        let visible = ghost.map(|_| FIXED + aux.channels());
        Stride { values: FIXED + aux.channels() + if visible.is_some() { 3 } else { 0 }, ghost, blur, visible }
    }

    /// The value indices an add of `value` to `layer` (and to the ghost layer, for ghost light) touches, with
    /// the channel each takes.
    #[inline]
    fn targets(&self, pixel: u32, layer: Layer, ghost: bool) -> (usize, Option<usize>) {
        debug_assert!(
            layer != Layer::VisibleLights || self.visible.is_some(),
            "visible light gathered without a ghost layer"
        );
        let base = pixel as usize * self.values;
        let usual = base
            + match (layer, self.visible) {
                (Layer::Caustic, _) => 3,
                (Layer::VisibleLights, Some(v)) => v,
                _ => 0,
            };
        (usual, self.ghost.filter(|_| ghost).map(|g| base + g))
    }
}

/// Gathered light of one phase added by one thread. Zero between phases: `close` in `phase.rs` reads it and
/// zeroes it as it goes, and `absorb` zeroes what it takes.
#[derive(Clone, Debug, Default)]
pub struct GatherBuffer {
    values: Vec<f32>,
    stride: Stride,
}

impl GatherBuffer {
    /// Zeroes every value: the light of a phase that is left out instead of closed.
    pub fn clear(&mut self) {
        self.values.fill(0.0);
    }

    /// Sizes the buffer for `pixels` local pixels with the auxiliary channels of `aux`, all zero.
    pub fn reset(&mut self, pixels: usize, aux: &AuxLayout) {
        let stride = Stride::of(aux);
        if stride != self.stride {
            self.values.clear();
            self.stride = stride;
        }
        // Values already held are zero (the invariant above): only new ones need writing.
        self.values.resize(pixels * stride.values, 0.0);
    }

    /// Values per pixel: 6, plus the auxiliary channels, plus 3 with a ghost layer.
    pub fn stride(&self) -> usize {
        self.stride.values
    }

    /// Where a pixel's visible light from the sensor starts among its values, in an image with a ghost layer.
    pub fn visible_offset(&self) -> Option<usize> {
        self.stride.visible
    }

    /// Every pixel's values, pixel after pixel.
    pub fn values_mut(&mut self) -> &mut [f32] {
        &mut self.values
    }

    /// Gathered (indirect, caustic) of a local pixel.
    pub fn get(&self, local: usize) -> [Rgb; 2] {
        let v = &self.values[local * self.stride.values..];
        [Rgb::new(v[0], v[1], v[2]), Rgb::new(v[3], v[4], v[5])]
    }

    /// Gathered auxiliary channel `channel` of a local pixel.
    pub fn get_aux(&self, local: usize, channel: usize) -> f32 {
        self.values[local * self.stride.values + FIXED + channel]
    }

    /// Adds what `other` gathered into this buffer and zeroes `other`, with the threads of the current rayon
    /// pool. Both buffers must have the same size and layout.
    pub fn absorb(&mut self, other: &mut AtomicGatherBuffer) {
        assert_eq!(
            (self.values.len(), self.stride),
            (other.values.len(), other.stride),
            "absorbing gathered light of another size"
        );
        self.values.par_iter_mut().zip(other.values.par_iter_mut()).for_each(|(a, b)| {
            *a += f32::from_bits(std::mem::take(b.get_mut()));
        });
        other.clean = true;
    }

    /// Adds what another thread's plain buffer gathered into this one and zeroes it, with the threads of the
    /// current rayon pool. Both buffers must have the same size and layout.
    pub fn absorb_plain(&mut self, other: &mut GatherBuffer) {
        assert_eq!(
            (self.values.len(), self.stride),
            (other.values.len(), other.stride),
            "absorbing gathered light of another size"
        );
        self.values.par_iter_mut().zip(other.values.par_iter_mut()).with_min_len(1 << 12).for_each(|(a, b)| {
            *a += std::mem::take(b);
        });
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        self.values.capacity() * 4
    }
}

impl Gather for GatherBuffer {
    #[inline]
    fn add(&mut self, pixel: u32, layer: Layer, ghost: bool, value: Rgb) {
        let (usual, ghost) = self.stride.targets(pixel, layer, ghost);
        for (v, c) in self.values[usual..usual + 3].iter_mut().zip([value.x, value.y, value.z]) {
            *v += c;
        }
        if let Some(g) = ghost {
            for (v, c) in self.values[g..g + 3].iter_mut().zip([value.x, value.y, value.z]) {
                *v += c;
            }
        }
    }

    #[inline]
    fn measures_blur(&self) -> bool {
        self.stride.blur.is_some()
    }

    #[inline]
    fn add_blur(&mut self, pixel: u32, d: f32) {
        if let Some(b) = self.stride.blur {
            self.values[pixel as usize * self.stride.values + b] += d;
        }
    }
}

/// Gathered light of one phase added from any thread by f32 compare-and-swap loops, with a count of the merges
/// the adders made.
#[derive(Debug, Default)]
pub struct AtomicGatherBuffer {
    values: Vec<AtomicU32>,
    stride: Stride,
    merges: AtomicU64,
    /// Every value is zero (set by `GatherBuffer::absorb` and `reset`).
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

impl AtomicGatherBuffer {
    /// Readies the buffer for `pixels` local pixels with the auxiliary channels of `aux` (by its owner, while
    /// no other thread adds): zero, with no merges counted.
    pub fn reset(&mut self, pixels: usize, aux: &AuxLayout) {
        let stride = Stride::of(aux);
        if !(self.clean && self.stride == stride && self.values.len() == pixels * stride.values) {
            self.stride = stride;
            self.values.resize_with(pixels * stride.values, || AtomicU32::new(0));
            self.values.truncate(pixels * stride.values);
            self.values.par_iter_mut().for_each(|v| *v.get_mut() = 0);
        }
        self.clean = false;
        *self.merges.get_mut() = 0;
    }

    /// Gathered (indirect, caustic) of a local pixel.
    pub fn get(&self, local: usize) -> [Rgb; 2] {
        let f = |k: usize| f32::from_bits(self.values[local * self.stride.values + k].load(Ordering::Relaxed));
        [Rgb::new(f(0), f(1), f(2)), Rgb::new(f(3), f(4), f(5))]
    }

    /// Gathered auxiliary channel `channel` of a local pixel.
    pub fn get_aux(&self, local: usize, channel: usize) -> f32 {
        f32::from_bits(self.values[local * self.stride.values + FIXED + channel].load(Ordering::Relaxed))
    }

    /// Merges recorded since the last reset.
    pub fn merges(&self) -> u64 {
        self.merges.load(Ordering::Relaxed)
    }

    /// Records merges made into this buffer (callers count them per batch of light paths and add them once).
    pub fn add_merges(&self, n: u64) {
        if n > 0 {
            self.merges.fetch_add(n, Ordering::Relaxed);
        }
    }

    /// A sink that adds into this buffer from any thread.
    pub fn sink(&self) -> AtomicSink<'_> {
        AtomicSink { buffer: self, sole: false }
    }

    /// A sink for the one thread that adds into this buffer while its map is open (two groups of one thread
    /// each: the other group's thread is the only foreign adder). Each add is then a load and a store, as cheap
    /// as a plain add, instead of a compare-and-swap loop; a second thread adding at the same time would lose
    /// adds, so the caller must know it is alone.
    pub fn sole_writer_sink(&self) -> AtomicSink<'_> {
        AtomicSink { buffer: self, sole: true }
    }

    /// Bytes held.
    pub fn capacity_bytes(&self) -> usize {
        self.values.capacity() * 4
    }
}

/// Adds gathered light into an `AtomicGatherBuffer`.
pub struct AtomicSink<'a> {
    buffer: &'a AtomicGatherBuffer,
    /// No other thread adds into the buffer meanwhile (`sole_writer_sink`).
    sole: bool,
}

impl AtomicSink<'_> {
    #[inline]
    fn add_one(&self, a: &AtomicU32, c: f32) {
        if self.sole {
            a.store((f32::from_bits(a.load(Ordering::Relaxed)) + c).to_bits(), Ordering::Relaxed);
        } else {
            add_f32(a, c);
        }
    }

    #[inline]
    fn add_rgb(&self, first: usize, value: Rgb) {
        let values = &self.buffer.values[first..first + 3];
        for (a, c) in values.iter().zip([value.x, value.y, value.z]) {
            self.add_one(a, c);
        }
    }
}

impl Gather for AtomicSink<'_> {
    #[inline]
    fn add(&mut self, pixel: u32, layer: Layer, ghost: bool, value: Rgb) {
        let (usual, ghost) = self.buffer.stride.targets(pixel, layer, ghost);
        self.add_rgb(usual, value);
        if let Some(g) = ghost {
            self.add_rgb(g, value);
        }
    }

    #[inline]
    fn measures_blur(&self) -> bool {
        self.buffer.stride.blur.is_some()
    }

    #[inline]
    fn add_blur(&mut self, pixel: u32, d: f32) {
        if let Some(b) = self.buffer.stride.blur {
            self.add_one(&self.buffer.values[pixel as usize * self.buffer.stride.values + b], d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accumulation::AuxLayer;

    fn ghost_layout() -> AuxLayout {
        AuxLayout::new(vec![
            AuxLayer { name: "band".into(), channels: 1 },
            AuxLayer { name: GHOST_LAYER.into(), channels: 3 },
        ])
    }

    #[test]
    fn concurrent_atomic_adds_lose_nothing() {
        let mut b = AtomicGatherBuffer::default();
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
    fn a_sole_writer_adds_what_compare_and_swap_adds() {
        let (mut cas, mut sole) = (AtomicGatherBuffer::default(), AtomicGatherBuffer::default());
        cas.reset(3, &ghost_layout());
        sole.reset(3, &ghost_layout());
        // The sole writer is another thread than the owner that reads the buffer afterwards.
        std::thread::scope(|s| {
            s.spawn(|| {
                let (mut a, mut b) = (cas.sink(), sole.sole_writer_sink());
                for i in 0..1000u32 {
                    let (pixel, layer, ghost) =
                        (i % 3, if i % 2 == 0 { Layer::Indirect } else { Layer::Caustic }, i % 5 == 0);
                    let value = Rgb::new(i as f32, 0.5, 1.0 / (1 + i) as f32);
                    a.add(pixel, layer, ghost, value);
                    b.add(pixel, layer, ghost, value);
                }
            });
        });
        for p in 0..3 {
            assert_eq!(sole.get(p), cas.get(p));
            for c in 0..4 {
                assert_eq!(sole.get_aux(p, c).to_bits(), cas.get_aux(p, c).to_bits());
            }
        }
        assert_ne!(sole.get(1), [Rgb::ZERO; 2]);
    }

    #[test]
    fn ghost_light_lands_in_its_layer_and_its_usual_layer_but_other_light_only_in_its_usual_layer() {
        let mut atomic = AtomicGatherBuffer::default();
        atomic.reset(3, &ghost_layout());
        let mut plain = GatherBuffer::default();
        plain.reset(3, &ghost_layout());
        let adds = [
            (2, Layer::Indirect, true, Rgb::new(1.0, 2.0, 3.0)),
            (2, Layer::Caustic, false, Rgb::splat(10.0)),
            (1, Layer::Caustic, true, Rgb::splat(0.5)),
        ];
        for (p, l, g, v) in adds {
            atomic.sink().add(p, l, g, v);
            plain.add(p, l, g, v);
        }
        let read_atomic = |p: usize| (atomic.get(p), [0, 1, 2, 3].map(|c| atomic.get_aux(p, c)));
        let read_plain = |p: usize| (plain.get(p), [0, 1, 2, 3].map(|c| plain.get_aux(p, c)));
        assert!((0..3).all(|p| read_atomic(p) == read_plain(p)), "both buffers lay light out alike");
        assert_eq!(read_plain(2), ([Rgb::new(1.0, 2.0, 3.0), Rgb::splat(10.0)], [0.0, 1.0, 2.0, 3.0]));
        assert_eq!(read_plain(1), ([Rgb::ZERO, Rgb::splat(0.5)], [0.0, 0.5, 0.5, 0.5]));
        assert_eq!(read_plain(0), ([Rgb::ZERO; 2], [0.0; 4]));
    }

    #[test]
    fn absorbing_adds_the_atomic_light_and_leaves_it_zero_for_the_next_phase() {
        let mut plain = GatherBuffer::default();
        plain.reset(2, &ghost_layout());
        let mut atomic = AtomicGatherBuffer::default();
        atomic.reset(2, &ghost_layout());
        plain.add(1, Layer::Indirect, true, Rgb::ONE);
        atomic.sink().add(1, Layer::Indirect, true, Rgb::splat(2.0));
        atomic.sink().add(0, Layer::Caustic, false, Rgb::splat(4.0));
        plain.absorb(&mut atomic);
        assert_eq!(plain.get(1)[0], Rgb::splat(3.0));
        assert_eq!(plain.get_aux(1, 1), 3.0);
        assert_eq!(plain.get(0)[1], Rgb::splat(4.0));
        assert_eq!((atomic.get(0), atomic.get(1)), ([Rgb::ZERO; 2], [Rgb::ZERO; 2]));
        // The absorbed buffer counts as clean: the next reset at its size has nothing to zero, and is zero.
        atomic.reset(2, &ghost_layout());
        assert_eq!(atomic.get(0), [Rgb::ZERO; 2]);
    }

    #[test]
    fn a_reset_starts_every_phase_from_zero_whether_or_not_the_last_phase_was_absorbed() {
        // Each sequence adds light at some point and ends with a reset, at 2 pixels without auxiliary layers:
        // adds left over without an absorb, adds absorbed, and adds after an absorb whose reset came.
        let sequences: [&[&str]; 3] =
            [&["reset", "add", "reset"], &["reset", "add", "absorb", "reset"], &["absorb", "reset", "add", "reset"]];
        for steps in sequences {
            let mut b = AtomicGatherBuffer::default();
            b.reset(2, &AuxLayout::default());
            let mut plain = GatherBuffer::default();
            plain.reset(2, &AuxLayout::default());
            for &step in steps {
                match step {
                    "reset" => b.reset(2, &AuxLayout::default()),
                    "absorb" => plain.absorb(&mut b),
                    _ => b.sink().add(1, Layer::Indirect, true, Rgb::ONE),
                }
            }
            assert_eq!(b.get(1), [Rgb::ZERO; 2], "{steps:?}");
        }
        // A new layout after an absorb: sized and zeroed for it.
        let (mut b, mut plain) = (AtomicGatherBuffer::default(), GatherBuffer::default());
        b.reset(2, &AuxLayout::default());
        plain.reset(2, &AuxLayout::default());
        b.sink().add(1, Layer::Indirect, true, Rgb::ONE);
        plain.absorb(&mut b);
        b.reset(3, &ghost_layout());
        assert!(b.capacity_bytes() >= 3 * 10 * 4);
        assert_eq!((b.get(2), [0, 1, 2, 3].map(|c| b.get_aux(2, c))), ([Rgb::ZERO; 2], [0.0; 4]));
    }

    #[test]
    fn absorbing_a_plain_buffer_adds_it_and_leaves_it_zero() {
        let (mut a, mut b) = (GatherBuffer::default(), GatherBuffer::default());
        a.reset(3, &ghost_layout());
        b.reset(3, &ghost_layout());
        a.add(0, Layer::Indirect, false, Rgb::new(1.0, 2.0, 3.0));
        b.add(0, Layer::Indirect, true, Rgb::new(0.5, 0.25, 0.125));
        b.add(2, Layer::Caustic, false, Rgb::ONE);
        a.absorb_plain(&mut b);
        assert_eq!(a.get(0), [Rgb::new(1.5, 2.25, 3.125), Rgb::ZERO]);
        assert_eq!(a.get(2), [Rgb::ZERO, Rgb::ONE]);
        assert_eq!([1, 2, 3].map(|c| a.get_aux(0, c)), [0.5, 0.25, 0.125], "the ghost layer's channels too");
        assert!(b.values.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn a_plain_buffer_resized_to_a_new_layout_starts_at_zero() {
        let mut plain = GatherBuffer::default();
        plain.reset(2, &AuxLayout::default());
        plain.add(1, Layer::Caustic, false, Rgb::ONE);
        plain.reset(3, &ghost_layout());
        assert_eq!(plain.stride(), 13, "6 + the 4 auxiliary channels + the sensor's visible light");
        assert!((0..3).all(|p| plain.get(p) == [Rgb::ZERO; 2]));
    }
}
