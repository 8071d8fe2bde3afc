//! The boundary skin of a lattice: its boundary cell faces as outward
//! triangles whose vertices are bound to lattice nodes, so the skin follows
//! the nodes as they move.
//!
//! Where cells meet only along an edge or at a corner, the faces around a
//! node (or an edge) do not form a single disc. The skin stays a closed
//! 2-manifold by giving such a node one skin vertex per local fan of faces:
//! at an edge shared by four boundary faces (two cells touching along the
//! edge only) the faces are paired per cell, and the faces around a node are
//! grouped into cycles across paired edges. Every group becomes its own skin
//! vertex, all bound to the same node. Hence every skin edge is used by
//! exactly two triangles, in opposite directions, and the enclosed (signed)
//! volume equals the lattice volume.

use std::collections::HashMap;

use crate::Lattice;

/// A triangle surface bound to lattice nodes.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Skin {
    /// For each skin vertex, the lattice node it follows.
    pub vertex_nodes: Vec<u32>,
    /// Triangles as indices into the skin vertices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl Skin {
    /// Positions of the skin vertices given positions of the lattice nodes.
    pub fn positions(&self, node_positions: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.vertex_nodes
            .iter()
            .map(|&n| node_positions[n as usize])
            .collect()
    }
}

/// A boundary face and one of its 4 edges (corner k to corner k + 1).
type FaceEdge = (u32, u8);

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[x as usize];
        parent[x as usize] = parent[p as usize];
        x = p;
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        // The smaller root wins, so the grouping is deterministic.
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        parent[hi as usize] = lo;
    }
}

/// Every boundary face of `lattice` as two outward triangles (see the module
/// docs for how non-manifold nodes and edges are split).
pub fn boundary_skin(lattice: &Lattice) -> Skin {
    let faces = lattice.boundary_faces();
    // Corner slot (face, corner 0..4) -> id 4 f + k.
    let n = faces.len() * 4;
    let mut parent: Vec<u32> = (0..n as u32).collect();
    // Undirected node edge -> (face, local edge k from corner k to k+1).
    let mut by_edge: HashMap<(u32, u32), Vec<(u32, u8)>> = HashMap::with_capacity(2 * faces.len());
    for (f, face) in faces.iter().enumerate() {
        for k in 0..4 {
            let (a, b) = (face.nodes[k], face.nodes[(k + 1) % 4]);
            by_edge
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push((f as u32, k as u8));
        }
    }
    let mut keys: Vec<(u32, u32)> = by_edge.keys().copied().collect();
    keys.sort_unstable();
    for key in keys {
        let users = &by_edge[&key];
        let pairs: Vec<((u32, u8), (u32, u8))> = match users.len() {
            2 => vec![(users[0], users[1])],
            4 => {
                // Two cells touching along this edge only: pair each cell's own two faces.
                let cell = |u: &(u32, u8)| faces[u.0 as usize].cell;
                let first = cell(&users[0]);
                let (same, other): (Vec<&FaceEdge>, Vec<&FaceEdge>) =
                    users.iter().partition(|u| cell(u) == first);
                if same.len() == 2 && other.len() == 2 {
                    vec![(*same[0], *same[1]), (*other[0], *other[1])]
                } else {
                    vec![(users[0], users[1]), (users[2], users[3])]
                }
            }
            // Cannot happen on a cubic lattice (an edge has 0, 2 or 4 boundary faces).
            _ => Vec::new(),
        };
        for ((f, k), (g, l)) in pairs {
            // Face f goes a -> b along its edge k (corners k, k+1); face g goes b -> a.
            let (fk, fk1) = (4 * f + k as u32, 4 * f + (k as u32 + 1) % 4);
            let (gl, gl1) = (4 * g + l as u32, 4 * g + (l as u32 + 1) % 4);
            // Corner k of f is node a = corner l+1 of g, and the other way round.
            union(&mut parent, fk, gl1);
            union(&mut parent, fk1, gl);
        }
    }
    let mut vertex_of_root: HashMap<u32, u32> = HashMap::new();
    let mut vertex_nodes = Vec::new();
    let mut slot_vertex = vec![0u32; n];
    for (slot, sv) in slot_vertex.iter_mut().enumerate() {
        let root = find(&mut parent, slot as u32);
        *sv = *vertex_of_root.entry(root).or_insert_with(|| {
            vertex_nodes.push(faces[slot / 4].nodes[slot % 4]);
            (vertex_nodes.len() - 1) as u32
        });
    }
    let mut triangles = Vec::with_capacity(2 * faces.len());
    for f in 0..faces.len() {
        let v: [u32; 4] = std::array::from_fn(|k| slot_vertex[4 * f + k]);
        triangles.push([v[0], v[1], v[2]]);
        triangles.push([v[0], v[2], v[3]]);
    }
    Skin {
        vertex_nodes,
        triangles,
    }
}
