//! The guard that keeps NaNs and infinities out of the sums: such a phase value is dropped and counted, and the
//! run record flags the count.

use crate::color::Rgb;
use std::sync::atomic::{AtomicU64, Ordering};

/// Phase values this process dropped for not being finite.
static NON_FINITE_DROPPED: AtomicU64 = AtomicU64::new(0);

/// How many phase values with a NaN or an infinity this process has dropped; the run record flags any.
pub fn non_finite_dropped() -> u64 {
    NON_FINITE_DROPPED.load(Ordering::Relaxed)
}

/// No NaN or infinity may ever reach the sums: such a sample is dropped, counted, and flagged in the record (it
/// is a bug to find).
#[inline]
pub(super) fn sanitize(v: Rgb) -> Rgb {
    if v.is_finite() {
        v
    } else {
        NON_FINITE_DROPPED.fetch_add(1, Ordering::Relaxed);
        Rgb::ZERO
    }
}

/// True when every value of a pixel's auxiliary channels is finite; otherwise they are dropped together and
/// counted like a fixed layer's value.
#[inline]
pub(super) fn sanitize_slice(v: &[f32]) -> bool {
    if v.iter().all(|x| x.is_finite()) {
        true
    } else {
        NON_FINITE_DROPPED.fetch_add(1, Ordering::Relaxed);
        false
    }
}
