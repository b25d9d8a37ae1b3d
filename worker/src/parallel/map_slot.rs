//! A group's backward photon map shared with other groups through one atomic counter (paper §4.2, Figs. 8–10;
//! docs/parallel-engine.md, "Shared maps"). 0 means closed. The owner opens it (0 → 1) before its forward pass, traces its light paths,
//! then keeps tracing until a compare-and-swap 1 → 0 succeeds, i.e. until no other group is inside. Another
//! group acquires an open map by a compare-and-swap increment (moving on when it fails), gathers into it, counts
//! its light path in the map's statistics and releases by a decrement. No locks on this path.

use super::sync_primitives::{AtomicBool, AtomicU32, AtomicU64, Cell, Ordering};

/// A shared slot holding one group's map data `T`.
pub struct MapSlot<T> {
    /// 0 = closed; n ≥ 1 = open with n − 1 foreign users inside.
    state: CacheLine<AtomicU32>,
    /// Light paths traced against the map since it was opened (owner's and foreign).
    light_paths: CacheLine<AtomicU64>,
    owner_taken: AtomicBool,
    data: Cell<T>,
}

// SAFETY: `data` is written only through `OwnerToken::data_mut`, which requires the slot to be closed and
// the single owner token; it is read by other threads only through a `Guard`, which exists only while the
// slot is open (state ≥ 2 counts the guard), and the owner cannot close while a guard exists. T: Sync lets
// guards read it concurrently (T's own interior mutability must be atomic).
unsafe impl<T: Send + Sync> Sync for MapSlot<T> {}
unsafe impl<T: Send> Send for MapSlot<T> {}

/// Keeps a hot atomic on a cache line of its own, so that counters of different slots (or of one slot) do not
/// share a line that every core writes.
#[repr(align(64))]
struct CacheLine<T>(T);

impl<T> std::ops::Deref for CacheLine<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.0
    }
}

/// The right to open, close and rebuild one slot; exactly one exists per slot.
pub struct OwnerToken {
    slot_address: usize,
}

/// A foreign group's hold on an open map; dropping it releases the map.
pub struct Guard<'a, T> {
    slot: &'a MapSlot<T>,
}

impl<T> MapSlot<T> {
    /// A closed slot.
    pub fn new(data: T) -> Self {
        MapSlot {
            state: CacheLine(AtomicU32::new(0)),
            light_paths: CacheLine(AtomicU64::new(0)),
            owner_taken: AtomicBool::new(false),
            data: Cell::new(data),
        }
    }

    /// The owner token; panics if it was taken before (a slot has one owner).
    pub fn take_owner(&self) -> OwnerToken {
        assert!(!self.owner_taken.swap(true, Ordering::SeqCst), "a map slot has exactly one owner");
        OwnerToken { slot_address: self as *const _ as usize }
    }

    /// Foreign access: increments a positive counter by compare-and-swap; None when closed or contended.
    pub fn try_acquire(&self) -> Option<Guard<'_, T>> {
        let v = self.state.load(Ordering::Acquire);
        if v == 0 {
            return None;
        }
        self.state.compare_exchange(v, v + 1, Ordering::AcqRel, Ordering::Relaxed).ok().map(|_| Guard { slot: self })
    }

    /// Light paths counted against the map since it was opened.
    pub fn light_paths(&self) -> u64 {
        self.light_paths.load(Ordering::Acquire)
    }

    fn check(&self, token: &OwnerToken) {
        assert_eq!(token.slot_address, self as *const _ as usize, "owner token of another slot");
    }

    /// Owner: exclusive access to the data while the slot is closed (to rebuild the map, reset buffers).
    pub fn data_mut<'a>(&'a self, token: &'a mut OwnerToken) -> &'a mut T {
        self.check(token);
        assert_eq!(self.state.load(Ordering::Acquire), 0, "the owner may change its map only while it is closed");
        // SAFETY: the slot is closed, so no guard exists and none can be created until `open`; the token is
        // unique and borrowed mutably, so this is the only access.
        self.data.with_mut(|p| unsafe { &mut *p })
    }

    /// Owner: opens the map to everyone (0 → 1) and resets its light-path count.
    pub fn open(&self, token: &OwnerToken) {
        self.check(token);
        self.light_paths.store(0, Ordering::Relaxed);
        let opened = self.state.compare_exchange(0, 1, Ordering::AcqRel, Ordering::Relaxed);
        assert!(opened.is_ok(), "opening a map that is already open");
    }

    /// Owner: counts `n` light paths the owning group traced against its open map.
    pub fn count_owner_paths(&self, token: &OwnerToken, n: u64) {
        self.check(token);
        self.light_paths.fetch_add(n, Ordering::AcqRel);
    }

    /// Owner: read access while open (the owner gathers into its own map too).
    pub fn owner_data<'a>(&'a self, token: &'a OwnerToken) -> &'a T {
        self.check(token);
        // SAFETY: mutation needs `data_mut`, which requires `&mut OwnerToken` (not available while this shared
        // borrow lives) and a closed slot.
        self.data.with(|p| unsafe { &*p })
    }

    /// Owner: tries to close (1 → 0); fails while foreign groups are inside. On success every guard has been
    /// dropped, so all their contributions are visible.
    pub fn try_close(&self, token: &OwnerToken) -> bool {
        self.check(token);
        self.state.compare_exchange(1, 0, Ordering::AcqRel, Ordering::Relaxed).is_ok()
    }
}

