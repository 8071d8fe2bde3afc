//! `[loads]`: gravity, forces, tractions and drag springs, and their library
//! specs.

use mss_core::constraints::NodeSelector;
use mss_core::loads::{ForceDistribution, LoadSpec};
use serde::Deserialize;

/// `[loads]`: external loads. All default to none.
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct LoadsSection {
    /// Gravity acceleration (m/s^2), e.g. `[0, 0, -9.81]`.
    pub gravity: Option<[f64; 3]>,
    /// `[[loads.forces]]`: forces on node sets.
    #[serde(default)]
    pub forces: Vec<ForceSpec>,
    /// `[[loads.tractions]]`: surface tractions on boundary faces.
    #[serde(default)]
    pub tractions: Vec<TractionSpec>,
    /// `[[loads.drags]]`: springs pulling a node toward a target point.
    #[serde(default)]
    pub drags: Vec<DragSpec>,
}

/// A constant force on a node set.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSpec {
    /// The nodes.
    pub select: NodeSelector,
    /// Force (N): the total, shared equally by the selected nodes, or with
    /// `per_node = true` the force on each node.
    pub force: [f64; 3],
    /// Whether `force` applies to each node rather than to the set (default false).
    #[serde(default)]
    pub per_node: bool,
}

/// A traction (force per area) on the lattice's boundary faces whose centres
/// lie in a box.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TractionSpec {
    /// Box minimum corner (m).
    pub min: [f64; 3],
    /// Box maximum corner (m).
    pub max: [f64; 3],
    /// Traction (Pa).
    pub traction: [f64; 3],
}

/// A drag spring: pulls the centroid of a node set toward a target point
/// (zero-length springs shared by the nodes, so the set is not collapsed).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DragSpec {
    /// The nodes.
    pub select: NodeSelector,
    /// Target of the set's centroid (m).
    pub target: [f64; 3],
    /// Total spring stiffness (N/m), > 0.
    pub stiffness: f64,
}

impl LoadsSection {
    /// The library's load descriptions: gravity, then forces, tractions and
    /// drag springs in the order written.
    pub fn specs(&self) -> Vec<LoadSpec> {
        let mut specs = Vec::new();
        if let Some(g) = self.gravity {
            specs.push(LoadSpec::Gravity { g });
        }
        specs.extend(self.forces.iter().map(LoadSpec::from));
        specs.extend(self.tractions.iter().map(LoadSpec::from));
        specs.extend(self.drags.iter().map(LoadSpec::from));
        specs
    }
}

impl From<&ForceSpec> for LoadSpec {
    fn from(f: &ForceSpec) -> Self {
        LoadSpec::Force {
            select: f.select.clone(),
            force: f.force,
            distribution: if f.per_node {
                ForceDistribution::PerNode
            } else {
                ForceDistribution::Total
            },
        }
    }
}

impl From<&TractionSpec> for LoadSpec {
    fn from(t: &TractionSpec) -> Self {
        LoadSpec::Traction {
            min: t.min,
            max: t.max,
            traction: t.traction,
        }
    }
}

impl From<&DragSpec> for LoadSpec {
    fn from(d: &DragSpec) -> Self {
        LoadSpec::Drag {
            select: d.select.clone(),
            target: d.target,
            stiffness: d.stiffness,
        }
    }
}
