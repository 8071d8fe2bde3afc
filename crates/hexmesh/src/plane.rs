//! Planar lattices for the paper's 2D element: rectangles `lx x ly` (any
//! aspect ratio) on a regular grid of the plane, with shared nodes, and
//! planar outlines rasterized onto them.
//!
//! - [`RectLattice`]: cells as `[u32; 4]` counter-clockwise from the
//!   lower-left corner (VTK_QUAD order: `(0,0)`, `(1,0)`, `(1,1)`, `(0,1)`),
//!   nodes sorted by grid index (x fastest), built from an occupancy grid
//!   ([`RectLattice::from_occupancy`]) or as a block
//!   ([`RectLattice::block`]).
//! - [`Outline`]: closed polygons (a shape and its holes); a grid cell is
//!   part of the body when its centre is inside by the even-odd rule
//!   ([`rasterize`]).
//!
//! ```
//! use hexmesh::plane::{Outline, RectLattice, rasterize};
//!
//! let beam = RectLattice::block([8, 2], [0.05, 0.025], [0.0, 0.0]).unwrap();
//! assert_eq!(beam.num_cells(), 16);
//! assert_eq!(beam.num_nodes(), 9 * 3);
//! assert!((beam.area() - 0.4 * 0.05).abs() < 1e-15);
//!
//! // A unit square with a square hole, 10 x 10 cells.
//! let shape = Outline::new(vec![
//!     vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
//!     vec![[0.4, 0.4], [0.6, 0.4], [0.6, 0.6], [0.4, 0.6]],
//! ]).unwrap();
//! let lattice = rasterize(&shape, [0.1, 0.1]).unwrap();
//! assert_eq!(lattice.num_cells(), 100 - 4);
//! ```

use thiserror::Error;

/// Why a planar lattice or outline was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PlaneError {
    /// A cell size is not a positive finite number.
    #[error("cell size {0:?} must be two positive finite lengths (m)")]
    BadCellSize([f64; 2]),
    /// The origin or a vertex is not finite.
    #[error("a coordinate is not finite: {0:?}")]
    NonFinite([f64; 2]),
    /// No cell is part of the body.
    #[error("the lattice has no cells: the shape is thinner than a cell, or empty")]
    Empty,
    /// The grid is too large.
    #[error("a grid of {0:?} cells is too large (at most {1} cells)")]
    GridTooLarge([u64; 2], u64),
    /// A polygon has fewer than 3 vertices.
    #[error("polygon {0} has {1} vertices; a closed outline needs at least 3")]
    Degenerate(usize, usize),
    /// The occupancy does not match the grid.
    #[error("the occupancy has {got} entries for a grid of {want} cells")]
    Occupancy {
        /// Entries given.
        got: usize,
        /// Cells of the grid.
        want: usize,
    },
}

/// Rectangular cells `cell[0] x cell[1]` on a grid of the plane.
#[derive(Debug, Clone, PartialEq)]
pub struct RectLattice {
    origin: [f64; 2],
    cell: [f64; 2],
    dims: [u32; 2],
    nodes: Vec<[f64; 2]>,
    node_coords: Vec<[u32; 2]>,
    cells: Vec<[u32; 4]>,
    cell_coords: Vec<[u32; 2]>,
}

/// The corners of a cell, counter-clockwise from the lower left, as grid
/// offsets (VTK_QUAD order).
pub const QUAD_CORNERS: [[u32; 2]; 4] = [[0, 0], [1, 0], [1, 1], [0, 1]];

/// Most cells a planar grid may have.
pub const MAX_GRID_CELLS: u64 = 1 << 31;

