//! # hexmesh
//!
//! Geometry for the hexahedral mass-spring system: everything between a surface
//! file and the cubic lattice a simulator runs on, and back to skins that users
//! render. No physics lives here.
//!
//! - [`TriMesh`]: an indexed triangle surface (`f64` positions, `u32` indices).
//! - [`load`]: OBJ and STL (ASCII or binary, detected from the content) into a
//!   cleaned [`TriMesh`] (welded vertices, degenerate triangles dropped), with
//!   typed errors naming the file; more formats plug in through [`MeshLoader`].
//! - [`voxelize`](mod@voxelize): a surface to a [`Lattice`]. Inside means a
//!   generalized winding number of at least 0.5 (exact signed crossings on
//!   closed meshes, a fast hierarchical winding number on open ones, after
//!   repairing orientation; see [`winding`]); cells are kept by an
//!   [`OccupancyRule`] (centre inside, any overlap, or a fraction of samples),
//!   and only the largest face-connected component by default.
//! - [`Lattice`]: cubic cells of edge `h` on a regular grid, with shared nodes and
//!   cells as `[u32; 8]` in VTK_HEXAHEDRON order. Built by a checked constructor
//!   from a set of grid cells, by the procedural generators [`Lattice::block`] and
//!   [`Lattice::l_shape`], or by voxelizing a surface.
//! - [`skin`]: the lattice's boundary faces as a closed, outward, 2-manifold
//!   triangle surface bound to lattice nodes; [`embed`]: the original surface
//!   bound to cells by trilinear coordinates, so both follow the nodes.
//! - [`springs`]: the merged edge and body-diagonal springs of a lattice as
//!   node pairs, for writing them as lines.
//! - [`generate`]: the default "critter" mesh, spheres and boxes.
//!
//! ```
//! use hexmesh::{MeshFormat, Resolution, VoxelizeOptions, boundary_skin, load_mesh_bytes, voxelize};
//!
//! // A surface (here the built-in critter, as OBJ text) ...
//! let obj = hexmesh::generate::critter_obj();
//! let loaded = load_mesh_bytes(obj.as_bytes(), MeshFormat::Obj, "critter.obj").unwrap();
//! assert_eq!(loaded.report.vertices_welded, 0);
//!
//! // ... voxelized with 24 cells along its longest axis ...
//! let opts = VoxelizeOptions {
//!     resolution: Resolution::CellsAlongLongestAxis(24),
//!     ..Default::default()
//! };
//! let vox = voxelize(&loaded.mesh, &opts).unwrap();
//! let lattice = &vox.lattice;
//! assert_eq!(vox.stats.components_found, 1);
//! let rel = (vox.stats.lattice_volume - vox.stats.mesh_volume).abs() / vox.stats.mesh_volume;
//! assert!(rel < 0.05);
//!
//! // ... and its skin, which moves with the nodes and encloses the lattice volume.
//! let skin = boundary_skin(lattice);
//! let surface = hexmesh::TriMesh {
//!     vertices: skin.positions(lattice.nodes()),
//!     triangles: skin.triangles.clone(),
//! };
//! assert!((surface.signed_volume() - lattice.volume()).abs() < 1e-12);
//!
//! // Lattices also come from generators.
//! let block = hexmesh::Lattice::block([4, 1, 1], 0.1, [0.0; 3]).unwrap();
//! assert_eq!(block.num_cells(), 4);
//! assert_eq!(block.num_nodes(), 5 * 2 * 2);
//! ```

#![warn(missing_docs)]

pub mod embed;
pub mod generate;
#[cfg(feature = "image")]
pub mod image;
pub mod lattice;
pub mod load;
pub mod loader;
pub mod mesh;
#[cfg(feature = "svg")]
pub mod outline;
pub mod placement;
pub mod plane;
#[cfg(feature = "ply")]
pub mod ply;
pub mod skin;
pub mod springs;
pub mod voxelize;
#[cfg(feature = "vtk")]
pub mod vtk;
#[cfg(feature = "vtk")]
pub mod vtk_bounds;
pub mod winding;

pub use embed::Embedding;
pub use lattice::{
    BoundaryFace, CELL_DIAGONALS, CELL_EDGES, CELL_FACES, CORNER_OFFSETS, Lattice, LatticeError,
};
pub use load::{
    LoadError, LoadReport, LoadedMesh, MeshFormat, MeshLoader, load_mesh, load_mesh_bytes,
};
pub use mesh::{Aabb, TriMesh};
pub use placement::{Placement, PlacementError, Units, UpAxis};
pub use skin::{Skin, boundary_skin};
pub use springs::SpringTopology;
pub use voxelize::{
    ComponentPolicy, OccupancyRule, ProgressFn, Resolution, VoxelStats, VoxelizeError,
    VoxelizeOptions, Voxelized, voxelize, voxelize_with_progress,
};
pub use winding::InsideTest;
