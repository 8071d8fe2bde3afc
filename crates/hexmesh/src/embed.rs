//! The original surface embedded in the lattice: every input vertex is bound
//! to one cell by trilinear coordinates, so the surface deforms with the
//! cell's 8 nodes.
//!
//! A vertex inside a kept cell uses that cell (coordinates in [0, 1]); a
//! vertex outside every kept cell uses the nearest kept cell (by distance to
//! the cell's box), with coordinates outside [0, 1] (trilinear
//! extrapolation). Trilinear maps reproduce affine maps exactly, so a rigid
//! or affine motion of the lattice moves the embedded surface the same way.

use crate::{Lattice, TriMesh};

/// An embedded surface: for each vertex, a cell and trilinear coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Embedding {
    cells: Vec<[u32; 8]>,
    coords: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl Embedding {
    /// Binds every vertex of `mesh` to a cell of `lattice`.
    pub fn new(lattice: &Lattice, mesh: &TriMesh) -> Embedding {
        let h = lattice.h();
        let o = lattice.origin();
        let dims = lattice.dims();
        let mut cells = Vec::with_capacity(mesh.vertices.len());
        let mut coords = Vec::with_capacity(mesh.vertices.len());
        for &p in &mesh.vertices {
            let g: [f64; 3] = std::array::from_fn(|k| (p[k] - o[k]) / h);
            let home: [i64; 3] = std::array::from_fn(|k| g[k].floor() as i64);
            let cell = nearest_cell(lattice, g, home, dims);
            let cc = lattice.cell_coord(cell as usize);
            cells.push(lattice.cells()[cell as usize]);
            coords.push(std::array::from_fn(|k| g[k] - cc[k] as f64));
        }
        Embedding {
            cells,
            coords,
            triangles: mesh.triangles.clone(),
        }
    }

    /// Positions of the embedded vertices for the given node positions.
    pub fn deform(&self, node_positions: &[[f64; 3]]) -> Vec<[f64; 3]> {
        self.cells
            .iter()
            .zip(&self.coords)
            .map(|(cell, &uvw)| {
                let wts = trilinear_weights(uvw);
                let mut p = [0.0; 3];
                for (k, &n) in cell.iter().enumerate() {
                    let q = node_positions[n as usize];
                    for a in 0..3 {
                        p[a] += wts[k] * q[a];
                    }
                }
                p
            })
            .collect()
    }

    /// The surface's triangles (indices into the embedded vertices).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// For each vertex, the 8 nodes of its cell.
    pub fn vertex_cells(&self) -> &[[u32; 8]] {
        &self.cells
    }

    /// Vertex `i`'s 8 nodes and their weights (sum 1; outside `[0, 1]` for a
    /// vertex outside every cell).
    pub fn vertex_weights(&self, i: usize) -> ([u32; 8], [f64; 8]) {
        (self.cells[i], trilinear_weights(self.coords[i]))
    }

    /// For each vertex, its trilinear coordinates in its cell.
    pub fn vertex_coords(&self) -> &[[f64; 3]] {
        &self.coords
    }

    /// Appends `other`, the surface of another body whose nodes come
    /// `node_offset` after this one's first node in a shared node array (as
    /// in a model of several bodies): one embedding of both surfaces.
    pub fn append(&mut self, other: &Embedding, node_offset: u32) {
        let vertex_offset = self.coords.len() as u32;
        self.cells
            .extend(other.cells.iter().map(|c| c.map(|n| n + node_offset)));
        self.coords.extend_from_slice(&other.coords);
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|v| v + vertex_offset)));
    }

    /// The deformed surface as a mesh.
    pub fn deformed_mesh(&self, node_positions: &[[f64; 3]]) -> TriMesh {
        TriMesh {
            vertices: self.deform(node_positions),
            triangles: self.triangles.clone(),
        }
    }
}

/// Trilinear weights of the 8 corners (VTK_HEXAHEDRON order, see
/// [`crate::CORNER_OFFSETS`]) at local coordinates `[u, v, w]`.
fn trilinear_weights([u, v, w]: [f64; 3]) -> [f64; 8] {
    [
        (1.0 - u) * (1.0 - v) * (1.0 - w),
        u * (1.0 - v) * (1.0 - w),
        u * v * (1.0 - w),
        (1.0 - u) * v * (1.0 - w),
        (1.0 - u) * (1.0 - v) * w,
        u * (1.0 - v) * w,
        u * v * w,
        (1.0 - u) * v * w,
    ]
}

/// The kept cell nearest to grid point `g` (in cell units), searching cubic
/// shells of grid cells around `home`.
fn nearest_cell(lattice: &Lattice, g: [f64; 3], home: [i64; 3], dims: [u32; 3]) -> u32 {
    let lookup = |c: [i64; 3]| -> Option<u32> {
        if (0..3).any(|k| c[k] < 0 || c[k] >= dims[k] as i64) {
            return None;
        }
        lattice.cell_at([c[0] as u32, c[1] as u32, c[2] as u32])
    };
    if let Some(c) = lookup(home) {
        return c;
    }
    // Squared distance from g to the box of grid cell c.
    let dist2 = |c: [i64; 3]| -> f64 {
        (0..3)
            .map(|k| {
                let lo = c[k] as f64;
                let d = (lo - g[k]).max(g[k] - (lo + 1.0)).max(0.0);
                d * d
            })
            .sum()
    };
    let max_r = dims.iter().map(|&d| d as i64).max().unwrap_or(1)
        + home.iter().map(|h| h.abs()).max().unwrap_or(0)
        + 1;
    let mut best: Option<(f64, u32)> = None;
    for r in 1..=max_r {
        // Every cell of shell r is at least (r - 1) cells away.
        if let Some((d, _)) = best
            && ((r - 1) as f64).powi(2) > d
        {
            break;
        }
        for dz in -r..=r {
            for dy in -r..=r {
                for dx in -r..=r {
                    if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                        continue;
                    }
                    let c = [home[0] + dx, home[1] + dy, home[2] + dz];
                    if let Some(cell) = lookup(c) {
                        let d = dist2(c);
                        // Ties: the lower cell index, for determinism.
                        if best.is_none_or(|(bd, bc)| d < bd || (d == bd && cell < bc)) {
                            best = Some((d, cell));
                        }
                    }
                }
            }
        }
    }
    best.map_or(0, |(_, c)| c)
}
