//! # mss-io
//!
//! File formats of the hexahedral MSS: lattice frames as VTK (XML `.vtu`,
//! legacy `.vtk`, `.pvd` time series) and skins as OBJ and binary STL. Every
//! file is written to a temporary name and renamed when complete ([`atomic::write_atomic`]), so an interrupted run never
//! leaves a half-written file.
//!
//! The writers take plain slices (`[f64; 3]` positions, `[u32; 8]` cells in
//! VTK_HEXAHEDRON order, `[u32; 3]` triangles), so they do not depend on how the
//! simulator stores its state.
//!
//! ```
//! use mss_io::vtk::{Field, LatticeFrame, VtuEncoding, write_vtu};
//!
//! // One unit cube cell, nodes in VTK_HEXAHEDRON order.
//! let points = [
//!     [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0],
//!     [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.0], [0.0, 1.0, 1.0],
//! ];
//! let cells = [[0, 1, 2, 3, 4, 5, 6, 7]];
//! let displacement = [[0.0, 0.0, -0.01]; 8];
//! let fixed = [true, true, true, true, false, false, false, false];
//! let strain = [0.01];
//! let frame = LatticeFrame::new(&points, &cells)
//!     .with_point_field(Field::vectors("displacement", &displacement))
//!     .with_point_field(Field::flags("fixed", &fixed))
//!     .with_cell_field(Field::scalars("strain", &strain));
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("cube.vtu");
//! write_vtu(&path, &frame, VtuEncoding::default()).unwrap();
//! let vtk = vtkio::Vtk::import(&path).unwrap();
//! assert_eq!(vtk.version, vtkio::model::Version::new_xml(1, 0));
//! ```

pub mod atomic;
pub mod exporters;
pub mod outline;
pub mod pc2;
pub mod skin;
pub mod vtk;

pub use atomic::IoError;

/// Number formatting shared by the text writers.
pub(crate) mod numfmt {
    use std::io::{self, Write};

    /// Writes `x` with the shortest digits that parse back to exactly `x`
    /// (Rust's float formatting is round-trip exact). Plain notation for
    /// ordinary magnitudes, exponent notation for tiny or huge ones so that
    /// `1e-300` does not become 300 zeros.
    pub(crate) fn write_f64(w: &mut dyn Write, x: f64) -> io::Result<()> {
        let a = x.abs();
        if x == 0.0 || (1e-5..1e16).contains(&a) {
            write!(w, "{x}")
        } else if x.is_nan() {
            w.write_all(b"nan")
        } else {
            write!(w, "{x:e}")
        }
    }
}