impl<T> Guard<'_, T> {
    /// The map data, readable while the guard lives.
    pub fn data(&self) -> &T {
        // SAFETY: the guard holds a count, so the owner cannot close the slot and therefore cannot mutate it.
        self.slot.data.with(|p| unsafe { &*p })
    }

    /// Light paths counted against the map since it was opened.
    pub fn light_paths(&self) -> u64 {
        self.slot.light_paths()
    }

    /// Counts the guard's light path in the map's statistics.
    pub fn count_light_path(&self) {
        self.count_light_paths(1);
    }

    /// Counts `n` light paths traced against the map while this guard was held.
    pub fn count_light_paths(&self, n: u64) {
        self.slot.light_paths.fetch_add(n, Ordering::AcqRel);
    }
}

impl<T> Drop for Guard<'_, T> {
    fn drop(&mut self) {
        self.slot.state.fetch_sub(1, Ordering::AcqRel);
    }
}

#[cfg(all(test, not(photonfarm_loom)))]
mod tests {
    use super::*;

    #[test]
    fn closed_maps_refuse_foreign_access_and_open_maps_grant_it() {
        let slot = MapSlot::new(5u32);
        let mut owner = slot.take_owner();
        assert!(slot.try_acquire().is_none());
        *slot.data_mut(&mut owner) = 7;
        slot.open(&owner);
        let g = slot.try_acquire().expect("open map");
        assert_eq!(*g.data(), 7);
        g.count_light_path();
        assert!(!slot.try_close(&owner), "closed while a foreign group was inside");
        drop(g);
        assert_eq!(slot.light_paths(), 1);
        assert!(slot.try_close(&owner));
        assert!(slot.try_acquire().is_none());
    }

    #[test]
    #[should_panic(expected = "exactly one owner")]
    fn a_slot_has_one_owner() {
        let slot = MapSlot::new(());
        let _a = slot.take_owner();
        let _b = slot.take_owner();
    }
}

#[cfg(all(test, photonfarm_loom))]
mod loom_tests {
    use super::*;
    use loom::sync::Arc;

    /// Map data whose contributions are atomic, as in the real gathered buffer.
    struct Data {
        generation: u32,
        contributions: AtomicU32,
    }

    /// One owner phase against two foreign groups that each trace one light path: under every interleaving
    /// (up to three preemptions, loom's recommended bound) the owner never changes its data while a foreign
    /// group reads it (loom's cell checks this), no contribution lands in a closed map, the counts add up,
    /// and nobody deadlocks.
    #[test]
    fn owner_and_foreign_groups_follow_the_counter_protocol() {
        let mut model = loom::model::Builder::new();
        model.preemption_bound = Some(3);
        model.check(|| {
            let slot = Arc::new(MapSlot::new(Data { generation: 0, contributions: AtomicU32::new(0) }));
            let mut owner = slot.take_owner();
            slot.data_mut(&mut owner).generation = 1;
            let foreign: Vec<_> = (0..2)
                .map(|_| {
                    let slot = slot.clone();
                    loom::thread::spawn(move || {
                        if let Some(g) = slot.try_acquire() {
                            assert_eq!(g.data().generation, 1, "read a map that is being rebuilt");
                            g.data().contributions.fetch_add(1, Ordering::Relaxed);
                            g.count_light_path();
                            1u32
                        } else {
                            0
                        }
                    })
                })
                .collect();
            slot.open(&owner);
            slot.count_owner_paths(&owner, 1);
            slot.owner_data(&owner).contributions.fetch_add(1, Ordering::Relaxed);
            while !slot.try_close(&owner) {
                super::super::sync_primitives::spin_yield();
            }
            let counted = slot.light_paths();
            let data = slot.data_mut(&mut owner);
            let contributions = data.contributions.load(Ordering::Relaxed);
            assert_eq!(contributions as u64, counted, "a contribution without its light path (or the reverse)");
            data.generation = 2; // rebuild: must not race with any reader
            let joined: u32 = foreign.into_iter().map(|t| t.join().unwrap()).sum();
            // Foreign paths that acquired were inside before the close; none can add after it.
            assert_eq!(joined + 1, contributions);
        });
    }
}
