//! The rendering methods and how each lays out its processes, groups and threads (docs/parallel-engine.md,
//! "Configurations"; README's methods table). One table,
//! [`Method::layout`], answers every question about a method: the command line, the launcher of worker
//! processes, the engines, the bench and the run record all read it.
//!
//! | method | processes | groups × threads per process | masks | maps shared between groups | image |
//! |---|---|---|---|---|---|
//! | pbpm (single-thread engine) | 1 | 1 × 1 | no | — | one |
//! | path (reference path tracer, single thread) | 1 | 1 × 1 | no | — | one |
//! | sync | 1 | 1 × n | no | — | one |
//! | async | 1 | n × 1 | no (each group renders the whole image) | no | one per thread |
//! | combination | one per NUMA node | 1 × cores of the node | no | — | one per process |
//! | two-level | 1 | n/g × g (g = 1, 2 or 4, see [`Grouping::split`]) | yes | yes | one |
//! | three-level | one per NUMA node | two-level inside each | yes | yes, inside a process | one per process |

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::str::FromStr;

/// A method as the user names it with `--method`, and as run records, checkpoints and the bench's tables
/// name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Method {
    /// Progressive backward photon mapping on one thread: the reference engine of every parallel method.
    Pbpm,
    /// The reference path tracer on one thread, for comparison.
    Path,
    /// One synchronous group of all threads over the whole image.
    Sync,
    /// One single-thread group per thread, each over the whole image with its own map and image.
    Async,
    /// Groups over random tile masks, sharing their photon maps.
    TwoLevel,
    /// One worker process per NUMA node, each one synchronous group of its node's cores.
    Combination,
    /// One worker process per NUMA node, each running two-level on its node's cores.
    ThreeLevel,
}

/// The estimator a run uses: what one phase computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Estimator {
    /// Progressive backward photon mapping.
    Pbpm,
    /// The reference path tracer (one sample per pixel per phase).
    Path,
}

/// The methods a parallel engine runs inside one process: the in-process rows of the table, which worker
/// processes of the distributed methods run too. The protocol's jobs and the engine's configuration carry it;
/// [`Method::from`] gives its row of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ParallelMethod {
    /// One group of n threads over the whole image.
    Sync,
    /// n groups of one thread, each over the whole image with a private map and image.
    Async,
    /// n/g groups of g threads over random tile masks, sharing their maps.
    TwoLevel,
}

/// How many processes render a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Processes {
    /// The coordinator's own process.
    One,
    /// One worker process per NUMA node (and any remote worker).
    PerNumaNode,
}

/// How the threads of one process form groups (the synchronous groups of docs/parallel-engine.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grouping {
    /// One group of one thread: the single-threaded estimators.
    SingleThread,
    /// One group of every thread.
    OneGroup,
    /// One group per thread.
    GroupPerThread,
    /// Equal groups of at most the group size, at least two of them on two threads or more.
    GroupsOfSize,
}

/// Which images a run accumulates before they are merged into the one it writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Images {
    /// Every thread adds into one image.
    One,
    /// Every group keeps its own image, merged at the end of each synchronisation round.
    PerGroup,
    /// Every process keeps its own image; the coordinator merges their snapshots.
    PerProcess,
}

/// A method's row of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub processes: Processes,
    /// How each process's threads form groups.
    pub grouping: Grouping,
    /// Groups render random tile masks (otherwise every group renders the whole image).
    pub masks: bool,
    /// Groups gather into each other's open maps (within a process). False where there is one group.
    pub shared_maps: bool,
    pub images: Images,
    pub estimator: Estimator,
    /// The parallel engine every process runs (for the distributed methods, inside every worker); None for
    /// the single-threaded estimators.
    pub parallel: Option<ParallelMethod>,
}

/// Groups and their threads in one process.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Groups {
    pub groups: usize,
    pub threads_per_group: usize,
}

/// Why a method cannot be laid out on the threads asked for.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LayoutError {
    #[error("at least one thread is needed")]
    NoThreads,
    #[error("a single-threaded estimator runs on one thread, not {0}")]
    SingleThread(usize),
    #[error("the group size must be 1, 2 or 4, got {0}")]
    GroupSize(usize),
}

/// A name that is not a method's.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is not a method (one of pbpm, path, sync, async, two-level, combination, three-level)")]
pub struct UnknownMethod(pub String);

