//! The cubic lattice: cells of edge `h` on a regular grid with shared nodes.

use std::sync::{Arc, OnceLock};
use thiserror::Error;

/// Offsets of the 8 corners of a cell, in VTK_HEXAHEDRON order: the bottom face
/// (z = 0) counter-clockwise seen from +z, then the top face (z = 1) likewise.
pub const CORNER_OFFSETS: [[u32; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

/// Why a lattice could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LatticeError {
    /// The cell edge is not a positive finite number.
    #[error("cell size h = {0} is not a positive finite number")]
    BadCellSize(f64),
    /// The origin has a NaN or infinite coordinate.
    #[error("lattice origin {0:?} has a non-finite coordinate")]
    BadOrigin([f64; 3]),
    /// No cells were given.
    #[error("the lattice has no cells")]
    Empty,
    /// A cell lies outside the declared grid.
    #[error("cell at grid coordinates {coord:?} lies outside the grid of {dims:?} cells")]
    CellOutsideGrid {
        /// Grid coordinates of the offending cell.
        coord: [u32; 3],
        /// Grid dimensions in cells.
        dims: [u32; 3],
    },
    /// The same grid cell was given twice.
    #[error("cell at grid coordinates {0:?} is given more than once")]
    DuplicateCell([u32; 3]),
    /// The grid has more nodes than `u32` indices can address.
    #[error("grid of {0:?} cells is too large for u32 node indices")]
    GridTooLarge([u32; 3]),
}

/// A set of cubic cells of edge `h` on a regular grid, with shared nodes.
///
/// Invariants (established by [`Lattice::from_cells`], the only constructor):
/// cells are unique and sorted by their grid linear index (x fastest, then y,
/// then z); nodes are exactly the corners of the cells, without duplicates,
/// sorted the same way; `cells[c][k]` is the node at grid coordinates
/// `cell_coords[c] + CORNER_OFFSETS[k]` (VTK_HEXAHEDRON order).
#[derive(Debug, Clone)]
pub struct Lattice {
    origin: [f64; 3],
    h: f64,
    dims: [u32; 3],
    /// Shared with the models built on the lattice (no copy).
    nodes: Arc<[[f64; 3]]>,
    /// Derived from `nodes` when asked for after [`Lattice::release_coordinates`].
    node_coords: OnceLock<Vec<[u32; 3]>>,
    /// Shared with the models built on the lattice (no copy).
    cells: Arc<[[u32; 8]]>,
    /// Derived from the cells' corner 0 when asked for after
    /// [`Lattice::release_coordinates`].
    cell_coords: OnceLock<Vec<[u32; 3]>>,
}

impl PartialEq for Lattice {
    /// The grid, the nodes and the cells: the coordinates follow from them.
    fn eq(&self, other: &Self) -> bool {
        self.origin == other.origin
            && self.h == other.h
            && self.dims == other.dims
            && self.nodes == other.nodes
            && self.cells == other.cells
    }
}

/// Checks what both constructors need: a positive finite `h`, a finite origin,
/// and node indices that fit in `u32`. Returns the number of grid nodes.
fn check_grid(origin: [f64; 3], h: f64, dims: [u32; 3]) -> Result<u64, LatticeError> {
    if !(h.is_finite() && h > 0.0) {
        return Err(LatticeError::BadCellSize(h));
    }
    if origin.iter().any(|v| !v.is_finite()) {
        return Err(LatticeError::BadOrigin(origin));
    }
    let node_count = (dims[0] as u64 + 1) * (dims[1] as u64 + 1) * (dims[2] as u64 + 1);
    if node_count > u32::MAX as u64 {
        return Err(LatticeError::GridTooLarge(dims));
    }
    Ok(node_count)
}

fn node_key(c: [u32; 3], dims: [u32; 3]) -> u64 {
    let nx = dims[0] as u64 + 1;
    let ny = dims[1] as u64 + 1;
    c[0] as u64 + nx * (c[1] as u64 + ny * c[2] as u64)
}

fn cell_key(c: [u32; 3], dims: [u32; 3]) -> u64 {
    let nx = dims[0] as u64;
    let ny = dims[1] as u64;
    c[0] as u64 + nx * (c[1] as u64 + ny * c[2] as u64)
}

impl Lattice {
    /// Builds a lattice from the grid coordinates of its cells.
    ///
    /// `origin` is the position of grid node (0, 0, 0), `h` the cell edge (m),
    /// `dims` the grid size in cells. Cells may come in any order; they are
    /// sorted. Fails on a bad `h` or origin, no cells, a cell outside the grid,
    /// or a duplicated cell.
    pub fn from_cells(
        origin: [f64; 3],
        h: f64,
        dims: [u32; 3],
        cell_coords: impl IntoIterator<Item = [u32; 3]>,
    ) -> Result<Self, LatticeError> {
        check_grid(origin, h, dims)?;
        let mut keyed: Vec<(u64, [u32; 3])> = Vec::new();
        for coord in cell_coords {
            if (0..3).any(|k| coord[k] >= dims[k]) {
                return Err(LatticeError::CellOutsideGrid { coord, dims });
            }
            keyed.push((cell_key(coord, dims), coord));
        }
        if keyed.is_empty() {
            return Err(LatticeError::Empty);
        }
        keyed.sort_unstable_by_key(|&(key, _)| key);
        if let Some(w) = keyed.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(LatticeError::DuplicateCell(w[0].1));
        }
        let cell_coords: Vec<[u32; 3]> = keyed.into_iter().map(|(_, c)| c).collect();

        let corner = |c: [u32; 3], k: usize| {
            let o = CORNER_OFFSETS[k];
            [c[0] + o[0], c[1] + o[1], c[2] + o[2]]
        };
        let mut node_keys: Vec<u64> = cell_coords
            .iter()
            .flat_map(|&c| (0..8).map(move |k| node_key(corner(c, k), dims)))
            .collect();
        node_keys.sort_unstable();
        node_keys.dedup();
        let nx = dims[0] as u64 + 1;
        let ny = dims[1] as u64 + 1;
        let node_coords: Vec<[u32; 3]> = node_keys
            .iter()
            .map(|&key| {
                [
                    (key % nx) as u32,
                    ((key / nx) % ny) as u32,
                    (key / (nx * ny)) as u32,
                ]
            })
            .collect();
        let nodes: Vec<[f64; 3]> = node_coords
            .iter()
            .map(|c| std::array::from_fn(|k| origin[k] + h * c[k] as f64))
            .collect();
        let cells: Vec<[u32; 8]> = cell_coords
            .iter()
            .map(|&c| {
                std::array::from_fn(|k| {
                    let key = node_key(corner(c, k), dims);
                    // Every corner key was inserted above, so the search succeeds.
                    node_keys.binary_search(&key).map_or(u32::MAX, |i| i as u32)
                })
            })
            .collect();
        Ok(Self {
            origin,
            h,
            dims,
            nodes: nodes.into(),
            node_coords: OnceLock::from(node_coords),
            cells: cells.into(),
            cell_coords: OnceLock::from(cell_coords),
        })
    }

    /// A rectangular block of `n[0] x n[1] x n[2]` cells of edge `h` whose
    /// minimum corner is at `origin`.
    pub fn block(n: [u32; 3], h: f64, origin: [f64; 3]) -> Result<Self, LatticeError> {
        let cells = (0..n[2])
            .flat_map(move |z| (0..n[1]).flat_map(move |y| (0..n[0]).map(move |x| [x, y, z])));
        Self::from_cells(origin, h, n, cells)
    }

    /// The L-shaped block of the paper's shearing experiment, made of six unit
    /// cubes of edge `unit` (m), each split into `cells_per_unit`^3 cells.
    ///
    /// In units: a vertical leg `x in [0, 1], z in [0, 2]` and an overhanging arm
    /// `x in [1, 2], z in [1, 2]`, both `y in [0, 2]`. The bounding box is
    /// `2 unit` on every side (the paper: 4 m with 2 m wide arms). The base is the
    /// face z = 0 of the leg; the arm's top faces are at z = 2 unit, x > unit.
    pub fn l_shape(cells_per_unit: u32, unit: f64) -> Result<Self, LatticeError> {
        let n = cells_per_unit;
        let units: [[u32; 3]; 6] = [
            [0, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [0, 1, 1],
            [1, 0, 1],
            [1, 1, 1],
        ];
        let cells = units.into_iter().flat_map(move |u| {
            (0..n).flat_map(move |z| {
                (0..n).flat_map(move |y| {
                    (0..n).map(move |x| [u[0] * n + x, u[1] * n + y, u[2] * n + z])
                })
            })
        });
        if cells_per_unit == 0 {
            return Err(LatticeError::Empty);
        }
        Self::from_cells([0.0; 3], unit / n as f64, [2 * n, 2 * n, 2 * n], cells)
    }

    /// Position of grid node (0, 0, 0) (m).
    pub fn origin(&self) -> [f64; 3] {
        self.origin
    }

    /// Cell edge length (m).
    pub fn h(&self) -> f64 {
        self.h
    }

    /// Grid size in cells.
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// Rest positions of the nodes (m).
    pub fn nodes(&self) -> &[[f64; 3]] {
        &self.nodes
    }

    /// The node positions as a shared handle: a model built on the lattice
    /// keeps this one instead of a copy.
    pub fn shared_nodes(&self) -> Arc<[[f64; 3]]> {
        Arc::clone(&self.nodes)
    }

    /// The cells as a shared handle (see [`Lattice::shared_nodes`]).
    pub fn shared_cells(&self) -> Arc<[[u32; 8]]> {
        Arc::clone(&self.cells)
    }

    /// Grid coordinates of the nodes (derived and kept when first asked
    /// for after [`Lattice::release_coordinates`]; [`Lattice::node_coord`]
    /// derives one without keeping any).
    pub fn node_coords(&self) -> &[[u32; 3]] {
        self.node_coords
            .get_or_init(|| self.nodes.iter().map(|p| self.grid_coords_of(p)).collect())
    }

    /// Grid coordinates of node `i`, from its position.
    pub fn node_coord(&self, i: usize) -> [u32; 3] {
        self.grid_coords_of(&self.nodes[i])
    }

    /// Grid coordinates of cell `c` (of its minimum corner), from the
    /// position of its corner 0.
    pub fn cell_coord(&self, c: usize) -> [u32; 3] {
        self.node_coord(self.cells[c][0] as usize)
    }

    /// The grid coordinates of a node at `p`: nodes are placed at
    /// `origin + h * coords`, so the quotient is within round-off of an
    /// integer (for any origin less than 10^15 cells away).
    fn grid_coords_of(&self, p: &[f64; 3]) -> [u32; 3] {
        std::array::from_fn(|k| ((p[k] - self.origin[k]) / self.h).round() as u32)
    }

    /// Frees the nodes' and cells' grid coordinates (24 bytes per cell),
    /// which are derived again from the positions and cells when next asked
    /// for: for a holder that keeps the lattice through a long run (its
    /// frames share its cells) but no longer looks its cells up by
    /// coordinates.
    pub fn release_coordinates(&mut self) {
        self.node_coords = OnceLock::new();
        self.cell_coords = OnceLock::new();
    }

    /// Cells as 8 node indices in VTK_HEXAHEDRON order.
    pub fn cells(&self) -> &[[u32; 8]] {
        &self.cells
    }

    /// Grid coordinates of the cells (of their minimum corner; kept as
    /// [`Lattice::node_coords`] are, [`Lattice::cell_coord`] for one).
    pub fn cell_coords(&self) -> &[[u32; 3]] {
        self.cell_coords
            .get_or_init(|| (0..self.cells.len()).map(|c| self.cell_coord(c)).collect())
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Number of cells.
    pub fn num_cells(&self) -> usize {
        self.cells.len()
    }

    /// Total volume of the cells (m^3).
    pub fn volume(&self) -> f64 {
        self.cells.len() as f64 * self.h.powi(3)
    }

    /// Index of the cell at grid coordinates `coord`, if it is in the lattice.
    pub fn cell_at(&self, coord: [u32; 3]) -> Option<u32> {
        if (0..3).any(|k| coord[k] >= self.dims[k]) {
            return None;
        }
        let key = cell_key(coord, self.dims);
        // Cells are sorted by their key (no coordinates need be held).
        self.cells
            .binary_search_by_key(&key, |c| {
                cell_key(self.grid_coords_of(&self.nodes[c[0] as usize]), self.dims)
            })
            .ok()
            .map(|i| i as u32)
    }

    /// Index of the node at grid coordinates `coord`, if it is in the lattice.
    pub fn node_at(&self, coord: [u32; 3]) -> Option<u32> {
        if (0..3).any(|k| coord[k] > self.dims[k]) {
            return None;
        }
        let key = node_key(coord, self.dims);
        self.nodes
            .binary_search_by_key(&key, |p| node_key(self.grid_coords_of(p), self.dims))
            .ok()
            .map(|i| i as u32)
    }

    /// Axis-aligned bounding box of the nodes (a lattice has at least one cell).
    pub fn bounding_box(&self) -> crate::Aabb {
        crate::Aabb::of_points(self.nodes.iter().copied()).unwrap_or(crate::Aabb {
            min: self.origin,
            max: self.origin,
        })
    }

    /// Number of distinct cell edges (each shared edge counted once).
    pub fn num_unique_edges(&self) -> usize {
        // An edge is its lower node and its axis: one flag bit per node and
        // axis (a byte per node), not a sorted list of the 12 edges of every
        // cell (96 bytes per cell, and a sort).
        let mut flags = vec![0u8; self.nodes.len()];
        for c in self.cells.iter() {
            for &(a, _, axis) in &CELL_EDGES {
                flags[c[a] as usize] |= 1 << axis;
            }
        }
        flags.iter().map(|f| f.count_ones() as usize).sum()
    }
}

/// The 6 faces of a cell as 4 corners (VTK_HEXAHEDRON order), counter-clockwise
/// seen from outside the cell, in the order -x, +x, -y, +y, -z, +z.
pub const CELL_FACES: [[usize; 4]; 6] = [
    [0, 4, 7, 3],
    [1, 2, 6, 5],
    [0, 1, 5, 4],
    [3, 7, 6, 2],
    [0, 3, 2, 1],
    [4, 5, 6, 7],
];

/// A cell face that no other cell shares: part of the lattice boundary.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoundaryFace {
    /// The cell the face belongs to.
    pub cell: u32,
    /// Which face of the cell: index into [`CELL_FACES`] (0..6 = -x, +x, -y, +y, -z, +z).
    pub face: u8,
    /// The face's 4 nodes, counter-clockwise seen from outside the lattice.
    pub nodes: [u32; 4],
}

impl BoundaryFace {
    /// Outward unit normal of the face at rest: the axis of [`CELL_FACES`] with its sign.
    pub fn rest_normal(&self) -> [f64; 3] {
        let mut n = [0.0; 3];
        n[self.face as usize / 2] = if self.face.is_multiple_of(2) {
            -1.0
        } else {
            1.0
        };
        n
    }
}

impl Lattice {
    /// Every cell face not shared by two cells, in cell order then face order.
    pub fn boundary_faces(&self) -> Vec<BoundaryFace> {
        let dims = self.dims;
        let n = self.cells.len();
        // Keys of cells are unique and ascend with the cells, so the key a
        // neighbour would have (this cell's key minus or plus the axis
        // stride) ascends too: one cursor per direction walks the cells once
        // beside the loop (a merge), instead of a search per face.
        let strides = [1u64, dims[0] as u64, dims[0] as u64 * dims[1] as u64];
        let key_of = |i: usize| cell_key(self.cell_coord(i), dims);
        let mut cursor = [0usize; 6];
        let mut out = Vec::new();
        for (c, &cell) in self.cells.iter().enumerate() {
            let cc = self.cell_coord(c);
            let key = cell_key(cc, dims);
            for (f, corners) in CELL_FACES.iter().enumerate() {
                let axis = f / 2;
                let lower = f % 2 == 0;
                let inside = if lower {
                    cc[axis] > 0
                } else {
                    cc[axis] + 1 < dims[axis]
                };
                let has_neighbour = inside && {
                    let target = if lower {
                        key - strides[axis]
                    } else {
                        key + strides[axis]
                    };
                    let j = &mut cursor[f];
                    while *j < n && key_of(*j) < target {
                        *j += 1;
                    }
                    *j < n && key_of(*j) == target
                };
                if !has_neighbour {
                    out.push(BoundaryFace {
                        cell: c as u32,
                        face: f as u8,
                        nodes: corners.map(|k| cell[k]),
                    });
                }
            }
        }
        out
    }
}

/// The 12 edges of a cell as `(corner, corner, axis)`, corners in
/// VTK_HEXAHEDRON order, the first corner at the lower coordinate along `axis`.
pub const CELL_EDGES: [(usize, usize, usize); 12] = [
    (0, 1, 0),
    (3, 2, 0),
    (4, 5, 0),
    (7, 6, 0),
    (0, 3, 1),
    (1, 2, 1),
    (4, 7, 1),
    (5, 6, 1),
    (0, 4, 2),
    (1, 5, 2),
    (2, 6, 2),
    (3, 7, 2),
];

/// The 4 body diagonals of a cell as corner pairs (VTK_HEXAHEDRON order).
pub const CELL_DIAGONALS: [(usize, usize); 4] = [(0, 6), (1, 7), (2, 4), (3, 5)];

impl Lattice {
    /// Builds a lattice from a dense occupancy grid: `occupied[x + dims[0] *
    /// (y + dims[1] * z)]` says whether that grid cell is a cell. Same result
    /// and invariants as [`Lattice::from_cells`] with the occupied cells, in
    /// linear time (no sorting), for large voxelizations.
    pub fn from_occupancy(
        origin: [f64; 3],
        h: f64,
        dims: [u32; 3],
        occupied: &[bool],
    ) -> Result<Self, LatticeError> {
        let node_count = check_grid(origin, h, dims)?;
        let [dx, dy, dz] = dims.map(|d| d as usize);
        if occupied.len() != dx * dy * dz {
            // A grid of the wrong size cannot be interpreted: no valid cells.
            return Err(LatticeError::Empty);
        }
        use rayon::prelude::*;
        let (nx, ny, nz) = (dx + 1, dy + 1, dz + 1);
        let cell_row = |y: usize, z: usize| &occupied[dx * (y + dy * z)..dx * (y + dy * z + 1)];
        // A node is used if any of the (up to) 8 cells around it is occupied;
        // done per node row, streaming through the neighbouring cell rows.
        let mut node_index = vec![u32::MAX; node_count as usize];
        let row_counts: Vec<u32> = node_index
            .par_chunks_mut(nx)
            .enumerate()
            .map(|(r, out)| {
                let (y, z) = (r % ny, r / ny);
                let mut used = vec![false; dx];
                for cz in z.saturating_sub(1)..(z + 1).min(dz) {
                    for cy in y.saturating_sub(1)..(y + 1).min(dy) {
                        for (u, &o) in used.iter_mut().zip(cell_row(cy, cz)) {
                            *u |= o;
                        }
                    }
                }
                let mut n = 0u32;
                for (x, slot) in out.iter_mut().enumerate() {
                    let left = x > 0 && used[x - 1];
                    let right = x < dx && used[x];
                    if left || right {
                        *slot = n;
                        n += 1;
                    }
                }
                n
            })
            .collect();
        // Row-local numbers to global ones (node order = grid linear order).
        let mut offsets = Vec::with_capacity(row_counts.len());
        let mut total = 0u32;
        for &c in &row_counts {
            offsets.push(total);
            total += c;
        }
        node_index
            .par_chunks_mut(nx)
            .zip(&offsets)
            .for_each(|(row, &off)| {
                for v in row.iter_mut().filter(|v| **v != u32::MAX) {
                    *v += off;
                }
            });
        if total == 0 {
            return Err(LatticeError::Empty);
        }
        // Outputs are allocated zeroed at their exact sizes and filled per
        // z-layer in parallel (disjoint slices, so the result is the same for
        // any number of threads).
        let mut node_coords = vec![[0u32; 3]; total as usize];
        let mut nodes = vec![[0.0f64; 3]; total as usize];
        {
            let mut coord_rest = node_coords.as_mut_slice();
            let mut node_rest = nodes.as_mut_slice();
            let mut jobs = Vec::with_capacity(nz);
            for z in 0..nz {
                let n: usize = row_counts[z * ny..(z + 1) * ny]
                    .iter()
                    .map(|&c| c as usize)
                    .sum();
                let (c, cr) = coord_rest.split_at_mut(n);
                let (p, pr) = node_rest.split_at_mut(n);
                coord_rest = cr;
                node_rest = pr;
                jobs.push((z, c, p));
            }
            jobs.into_par_iter().for_each(|(z, coords, points)| {
                let mut i = 0;
                for y in 0..ny {
                    let row = &node_index[nx * (y + ny * z)..nx * (y + ny * z + 1)];
                    for (x, &v) in row.iter().enumerate() {
                        if v != u32::MAX {
                            let c = [x as u32, y as u32, z as u32];
                            coords[i] = c;
                            points[i] = std::array::from_fn(|k| origin[k] + h * c[k] as f64);
                            i += 1;
                        }
                    }
                }
            });
        }
        let layer_cells: Vec<usize> = (0..dz)
            .into_par_iter()
            .map(|z| {
                occupied[dx * dy * z..dx * dy * (z + 1)]
                    .iter()
                    .filter(|&&o| o)
                    .count()
            })
            .collect();
        let n_cells: usize = layer_cells.iter().sum();
        let mut cell_coords = vec![[0u32; 3]; n_cells];
        let mut cells = vec![[0u32; 8]; n_cells];
        {
            let mut coord_rest = cell_coords.as_mut_slice();
            let mut cell_rest = cells.as_mut_slice();
            let mut jobs = Vec::with_capacity(dz);
            for (z, &n) in layer_cells.iter().enumerate() {
                let (c, cr) = coord_rest.split_at_mut(n);
                let (p, pr) = cell_rest.split_at_mut(n);
                coord_rest = cr;
                cell_rest = pr;
                jobs.push((z, c, p));
            }
            jobs.into_par_iter().for_each(|(z, coords, out)| {
                let mut i = 0;
                for y in 0..dy {
                    let base = nx * (y + ny * z);
                    for (x, _) in cell_row(y, z).iter().enumerate().filter(|(_, o)| **o) {
                        coords[i] = [x as u32, y as u32, z as u32];
                        let b = base + x;
                        out[i] = [
                            node_index[b],
                            node_index[b + 1],
                            node_index[b + 1 + nx],
                            node_index[b + nx],
                            node_index[b + nx * ny],
                            node_index[b + 1 + nx * ny],
                            node_index[b + 1 + nx + nx * ny],
                            node_index[b + nx + nx * ny],
                        ];
                        i += 1;
                    }
                }
            });
        }
        Ok(Self {
            origin,
            h,
            dims,
            nodes: nodes.into(),
            node_coords: OnceLock::from(node_coords),
            cells: cells.into(),
            cell_coords: OnceLock::from(cell_coords),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_shares_nodes() {
        let l = Lattice::block([3, 2, 2], 0.5, [1.0, 2.0, 3.0]).unwrap();
        assert_eq!(l.num_cells(), 12);
        assert_eq!(l.num_nodes(), 4 * 3 * 3);
        // 3x2x2 block: x-edges 3*3*3, y-edges 4*2*3, z-edges 4*3*2.
        assert_eq!(l.num_unique_edges(), 27 + 24 + 24);
        for (c, cell) in l.cells().iter().enumerate() {
            let cc = l.cell_coords()[c];
            for (k, &n) in cell.iter().enumerate() {
                let o = CORNER_OFFSETS[k];
                assert_eq!(
                    l.node_coords()[n as usize],
                    [cc[0] + o[0], cc[1] + o[1], cc[2] + o[2]]
                );
                let p = l.nodes()[n as usize];
                for a in 0..3 {
                    let expect = l.origin()[a] + 0.5 * (cc[a] + o[a]) as f64;
                    assert_eq!(p[a], expect);
                }
            }
        }
        assert!((l.volume() - 12.0 * 0.125).abs() < 1e-15);
    }

    #[test]
    fn constructor_rejects_bad_input() {
        assert_eq!(
            Lattice::block([1, 1, 1], 0.0, [0.0; 3]),
            Err(LatticeError::BadCellSize(0.0))
        );
        assert!(matches!(
            Lattice::block([1, 1, 1], 1.0, [f64::NAN, 0.0, 0.0]),
            Err(LatticeError::BadOrigin(_))
        ));
        assert_eq!(
            Lattice::block([0, 1, 1], 1.0, [0.0; 3]),
            Err(LatticeError::Empty)
        );
        assert_eq!(
            Lattice::from_cells([0.0; 3], 1.0, [2, 2, 2], [[0, 0, 0], [0, 0, 0]]),
            Err(LatticeError::DuplicateCell([0, 0, 0]))
        );
        assert_eq!(
            Lattice::from_cells([0.0; 3], 1.0, [2, 2, 2], [[0, 2, 0]]),
            Err(LatticeError::CellOutsideGrid {
                coord: [0, 2, 0],
                dims: [2, 2, 2]
            })
        );
    }

    #[test]
    fn l_shape_has_six_unit_cubes() {
        let l = Lattice::l_shape(2, 2.0).unwrap();
        assert_eq!(l.num_cells(), 6 * 8);
        assert_eq!(l.h(), 1.0);
        assert_eq!(
            (l.bounding_box().min, l.bounding_box().max),
            ([0.0; 3], [4.0; 3])
        );
        assert!(l.cell_at([3, 0, 0]).is_none());
        assert!(l.cell_at([3, 0, 3]).is_some());
    }

    #[test]
    fn boundary_faces_of_block_are_outward() {
        let l = Lattice::block([2, 3, 1], 1.0, [0.0; 3]).unwrap();
        let faces = l.boundary_faces();
        assert_eq!(faces.len(), 2 * (2 * 3 + 2 + 3));
        let centre = [1.0, 1.5, 0.5];
        for f in &faces {
            let p = f.nodes.map(|n| l.nodes()[n as usize]);
            // Newell normal of the quad must agree with the rest normal and point away from the centre.
            let mut nrm = [0.0; 3];
            for i in 0..4 {
                let (a, b) = (p[i], p[(i + 1) % 4]);
                nrm[0] += (a[1] - b[1]) * (a[2] + b[2]);
                nrm[1] += (a[2] - b[2]) * (a[0] + b[0]);
                nrm[2] += (a[0] - b[0]) * (a[1] + b[1]);
            }
            let rn = f.rest_normal();
            let dot: f64 = (0..3).map(|k| nrm[k] * rn[k]).sum();
            assert!(
                dot > 0.0,
                "face {f:?} is not counter-clockwise from outside"
            );
            let mid: Vec<f64> = (0..3)
                .map(|k| p.iter().map(|q| q[k]).sum::<f64>() / 4.0)
                .collect();
            let out: f64 = (0..3).map(|k| (mid[k] - centre[k]) * rn[k]).sum();
            assert!(out > 0.0);
        }
    }

    #[test]
    fn from_occupancy_matches_from_cells() {
        let dims = [3, 2, 2];
        let occ = [
            true, false, true, false, true, true, true, false, false, false, true, true,
        ];
        let cells: Vec<[u32; 3]> = (0..12)
            .filter(|&i| occ[i])
            .map(|i| [(i % 3) as u32, ((i / 3) % 2) as u32, (i / 6) as u32])
            .collect();
        let a = Lattice::from_occupancy([0.5, 0.0, -1.0], 0.25, dims, &occ).unwrap();
        let b = Lattice::from_cells([0.5, 0.0, -1.0], 0.25, dims, cells).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.node_coords(), b.node_coords());
        assert_eq!(a.cell_coords(), b.cell_coords());
        assert_eq!(
            Lattice::from_occupancy([0.0; 3], 1.0, dims, &[false; 12]),
            Err(LatticeError::Empty)
        );
    }

    #[test]
    fn lookups_find_cells_and_nodes() {
        let l = Lattice::from_cells([0.0; 3], 1.0, [4, 4, 4], [[3, 3, 3], [0, 1, 2]]).unwrap();
        assert_eq!(l.cell_coords(), &[[0, 1, 2], [3, 3, 3]]);
        assert_eq!(l.cell_at([3, 3, 3]), Some(1));
        assert_eq!(l.cell_at([1, 1, 1]), None);
        let n = l.node_at([4, 4, 4]).unwrap();
        assert_eq!(l.nodes()[n as usize], [4.0, 4.0, 4.0]);
        assert_eq!(l.node_at([2, 2, 2]), None);
    }

    /// Coordinates freed and derived again from the positions are those the
    /// constructor made, far from the origin and with an awkward cell size,
    /// and the lookups and faces that use them do not change.
    #[test]
    fn released_coordinates_are_derived_again_exactly() {
        let dims = [7, 5, 6];
        let occ: Vec<bool> = (0..7 * 5 * 6).map(|i| (i * 7919) % 5 != 0).collect();
        for (origin, h) in [
            ([0.0; 3], 1.0),
            ([1234.567, -0.001, 1e3], 0.0137),
            ([-4.2e5, 3.3e5, 7.0], 1e-3),
        ] {
            let kept = Lattice::from_occupancy(origin, h, dims, &occ).unwrap();
            let mut released = kept.clone();
            released.release_coordinates();
            for i in 0..kept.num_nodes() {
                assert_eq!(released.node_coord(i), kept.node_coords()[i]);
            }
            for c in 0..kept.num_cells() {
                assert_eq!(released.cell_coord(c), kept.cell_coords()[c]);
            }
            assert_eq!(released.boundary_faces(), kept.boundary_faces());
            for (c, &cc) in kept.cell_coords().iter().enumerate() {
                assert_eq!(released.cell_at(cc), Some(c as u32));
            }
            for (n, &nc) in kept.node_coords().iter().enumerate() {
                assert_eq!(released.node_at(nc), Some(n as u32));
            }
            // Nothing above needed them held.
            assert!(released.node_coords.get().is_none() && released.cell_coords.get().is_none());
            assert_eq!(released.node_coords(), kept.node_coords());
            assert_eq!(released.cell_coords(), kept.cell_coords());
        }
    }
}