impl RectLattice {
    /// The cells of a `dims` grid from `origin` (m) whose `occupied[x +
    /// dims[0] * y]` is true, with their corner nodes.
    pub fn from_occupancy(
        origin: [f64; 2],
        cell: [f64; 2],
        dims: [u32; 2],
        occupied: &[bool],
    ) -> Result<Self, PlaneError> {
        if !cell.iter().all(|c| c.is_finite() && *c > 0.0) {
            return Err(PlaneError::BadCellSize(cell));
        }
        if !origin.iter().all(|c| c.is_finite()) {
            return Err(PlaneError::NonFinite(origin));
        }
        let (nx, ny) = (dims[0] as usize, dims[1] as usize);
        if (nx as u64 + 1) * (ny as u64 + 1) > u32::MAX as u64 {
            return Err(PlaneError::GridTooLarge(
                [nx as u64, ny as u64],
                MAX_GRID_CELLS,
            ));
        }
        if occupied.len() != nx * ny {
            return Err(PlaneError::Occupancy {
                got: occupied.len(),
                want: nx * ny,
            });
        }
        let at = |x: usize, y: usize| x < nx && y < ny && occupied[x + nx * y];
        let mut node_index = vec![u32::MAX; (nx + 1) * (ny + 1)];
        let mut nodes = Vec::new();
        let mut node_coords = Vec::new();
        for y in 0..=ny {
            for x in 0..=nx {
                let used = (x > 0 && y > 0 && at(x - 1, y - 1))
                    || (y > 0 && at(x, y - 1))
                    || (x > 0 && at(x - 1, y))
                    || at(x, y);
                if used {
                    node_index[x + (nx + 1) * y] = nodes.len() as u32;
                    nodes.push([
                        origin[0] + cell[0] * x as f64,
                        origin[1] + cell[1] * y as f64,
                    ]);
                    node_coords.push([x as u32, y as u32]);
                }
            }
        }
        let mut cells = Vec::new();
        let mut cell_coords = Vec::new();
        for y in 0..ny {
            for x in 0..nx {
                if at(x, y) {
                    cells.push(QUAD_CORNERS.map(|[dx, dy]| {
                        node_index[x + dx as usize + (nx + 1) * (y + dy as usize)]
                    }));
                    cell_coords.push([x as u32, y as u32]);
                }
            }
        }
        if cells.is_empty() {
            return Err(PlaneError::Empty);
        }
        Ok(Self {
            origin,
            cell,
            dims,
            nodes,
            node_coords,
            cells,
            cell_coords,
        })
    }

    /// A block of `n[0] x n[1]` cells of `cell` (m) from `origin` (m).
    pub fn block(n: [u32; 2], cell: [f64; 2], origin: [f64; 2]) -> Result<Self, PlaneError> {
        let count = n[0] as usize * n[1] as usize;
        Self::from_occupancy(origin, cell, n, &vec![true; count])
    }

    /// The grid's lower-left corner (m).
    pub fn origin(&self) -> [f64; 2] {
        self.origin
    }
    /// The cell size along x and y (m).
    pub fn cell_size(&self) -> [f64; 2] {
        self.cell
    }
    /// The grid's cells along x and y.
    pub fn dims(&self) -> [u32; 2] {
        self.dims
    }
    /// Node positions (m).
    pub fn nodes(&self) -> &[[f64; 2]] {
        &self.nodes
    }
    /// Grid coordinates of each node.
    pub fn node_coords(&self) -> &[[u32; 2]] {
        &self.node_coords
    }
    /// Cells as 4 nodes, counter-clockwise ([`QUAD_CORNERS`]).
    pub fn cells(&self) -> &[[u32; 4]] {
        &self.cells
    }
    /// Grid coordinates of each cell.
    pub fn cell_coords(&self) -> &[[u32; 2]] {
        &self.cell_coords
    }
    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }
    /// Number of cells.
    pub fn num_cells(&self) -> usize {
        self.cells.len()
    }
    /// Area of the cells (m^2).
    pub fn area(&self) -> f64 {
        self.cells.len() as f64 * self.cell[0] * self.cell[1]
    }

    /// The boundary edges (node pairs), each oriented with the body on its
    /// left (counter-clockwise around the outside, clockwise around holes).
    pub fn boundary_edges(&self) -> Vec<[u32; 2]> {
        boundary_edges_of(&self.cells)
    }
}

/// The boundary edges of quads `cells` (sides of one cell only), each
/// oriented with its cell on its left, in cell order.
pub fn boundary_edges_of(cells: &[[u32; 4]]) -> Vec<[u32; 2]> {
    let mut count = std::collections::HashMap::new();
    for c in cells {
        for e in 0..4 {
            let (a, b) = (c[e], c[(e + 1) % 4]);
            *count.entry((a.min(b), a.max(b))).or_insert(0u32) += 1;
        }
    }
    let mut edges = Vec::new();
    for c in cells {
        for e in 0..4 {
            let (a, b) = (c[e], c[(e + 1) % 4]);
            if count[&(a.min(b), a.max(b))] == 1 {
                edges.push([a, b]);
            }
        }
    }
    edges
}