impl Method {
    /// Every method, in the order the command line lists them.
    pub const ALL: [Method; 7] = [
        Method::Pbpm,
        Method::Path,
        Method::Sync,
        Method::Async,
        Method::TwoLevel,
        Method::Combination,
        Method::ThreeLevel,
    ];

    /// The name used on the command line, in records and in the bench's tables.
    pub fn name(self) -> &'static str {
        match self {
            Method::Pbpm => "pbpm",
            Method::Path => "path",
            Method::Sync => "sync",
            Method::Async => "async",
            Method::TwoLevel => "two-level",
            Method::Combination => "combination",
            Method::ThreeLevel => "three-level",
        }
    }

    /// One line on what the method does, for the command line's help.
    pub fn summary(self) -> &'static str {
        match self {
            Method::Pbpm => {
                "Progressive backward photon mapping on one thread: the reference engine of every parallel method"
            }
            Method::Path => "The reference path tracer (one thread), for comparison",
            Method::Sync => "PBPM, one synchronous group of all threads over the whole image",
            Method::Async => {
                "PBPM, one single-thread group per thread, each over the whole image with its own map and image"
            }
            Method::TwoLevel => {
                "PBPM, equal groups of up to the group size (1, 2 or 4 threads) over random tile masks, sharing their photon maps"
            }
            Method::Combination => {
                "PBPM, one worker process per NUMA node (and any remote worker), each one synchronous group of its cores"
            }
            Method::ThreeLevel => {
                "PBPM, one worker process per NUMA node (and any remote worker), each running two-level on its cores"
            }
        }
    }

    /// The method's row of the table.
    pub fn layout(self) -> Layout {
        use Grouping::*;
        let row = |processes, grouping, masks, shared_maps, images, estimator, parallel| Layout {
            processes,
            grouping,
            masks,
            shared_maps,
            images,
            estimator,
            parallel,
        };
        let one = Processes::One;
        let per_node = Processes::PerNumaNode;
        let pbpm = Estimator::Pbpm;
        match self {
            Method::Pbpm => row(one, SingleThread, false, false, Images::One, pbpm, None),
            Method::Path => row(one, SingleThread, false, false, Images::One, Estimator::Path, None),
            Method::Sync => row(one, OneGroup, false, false, Images::One, pbpm, Some(ParallelMethod::Sync)),
            Method::Async => {
                row(one, GroupPerThread, false, false, Images::PerGroup, pbpm, Some(ParallelMethod::Async))
            }
            Method::TwoLevel => row(one, GroupsOfSize, true, true, Images::One, pbpm, Some(ParallelMethod::TwoLevel)),
            Method::Combination => {
                row(per_node, OneGroup, false, false, Images::PerProcess, pbpm, Some(ParallelMethod::Sync))
            }
            Method::ThreeLevel => {
                row(per_node, GroupsOfSize, true, true, Images::PerProcess, pbpm, Some(ParallelMethod::TwoLevel))
            }
        }
    }

    /// What one phase of the method computes.
    pub fn estimator(self) -> Estimator {
        self.layout().estimator
    }

    /// The method runs worker processes (one per NUMA node, and any remote ones).
    pub fn is_distributed(self) -> bool {
        self.layout().processes == Processes::PerNumaNode
    }
}

impl Layout {
    /// Whether the method runs on `threads` threads of one process: the single-threaded estimators on one only.
    pub fn runs_on(&self, threads: usize) -> bool {
        threads >= 1 && (self.grouping != Grouping::SingleThread || threads == 1)
    }
}

impl Grouping {
    /// The groups of `threads` threads of one process. `group_size` (1, 2 or 4) is the most threads per group of
    /// [`Grouping::GroupsOfSize`], which takes the largest of `group_size`, 2 and 1 that divides the threads into
    /// equal groups, at least two of them on two threads or more: so every core is used, and there are always
    /// groups to share their maps (one group of several threads would be `sync` with masks).
    pub fn split(self, threads: usize, group_size: usize) -> Result<Groups, LayoutError> {
        if threads == 0 {
            return Err(LayoutError::NoThreads);
        }
        let (groups, threads_per_group) = match self {
            Grouping::SingleThread if threads != 1 => return Err(LayoutError::SingleThread(threads)),
            Grouping::SingleThread => (1, 1),
            Grouping::OneGroup => (1, threads),
            Grouping::GroupPerThread => (threads, 1),
            Grouping::GroupsOfSize => {
                if ![1, 2, 4].contains(&group_size) {
                    return Err(LayoutError::GroupSize(group_size));
                }
                let g = [group_size, 2, 1]
                    .into_iter()
                    .filter(|&g| g <= group_size && threads.is_multiple_of(g) && (threads == 1 || threads / g >= 2))
                    .max()
                    .unwrap_or(1);
                (threads / g, g)
            }
        };
        Ok(Groups { groups, threads_per_group })
    }
}

