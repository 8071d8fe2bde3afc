//! The boundary skin of a lattice: its boundary cell faces as outward
//! triangles whose vertices are bound to lattice nodes, so the skin follows
//! the nodes as they move.
//!
//! Where cells meet only along an edge or at a corner, the faces around a
//! node (or an edge) do not form a single disc. The skin stays a closed
//! 2-manifold by giving such a node one skin vertex per local fan of faces:
//! at an edge shared by four boundary faces (two cells touching along the
//! edge only) the faces are paired per cell, or, where the two cells are
//! joined through other cells around both ends of the edge (so that their
//! common surface would touch itself along it), around each empty cell; and
//! the faces around a node are grouped into cycles across paired edges. Every group becomes its own skin
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
    /// Appends `other`, the skin of another body whose nodes come
    /// `node_offset` after this one's first node in a shared node array:
    /// one skin of both.
    pub fn append(&mut self, other: &Skin, node_offset: u32) {
        let vertex_offset = self.vertex_nodes.len() as u32;
        self.vertex_nodes
            .extend(other.vertex_nodes.iter().map(|n| n + node_offset));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|v| v + vertex_offset)));
    }

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

/// Grid coordinates of the cell across face `face` (0..6 = -x, +x, -y, +y,
/// -z, +z) of the cell at `c` (wrapping below 0, which no cell has).
fn neighbour(c: [u32; 3], face: u8) -> [u32; 3] {
    let axis = (face / 2) as usize;
    let mut n = c;
    n[axis] = if face.is_multiple_of(2) {
        c[axis].wrapping_sub(1)
    } else {
        c[axis] + 1
    };
    n
}

/// Whether cells `c0` and `c1` (which share an edge ending at `node`) are
/// joined through face-adjacent occupied cells among the 8 around `node`.
fn joined_around(lattice: &Lattice, node: u32, c0: u32, c1: u32) -> bool {
    let p = lattice.node_coord(node as usize);
    // The 2 x 2 x 2 block of cells around the node: bit i of the index is
    // the offset along axis i.
    let at = |i: usize| -> Option<u32> {
        let c: [u32; 3] = std::array::from_fn(|k| {
            if (i >> k) & 1 == 1 {
                p[k]
            } else {
                p[k].wrapping_sub(1)
            }
        });
        if c.contains(&u32::MAX) {
            return None;
        }
        lattice.cell_at(c)
    };
    let block: [Option<u32>; 8] = std::array::from_fn(at);
    let index_of = |cell: u32| block.iter().position(|&b| b == Some(cell));
    let (Some(start), Some(goal)) = (index_of(c0), index_of(c1)) else {
        return false;
    };
    let mut seen = 1u8 << start;
    let mut stack = vec![start];
    while let Some(i) = stack.pop() {
        if i == goal {
            return true;
        }
        for k in 0..3 {
            let j = i ^ (1 << k);
            if block[j].is_some() && seen & (1 << j) == 0 {
                seen |= 1 << j;
                stack.push(j);
            }
        }
    }
    false
}

/// Every boundary face of `lattice` as two outward triangles (see the module
/// docs for how non-manifold nodes and edges are split).
pub fn boundary_skin(lattice: &Lattice) -> Skin {
    let faces = lattice.boundary_faces();
    // Corner slot (face, corner 0..4) -> id 4 f + k.
    let n = faces.len() * 4;
    let mut parent: Vec<u32> = (0..n as u32).collect();
    // (undirected node edge, face, local edge k from corner k to k + 1),
    // sorted: each edge's faces form one run, in face order. (A map of
    // small vectors cost an allocation per edge.)
    let mut by_edge: Vec<((u32, u32), (u32, u8))> = Vec::with_capacity(4 * faces.len());
    for (f, face) in faces.iter().enumerate() {
        for k in 0..4 {
            let (a, b) = (face.nodes[k], face.nodes[(k + 1) % 4]);
            by_edge.push(((a.min(b), a.max(b)), (f as u32, k as u8)));
        }
    }
    by_edge.sort_unstable();
    let mut users: Vec<(u32, u8)> = Vec::with_capacity(4);
    for run in by_edge.chunk_by(|x, y| x.0 == y.0) {
        let key = run[0].0;
        users.clear();
        users.extend(run.iter().map(|e| e.1));
        let users = &users;
        let pairs: Vec<((u32, u8), (u32, u8))> = match users.len() {
            2 => vec![(users[0], users[1])],
            4 => {
                // Two cells touching along this edge only. Pair each cell's
                // own two faces (the cells' surfaces part along the edge),
                // unless the two cells are joined through other cells around
                // both ends of the edge: then that surface would touch
                // itself along the edge, and the faces are paired around
                // each empty cell instead (the voids part).
                let cell = |u: &(u32, u8)| faces[u.0 as usize].cell;
                let void = |u: &(u32, u8)| {
                    let face = &faces[u.0 as usize];
                    neighbour(lattice.cell_coord(face.cell as usize), face.face)
                };
                let (a, b) = key;
                let c0 = cell(&users[0]);
                let c1 = users.iter().map(cell).find(|&c| c != c0).unwrap_or(c0);
                let joined = joined_around(lattice, a, c0, c1) && joined_around(lattice, b, c0, c1);
                let first = users[0];
                let (same, other): (Vec<&FaceEdge>, Vec<&FaceEdge>) = if joined {
                    users.iter().partition(|u| void(u) == void(&first))
                } else {
                    users.iter().partition(|u| cell(u) == cell(&first))
                };
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