/// Closed polygons in the plane (m): the even-odd rule tells inside, so a
/// polygon inside another is a hole.
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    polygons: Vec<Vec<[f64; 2]>>,
}

impl Outline {
    /// Checked polygons: at least 3 finite vertices each (the last joins the
    /// first; a repeated closing vertex is dropped).
    pub fn new(mut polygons: Vec<Vec<[f64; 2]>>) -> Result<Self, PlaneError> {
        for (i, p) in polygons.iter_mut().enumerate() {
            if p.len() > 1 && p.first() == p.last() {
                p.pop();
            }
            if p.len() < 3 {
                return Err(PlaneError::Degenerate(i, p.len()));
            }
            if let Some(v) = p.iter().find(|v| !v.iter().all(|c| c.is_finite())) {
                return Err(PlaneError::NonFinite(*v));
            }
        }
        if polygons.is_empty() {
            return Err(PlaneError::Empty);
        }
        Ok(Self { polygons })
    }

    /// The polygons.
    pub fn polygons(&self) -> &[Vec<[f64; 2]>] {
        &self.polygons
    }

    /// The bounding box as (min, max).
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for v in self.polygons.iter().flatten() {
            for k in 0..2 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        (lo, hi)
    }

    /// Whether `p` is inside (even-odd rule over every polygon).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.polygons
            .iter()
            .filter(|poly| point_in_polygon(poly, p))
            .count()
            % 2
            == 1
    }

    /// The enclosed area (m^2; holes subtracted, by the even-odd rule for
    /// polygons that do not cross).
    pub fn area(&self) -> f64 {
        let signed: Vec<f64> = self
            .polygons
            .iter()
            .map(|p| {
                let n = p.len();
                0.5 * (0..n)
                    .map(|i| p[i][0] * p[(i + 1) % n][1] - p[(i + 1) % n][0] * p[i][1])
                    .sum::<f64>()
            })
            .collect();
        // Nesting depth decides the sign: a polygon inside an odd number of
        // others is a hole.
        let mut total = 0.0;
        for (i, p) in self.polygons.iter().enumerate() {
            let depth = self
                .polygons
                .iter()
                .enumerate()
                .filter(|(j, q)| *j != i && point_in_polygon(q, p[0]))
                .count();
            let a = signed[i].abs();
            total += if depth % 2 == 0 { a } else { -a };
        }
        total
    }
}

fn point_in_polygon(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let n = poly.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// The cells of size `cell` (m) whose centres lie inside `outline`, on a
/// grid fitted to its bounding box (one empty cell of margin).
pub fn rasterize(outline: &Outline, cell: [f64; 2]) -> Result<RectLattice, PlaneError> {
    let (origin, [nx, ny]) = fitted_grid(outline, cell)?;
    let (nx, ny) = (nx as usize, ny as usize);
    let mut occupied = vec![false; nx * ny];
    for y in 0..ny {
        for x in 0..nx {
            let p = [
                origin[0] + (x as f64 + 0.5) * cell[0],
                origin[1] + (y as f64 + 0.5) * cell[1],
            ];
            occupied[x + nx * y] = outline.contains(p);
        }
    }
    RectLattice::from_occupancy(origin, cell, [nx as u32, ny as u32], &occupied)
}

/// The grid of cells `cell` (m) that [`rasterize`] lays over `outline`:
/// its bounding box and one empty cell of margin, centred; its origin (m)
/// and cells per axis.
pub fn fitted_grid(outline: &Outline, cell: [f64; 2]) -> Result<([f64; 2], [u32; 2]), PlaneError> {
    if !cell.iter().all(|c| c.is_finite() && *c > 0.0) {
        return Err(PlaneError::BadCellSize(cell));
    }
    let (lo, hi) = outline.bounds();
    let mut dims = [0u64; 2];
    for k in 0..2 {
        let n = ((hi[k] - lo[k]) / cell[k] * (1.0 - 1e-12)).ceil().max(1.0);
        dims[k] = if n < 1e9 { n as u64 + 2 } else { u64::MAX / 4 };
    }
    if dims[0].saturating_mul(dims[1]) > MAX_GRID_CELLS {
        return Err(PlaneError::GridTooLarge(dims, MAX_GRID_CELLS));
    }
    let origin: [f64; 2] =
        std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]) - 0.5 * cell[k] * dims[k] as f64);
    Ok((origin, [dims[0] as u32, dims[1] as u32]))
}