impl Estimator {
    /// The name used in records and in the names of reference images.
    pub fn name(self) -> &'static str {
        match self {
            Estimator::Pbpm => "pbpm",
            Estimator::Path => "path",
        }
    }
}

impl ParallelMethod {
    /// The name used on the command line and in records.
    pub fn name(self) -> &'static str {
        Method::from(self).name()
    }
}

impl From<ParallelMethod> for Method {
    fn from(m: ParallelMethod) -> Self {
        match m {
            ParallelMethod::Sync => Method::Sync,
            ParallelMethod::Async => Method::Async,
            ParallelMethod::TwoLevel => Method::TwoLevel,
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = UnknownMethod;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Method::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| UnknownMethod(s.to_string()))
    }
}

// By name in every format, JSON and the checkpoints' bincode alike: a checkpoint then holds the same bytes as
// it would for the name as text, and a renumbering of the variants changes no file.
impl Serialize for Method {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for Method {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (threads of a process, group size) → (groups, threads per group).
    type Split = ((usize, usize), (usize, usize));

    /// One row of the design's table, as the test states it.
    struct Row {
        method: Method,
        processes: Processes,
        groups: &'static [Split],
        masks: bool,
        /// None for "—": a single group has nobody to share with.
        shared_maps: Option<bool>,
        images: Images,
        estimator: Estimator,
    }

    fn design_table() -> Vec<Row> {
        use Estimator::{Path, Pbpm};
        use Processes::{One, PerNumaNode};
        vec![
            Row {
                method: Method::Pbpm,
                processes: One,
                groups: &[((1, 2), (1, 1))],
                masks: false,
                shared_maps: None,
                images: Images::One,
                estimator: Pbpm,
            },
            Row {
                method: Method::Path,
                processes: One,
                groups: &[((1, 2), (1, 1))],
                masks: false,
                shared_maps: None,
                images: Images::One,
                estimator: Path,
            },
            Row {
                method: Method::Sync,
                processes: One,
                groups: &[((1, 2), (1, 1)), ((2, 2), (1, 2)), ((4, 2), (1, 4)), ((8, 4), (1, 8))],
                masks: false,
                shared_maps: None,
                images: Images::One,
                estimator: Pbpm,
            },
            Row {
                method: Method::Async,
                processes: One,
                groups: &[((1, 2), (1, 1)), ((2, 2), (2, 1)), ((4, 2), (4, 1)), ((8, 4), (8, 1))],
                masks: false,
                shared_maps: Some(false),
                images: Images::PerGroup,
                estimator: Pbpm,
            },
            Row {
                method: Method::Combination,
                processes: PerNumaNode,
                // 1 × cores of the node.
                groups: &[((1, 2), (1, 1)), ((2, 2), (1, 2)), ((6, 4), (1, 6))],
                masks: false,
                shared_maps: None,
                images: Images::PerProcess,
                estimator: Pbpm,
            },
            Row {
                method: Method::TwoLevel,
                processes: One,
                // n/g × g: the largest of g, 2, 1 that divides n into at least two groups when n ≥ 2.
                groups: &[
                    ((1, 2), (1, 1)),
                    ((1, 4), (1, 1)),
                    ((2, 2), (2, 1)),
                    ((2, 4), (2, 1)),
                    ((3, 2), (3, 1)),
                    ((3, 4), (3, 1)),
                    ((4, 2), (2, 2)),
                    ((4, 4), (2, 2)),
                    ((6, 2), (3, 2)),
                    ((6, 4), (3, 2)),
                    ((8, 1), (8, 1)),
                    ((8, 2), (4, 2)),
                    ((8, 4), (2, 4)),
                ],
                masks: true,
                shared_maps: Some(true),
                images: Images::One,
                estimator: Pbpm,
            },
            Row {
                method: Method::ThreeLevel,
                processes: PerNumaNode,
                // Two-level inside each process.
                groups: &[((1, 2), (1, 1)), ((2, 2), (2, 1)), ((4, 4), (2, 2)), ((8, 4), (2, 4))],
                masks: true,
                shared_maps: Some(true),
                images: Images::PerProcess,
                estimator: Pbpm,
            },
        ]
    }

