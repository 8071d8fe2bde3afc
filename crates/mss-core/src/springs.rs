//! The merged springs of a [`Model`] with their constants, for output and
//! inspection: stiffness (the per-cell constants summed over the cells that
//! share a spring, as the force kernel effectively does) and rest length.
//!
//! The force kernel works cell by cell and never builds this list; it is
//! built on demand, e.g. to write the springs as lines with their strains.

use hexmesh::SpringTopology;
use thiserror::Error;

use crate::{Model, Vec3};

/// Why spring strains could not be computed.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum SpringError {
    /// The positions do not belong to the model.
    #[error("{given} node positions for a model of {nodes} nodes")]
    NodeCount {
        /// Positions given.
        given: usize,
        /// Nodes of the model.
        nodes: usize,
    },
}

/// Every merged spring of a model: topology, stiffness and rest length.
#[derive(Debug, Clone, PartialEq)]
pub struct SpringSet {
    /// End nodes and kind of each spring.
    pub topology: SpringTopology,
    /// Stiffness of each spring (N/m): the sum of the edge (or diagonal)
    /// constant of every cell the spring belongs to.
    pub stiffness: Vec<f64>,
    /// Rest length of each spring (m).
    pub rest_length: Vec<f64>,
}

impl SpringSet {
    /// The springs of `model`.
    pub fn new(model: &Model) -> Self {
        let topology = SpringTopology::new(model.cells());
        let mut stiffness = vec![0.0; topology.len()];
        for (c, ids) in topology.cell_springs.iter().enumerate() {
            let co = model.cell_coefficients(c);
            for (slot, &s) in ids.iter().enumerate() {
                stiffness[s as usize] += if slot < 12 { co.k_edge } else { co.k_diag };
            }
        }
        let rest = model.rest_positions();
        let rest_length = topology
            .nodes
            .iter()
            .map(|&[a, b]| (rest[b as usize] - rest[a as usize]).norm())
            .collect();
        Self {
            topology,
            stiffness,
            rest_length,
        }
    }

    /// Number of springs.
    pub fn len(&self) -> usize {
        self.topology.len()
    }

    /// Whether there are no springs.
    pub fn is_empty(&self) -> bool {
        self.topology.is_empty()
    }

    /// Engineering strain `(l - L0) / L0` of every spring at node positions `x`.
    pub fn strains(&self, x: &[Vec3]) -> Result<Vec<f64>, SpringError> {
        let nodes = self
            .topology
            .nodes
            .iter()
            .flatten()
            .max()
            .map_or(0, |&m| m as usize + 1);
        if x.len() < nodes {
            return Err(SpringError::NodeCount {
                given: x.len(),
                nodes,
            });
        }
        Ok(self
            .topology
            .nodes
            .iter()
            .zip(&self.rest_length)
            .map(|(&[a, b], &l0)| ((x[b as usize] - x[a as usize]).norm() - l0) / l0)
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Material, PaperModel, Parameterization};
    use hexmesh::Lattice;

    #[test]
    fn stiffness_sums_cells_and_strain_follows_stretch() {
        let lattice = Lattice::block([2, 2, 1], 0.1, [0.0; 3]).unwrap();
        let material = Material {
            young: 1e5,
            poisson: 0.3,
            density: 1000.0,
        };
        let model = Model::new(&lattice, material, &PaperModel).unwrap();
        let set = SpringSet::new(&model);
        assert_eq!(set.len(), model.num_springs());
        let co = PaperModel.coefficients(&material, 0.1);
        // The edge through the centre of a 2 x 2 x 1 block is shared by all 4 cells.
        let centre = lattice.node_at([1, 1, 0]).unwrap();
        let top = lattice.node_at([1, 1, 1]).unwrap();
        let i = set
            .topology
            .nodes
            .iter()
            .position(|&n| n == [centre.min(top), centre.max(top)])
            .unwrap();
        assert!((set.stiffness[i] - 4.0 * co.k_edge).abs() < 1e-9 * co.k_edge);
        for (k, &d) in set.stiffness.iter().zip(&set.topology.diagonal) {
            if d {
                assert_eq!(*k, co.k_diag);
            }
        }
        // Rest state: no strain; stretched by 1 % along x: x-edges 0.01, others 0.
        let rest = model.rest_positions();
        assert!(set.strains(rest).unwrap().iter().all(|&e| e.abs() < 1e-12));
        let x: Vec<Vec3> = rest
            .iter()
            .map(|p| Vec3::new(1.01 * p.x, p.y, p.z))
            .collect();
        let strain = set.strains(&x).unwrap();
        for (&[a, b], e) in set.topology.nodes.iter().zip(&strain) {
            let along_x = rest[a as usize].x != rest[b as usize].x
                && rest[a as usize].y == rest[b as usize].y
                && rest[a as usize].z == rest[b as usize].z;
            if along_x {
                assert!((e - 0.01).abs() < 1e-12, "{e}");
            } else if rest[a as usize].x == rest[b as usize].x {
                assert!(e.abs() < 1e-12, "{e}");
            }
        }
        assert_eq!(
            set.strains(&x[..3]),
            Err(SpringError::NodeCount {
                given: 3,
                nodes: model.num_nodes()
            })
        );
    }
}
