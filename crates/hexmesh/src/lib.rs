//! # hexmesh
//!
//! Geometry for the hexahedral mass-spring system: everything between a surface
//! file and the cubic lattice a simulator runs on, and back to skins that users
//! render. No physics lives here.
//!
//! - [`TriMesh`]: an indexed triangle surface (`f64` positions, `u32` indices).
//! - [`Lattice`]: cubic cells of edge `h` on a regular grid, with shared nodes and
//!   cells as `[u32; 8]` in VTK_HEXAHEDRON order. Built by a checked constructor
//!   from a set of grid cells, by the procedural generators [`Lattice::block`] and
//!   [`Lattice::l_shape`], or by voxelizing a surface.
//!
//! ```
//! use hexmesh::Lattice;
//! let lattice = Lattice::block([4, 1, 1], 0.1, [0.0; 3]).unwrap();
//! assert_eq!(lattice.num_cells(), 4);
//! assert_eq!(lattice.num_nodes(), 5 * 2 * 2);
//! ```

pub mod lattice;
pub mod mesh;

pub use lattice::{
    BoundaryFace, CELL_DIAGONALS, CELL_EDGES, CELL_FACES, CORNER_OFFSETS, Lattice, LatticeError,
};
pub use mesh::TriMesh;