    #[test]
    fn every_method_has_the_row_of_the_design_table() {
        let table = design_table();
        assert_eq!(table.len(), Method::ALL.len());
        for row in &table {
            let m = row.method;
            let layout = m.layout();
            assert_eq!(layout.processes, row.processes, "{m}: processes");
            assert_eq!(m.is_distributed(), row.processes == Processes::PerNumaNode, "{m}");
            for &((threads, group_size), (groups, per_group)) in row.groups {
                let got = layout.grouping.split(threads, group_size).unwrap();
                assert_eq!(
                    (got.groups, got.threads_per_group),
                    (groups, per_group),
                    "{m} on {threads} threads, group size {group_size}"
                );
            }
            assert_eq!(layout.masks, row.masks, "{m}: masks");
            assert_eq!(layout.shared_maps, row.shared_maps.unwrap_or(false), "{m}: shared maps");
            assert_eq!(layout.images, row.images, "{m}: images");
            assert_eq!(layout.estimator, row.estimator, "{m}: estimator");
        }
    }

    #[test]
    fn every_process_runs_the_parallel_method_of_its_own_grouping() {
        for m in Method::ALL {
            let layout = m.layout();
            match layout.parallel {
                None => assert_eq!(layout.grouping, Grouping::SingleThread, "{m}"),
                Some(p) => {
                    // A distributed method's workers run the in-process method with its groups, masks and maps.
                    let inner = Method::from(p).layout();
                    assert_eq!(inner.processes, Processes::One, "{m}");
                    assert_eq!(
                        (inner.grouping, inner.masks, inner.shared_maps),
                        (layout.grouping, layout.masks, layout.shared_maps),
                        "{m} runs {p:?}"
                    );
                    if !m.is_distributed() {
                        assert_eq!(Method::from(p), m);
                    }
                }
            }
        }
        assert_eq!(Method::Combination.layout().parallel, Some(ParallelMethod::Sync));
        assert_eq!(Method::ThreeLevel.layout().parallel, Some(ParallelMethod::TwoLevel));
    }

    #[test]
    fn layouts_refuse_what_they_cannot_run() {
        assert_eq!(Grouping::OneGroup.split(0, 2), Err(LayoutError::NoThreads));
        assert_eq!(Grouping::GroupsOfSize.split(4, 3), Err(LayoutError::GroupSize(3)));
        assert_eq!(Grouping::GroupsOfSize.split(1, 8), Err(LayoutError::GroupSize(8)));
        assert_eq!(Grouping::SingleThread.split(2, 2), Err(LayoutError::SingleThread(2)));
        for m in [Method::Pbpm, Method::Path] {
            assert!(m.layout().runs_on(1) && !m.layout().runs_on(2), "{m}");
        }
        assert!(Method::ALL.iter().all(|m| !m.layout().runs_on(0)));
        assert!(Method::TwoLevel.layout().runs_on(3));
    }

    #[test]
    fn methods_are_named_alike_everywhere() {
        let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        assert_eq!(names, ["pbpm", "path", "sync", "async", "two-level", "combination", "three-level"]);
        for m in Method::ALL {
            assert_eq!(m.name().parse::<Method>(), Ok(m));
            assert_eq!(serde_json::to_string(&m).unwrap(), format!("\"{m}\""));
            assert_eq!(serde_json::from_str::<Method>(&format!("\"{m}\"")).unwrap(), m);
            // In bincode too, the name: the same bytes as the name as a string.
            let bytes = bincode::serde::encode_to_vec(m, bincode::config::standard()).unwrap();
            assert_eq!(bytes, bincode::serde::encode_to_vec(m.name(), bincode::config::standard()).unwrap());
        }
        for p in [ParallelMethod::Sync, ParallelMethod::Async, ParallelMethod::TwoLevel] {
            assert_eq!(serde_json::to_string(&p).unwrap(), format!("\"{}\"", p.name()));
        }
        assert_eq!(Method::Pbpm.estimator().name(), "pbpm");
        assert_eq!(Method::Path.estimator().name(), "path");
        assert!("three_level".parse::<Method>().is_err());
    }
}
