//! Where a phase's parallel stages run: on the calling thread alone, or on the threads of the rayon pool the
//! caller installed (a synchronous group's pinned threads). The stages are written once, as rayon iterators over
//! chunks of pixels; the executor only decides whether rayon may split them.

use rayon::iter::{IndexedParallelIterator, MinLen};

/// Where a phase's parallel stages run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Executor {
    /// Every stage on the calling thread: the single-threaded engine, the reference of every parallel method.
    CallingThread,
    /// The threads of the current rayon pool (`ThreadPool::install`), cooperating on every stage.
    CurrentPool,
}

impl Executor {
    /// Threads the stages use.
    pub fn threads(self) -> usize {
        match self {
            Executor::CallingThread => 1,
            Executor::CurrentPool => rayon::current_num_threads().max(1),
        }
    }

    /// `iter` as this executor runs it. On the calling thread, rayon is told that one task takes every item, so
    /// it never splits the iterator and never hands work to another thread: the items run in order, inline.
    pub fn run<I: IndexedParallelIterator>(self, iter: I) -> MinLen<I> {
        iter.with_min_len(match self {
            Executor::CallingThread => usize::MAX,
            Executor::CurrentPool => 1,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn the_calling_thread_runs_every_item_itself_in_order_even_inside_a_pool() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let seen = std::sync::Mutex::new(Vec::new());
        pool.install(|| {
            let me = std::thread::current().id();
            Executor::CallingThread.run((0..1000).into_par_iter()).for_each(|i| {
                seen.lock().unwrap().push((i, std::thread::current().id() == me));
            })
        });
        let seen = seen.into_inner().unwrap();
        assert!(seen.iter().all(|&(_, here)| here), "an item ran on another thread");
        assert_eq!(seen.iter().map(|&(i, _)| i).collect::<Vec<_>>(), (0..1000).collect::<Vec<_>>());
        assert_eq!(Executor::CallingThread.threads(), 1);
        assert_eq!(pool.install(|| Executor::CurrentPool.threads()), 2);
    }
}
