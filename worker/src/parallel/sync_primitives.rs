//! Atomics and cells that become loom's model-checked versions under `--cfg photonfarm_loom`, so the map-sharing
//! protocol is tested exhaustively with the same code that runs in production. (Not `--cfg loom`: tokio, which
//! the worker links, reconfigures itself under that name and drops its networking.)

#[cfg(photonfarm_loom)]
pub use loom::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
#[cfg(not(photonfarm_loom))]
pub use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

/// An UnsafeCell with loom's closure API in both builds.
#[derive(Debug)]
pub struct Cell<T>(
    #[cfg(photonfarm_loom)] loom::cell::UnsafeCell<T>,
    #[cfg(not(photonfarm_loom))] std::cell::UnsafeCell<T>,
);

impl<T> Cell<T> {
    pub fn new(value: T) -> Self {
        #[cfg(photonfarm_loom)]
        return Cell(loom::cell::UnsafeCell::new(value));
        #[cfg(not(photonfarm_loom))]
        return Cell(std::cell::UnsafeCell::new(value));
    }

    /// Shared access; the caller guarantees no concurrent `with_mut`.
    pub fn with<R>(&self, f: impl FnOnce(*const T) -> R) -> R {
        #[cfg(photonfarm_loom)]
        return self.0.with(f);
        #[cfg(not(photonfarm_loom))]
        return f(self.0.get());
    }

    /// Exclusive access; the caller guarantees no concurrent access at all.
    pub fn with_mut<R>(&self, f: impl FnOnce(*mut T) -> R) -> R {
        #[cfg(photonfarm_loom)]
        return self.0.with_mut(f);
        #[cfg(not(photonfarm_loom))]
        return f(self.0.get());
    }
}

/// Yields inside spin loops: a no-op hint in production, a scheduling point under loom.
pub fn spin_yield() {
    #[cfg(photonfarm_loom)]
    loom::thread::yield_now();
    #[cfg(not(photonfarm_loom))]
    std::hint::spin_loop();
}
