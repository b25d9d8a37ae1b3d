//! The machine's NUMA nodes and their cores, from hwloc: this machine's, or a synthetic or XML description so
//! that 2-, 4- and 8-node layouts can be run on any machine (their cores are then mapped onto the real cores
//! modulo the real count, and the record says so).

use anyhow::{bail, Context, Result};
use hwlocality::object::types::ObjectType;
use hwlocality::Topology;
use serde::Serialize;
use std::path::Path;

/// One NUMA node: the cores its worker's threads are pinned to.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct NumaNode {
    /// The node's OS index in the topology.
    pub index: u32,
    /// The first processing unit of every core of the node, as the topology numbers them.
    pub topology_cores: Vec<usize>,
    /// The real cores to pin to (equal to `topology_cores` on this machine's own topology).
    pub cores: Vec<usize>,
}

/// The nodes a coordinator starts workers on, and where their description came from.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct NumaNodes {
    pub nodes: Vec<NumaNode>,
    /// "this machine", "synthetic: …" or "xml: …".
    pub source: String,
    /// The nodes are not this machine's: their cores are mapped onto real ones.
    pub synthetic: bool,
}

/// Finds the NUMA nodes of a topology: this machine's, or `spec`, an hwloc synthetic description (e.g.
/// `"pack:1 numa:2 core:1 pu:1"`) or the path of an hwloc XML file.
pub fn detect(spec: Option<&str>, real_cores: &[usize]) -> Result<NumaNodes> {
    if real_cores.is_empty() {
        bail!("no usable core on this machine");
    }
    let (topology, source) = match spec {
        None => (Topology::new().context("hwloc cannot read this machine's topology")?, "this machine".to_string()),
        Some(s) if s.ends_with(".xml") || Path::new(s).is_file() => {
            let t = Topology::builder()
                .from_xml_file(s)
                .with_context(|| format!("cannot load the hwloc XML topology {s}"))?
                .build()
                .with_context(|| format!("hwloc cannot build a topology from {s}"))?;
            (t, format!("xml: {s}"))
        }
        Some(s) => {
            let t = Topology::builder()
                .from_synthetic(s)
                .with_context(|| {
                    format!("'{s}' is not an hwloc synthetic description (e.g. \"pack:1 numa:2 core:1 pu:1\")")
                })?
                .build()
                .with_context(|| format!("hwloc cannot build the synthetic topology '{s}'"))?;
            (t, format!("synthetic: {s}"))
        }
    };
    let synthetic = spec.is_some() && !topology.is_this_system();
    let mut nodes = Vec::new();
    for node in topology.objects_with_type(ObjectType::NUMANode) {
        let Some(cpuset) = node.cpuset() else { continue };
        let topology_cores: Vec<usize> = topology
            .objects_inside_cpuset_with_type(cpuset, ObjectType::Core)
            .filter_map(|core| core.cpuset().and_then(|c| c.first_set()).map(usize::from))
            .collect();
        if topology_cores.is_empty() {
            // A memory-only node (e.g. high-bandwidth memory): no worker runs there.
            continue;
        }
        let cores = if synthetic {
            topology_cores.iter().map(|&c| real_cores[c % real_cores.len()]).collect()
        } else {
            topology_cores.clone()
        };
        nodes.push(NumaNode { index: node.os_index().unwrap_or(nodes.len()) as u32, topology_cores, cores });
    }
    if nodes.is_empty() {
        // Machines without NUMA information: one node with every core.
        nodes.push(NumaNode { index: 0, topology_cores: real_cores.to_vec(), cores: real_cores.to_vec() });
    }
    Ok(NumaNodes { nodes, source, synthetic })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_synthetic_description_gives_its_nodes_mapped_onto_the_real_cores() {
        let t = detect(Some("pack:2 numa:2 core:2 pu:1"), &[0, 1]).unwrap();
        assert!(t.synthetic);
        assert_eq!(t.nodes.len(), 4);
        assert_eq!(t.nodes[1].topology_cores, vec![2, 3]);
        assert_eq!(t.nodes[1].cores, vec![0, 1]);
        assert!(t.nodes.iter().all(|n| n.cores.len() == 2));
    }

    #[test]
    fn a_bad_description_is_a_clear_error() {
        let e = detect(Some("numa:two"), &[0]).unwrap_err();
        assert!(format!("{e:#}").contains("synthetic"), "{e:#}");
    }

    #[test]
    fn this_machine_has_at_least_one_node_with_cores() {
        let t = detect(None, &[0]).unwrap();
        assert!(!t.synthetic && !t.nodes.is_empty() && t.nodes.iter().all(|n| !n.cores.is_empty()));
    }
}
