//! Binding a worker's memory to its NUMA node with hwloc, so that the image, the photon maps and the groups'
//! buffers live next to the cores that touch them (paper §5: one process per node is what keeps memory local).

use hwlocality::memory::binding::{MemoryBindingFlags, MemoryBindingPolicy};
use hwlocality::object::types::ObjectType;
use hwlocality::topology::Topology;

/// What a worker obtained for its memory, as the run record reports it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MemoryBinding {
    /// Allocations of `scope` come from this node; `migrated` when the pages it already had were moved too.
    Bound { node: u32, scope: &'static str, migrated: bool },
    /// Not bound; pages land where the pinned threads first touch them. Says why.
    FirstTouch(String),
}

impl std::fmt::Display for MemoryBinding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MemoryBinding::Bound { node, scope, migrated } => {
                write!(f, "memory of the {scope} bound to NUMA node {node}")?;
                if *migrated {
                    write!(f, " (existing pages migrated)")?;
                }
                Ok(())
            }
            MemoryBinding::FirstTouch(why) => write!(f, "memory by first touch ({why})"),
        }
    }
}

/// Binds memory to NUMA node `os_index` of this machine: the whole process's where the OS allows it, otherwise
/// the calling thread's, which the threads it starts afterwards inherit (Linux binds per thread), so call it
/// before starting the engine. Never fails the job: a machine or container that refuses binding leaves memory
/// to first touch, and the returned value says why.
pub fn bind_memory(os_index: u32) -> MemoryBinding {
    let topology = match Topology::new() {
        Ok(t) => t,
        Err(e) => return MemoryBinding::FirstTouch(format!("hwloc cannot read the topology: {e}")),
    };
    let Some(node) = topology.objects_with_type(ObjectType::NUMANode).find(|n| n.os_index() == Some(os_index as usize))
    else {
        return MemoryBinding::FirstTouch(format!("this machine has no NUMA node {os_index}"));
    };
    let Some(nodeset) = node.nodeset() else {
        return MemoryBinding::FirstTouch(format!("NUMA node {os_index} has no node set"));
    };
    // Not STRICT: when the node is full the OS may spill to another node rather than fail an allocation.
    let mut last_error = String::new();
    for (scope, target) in [("process", MemoryBindingFlags::PROCESS), ("engine threads", MemoryBindingFlags::THREAD)] {
        for migrated in [true, false] {
            let flags = if migrated { target | MemoryBindingFlags::MIGRATE } else { target };
            match topology.bind_memory(nodeset, MemoryBindingPolicy::Bind, flags) {
                Ok(()) => return MemoryBinding::Bound { node: os_index, scope, migrated },
                Err(e) => last_error = e.to_string(),
            }
        }
    }
    MemoryBinding::FirstTouch(format!("the OS refused binding: {last_error}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hwlocality::memory::nodeset::NodeSet;

    #[test]
    fn threads_started_after_binding_allocate_from_the_node() {
        let can_bind = Topology::new()
            .ok()
            .and_then(|t| t.feature_support().memory_binding().map(|m| m.set_current_thread()))
            .unwrap_or(false);
        // A fresh thread, so that the binding does not leak into the other tests.
        let (binding, child) = std::thread::spawn(|| {
            let binding = bind_memory(0);
            // The engine's group threads are started like this one, after the binding.
            let child = std::thread::spawn(|| {
                Topology::new().unwrap().memory_binding::<NodeSet>(MemoryBindingFlags::THREAD).ok()
            })
            .join()
            .unwrap();
            (binding, child)
        })
        .join()
        .unwrap();
        if !can_bind {
            assert!(matches!(binding, MemoryBinding::FirstTouch(_)), "{binding}");
            return;
        }
        assert!(matches!(binding, MemoryBinding::Bound { node: 0, .. }), "{binding}");
        let (set, policy) = child.expect("a bound thread can read its binding");
        assert_eq!(policy, Some(MemoryBindingPolicy::Bind));
        assert!(set.is_set(0) && set.weight() == Some(1), "child thread bound to {set}");
    }

    #[test]
    fn a_node_this_machine_lacks_is_left_to_first_touch_with_the_reason() {
        let b = bind_memory(4096);
        assert!(matches!(&b, MemoryBinding::FirstTouch(why) if why.contains("no NUMA node 4096")), "{b}");
    }
}
