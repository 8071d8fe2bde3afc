//! The springs of a hexahedral lattice as line segments between nodes: every
//! distinct cell edge once (an edge shared by several cells is one merged
//! spring) and the 4 body diagonals of every cell.
//!
//! Only topology lives here; stiffnesses belong to the physics crate, which
//! sums the per-cell constants over [`SpringTopology::cell_springs`].

use std::collections::HashMap;

use crate::lattice::{CELL_DIAGONALS, CELL_EDGES};

/// The merged springs of a set of hexahedral cells.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SpringTopology {
    /// End nodes of each spring, the smaller index first. Springs are
    /// numbered in order of first appearance: cell by cell, each cell's new
    /// edges ([`CELL_EDGES`] order), then its 4 diagonals. The order depends
    /// only on the cells, so files written from it are reproducible.
    pub nodes: Vec<[u32; 2]>,
    /// Whether each spring is a body diagonal (rest length sqrt(3) h) rather
    /// than a cell edge (rest length h).
    pub diagonal: Vec<bool>,
    /// For each cell, the spring index of its 12 edges ([`CELL_EDGES`] order)
    /// followed by its 4 diagonals ([`CELL_DIAGONALS`] order).
    pub cell_springs: Vec<[u32; 16]>,
}

impl SpringTopology {
    /// The springs of `cells` (corners in VTK_HEXAHEDRON order).
    pub fn new(cells: &[[u32; 8]]) -> Self {
        // About 3 new edges and 4 diagonals per cell in a solid lattice.
        let mut nodes = Vec::with_capacity(cells.len() * 7);
        let mut diagonal = Vec::with_capacity(cells.len() * 7);
        let mut edge_index: HashMap<(u32, u32), u32> = HashMap::with_capacity(cells.len() * 3);
        let mut cell_springs = Vec::with_capacity(cells.len());
        for c in cells {
            let mut ids = [0u32; 16];
            for (slot, &(a, b, _)) in CELL_EDGES.iter().enumerate() {
                let key = (c[a].min(c[b]), c[a].max(c[b]));
                ids[slot] = *edge_index.entry(key).or_insert_with(|| {
                    nodes.push([key.0, key.1]);
                    diagonal.push(false);
                    (nodes.len() - 1) as u32
                });
            }
            for (slot, &(a, b)) in CELL_DIAGONALS.iter().enumerate() {
                nodes.push([c[a].min(c[b]), c[a].max(c[b])]);
                diagonal.push(true);
                ids[12 + slot] = (nodes.len() - 1) as u32;
            }
            cell_springs.push(ids);
        }
        Self {
            nodes,
            diagonal,
            cell_springs,
        }
    }

    /// Number of springs.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether there are no springs (no cells).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Current length of every spring for node positions `points`, or `None`
    /// if a spring refers to a node `points` does not have.
    pub fn lengths(&self, points: &[[f64; 3]]) -> Option<Vec<f64>> {
        self.nodes
            .iter()
            .map(|&[a, b]| {
                let (p, q) = (points.get(a as usize)?, points.get(b as usize)?);
                Some(((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt())
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Lattice;

    #[test]
    fn block_springs_are_unique_edges_plus_diagonals() {
        let l = Lattice::block([3, 2, 2], 0.5, [1.0, 0.0, -1.0]).unwrap();
        let s = SpringTopology::new(l.cells());
        assert_eq!(s.len(), l.num_unique_edges() + 4 * l.num_cells());
        assert_eq!(s.diagonal.iter().filter(|&&d| d).count(), 4 * l.num_cells());
        // No spring twice, every pair ordered.
        let mut pairs = s.nodes.clone();
        pairs.sort_unstable();
        pairs.dedup();
        assert_eq!(pairs.len(), s.len());
        assert!(s.nodes.iter().all(|&[a, b]| a < b));
        // Rest lengths: h for edges, sqrt(3) h for diagonals.
        let len = s.lengths(l.nodes()).unwrap();
        for (l_i, &d) in len.iter().zip(&s.diagonal) {
            let expect = if d { 0.5 * 3f64.sqrt() } else { 0.5 };
            assert!((l_i - expect).abs() < 1e-12);
        }
        // Each cell's slots point at springs between that cell's corners.
        for (c, ids) in l.cells().iter().zip(&s.cell_springs) {
            for (slot, &(a, b, _)) in CELL_EDGES.iter().enumerate() {
                let [p, q] = s.nodes[ids[slot] as usize];
                assert_eq!((p, q), (c[a].min(c[b]), c[a].max(c[b])));
            }
        }
        assert_eq!(s.lengths(&l.nodes()[..3]), None);
        assert!(SpringTopology::new(&[]).is_empty());
    }
}
