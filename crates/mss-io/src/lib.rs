//! # mss-io
//!
//! File formats of the hexahedral MSS: lattice frames as VTK (XML `.vtu`,
//! legacy `.vtk`, `.pvd` time series), skins as OBJ and binary STL, scene files
//! (TOML), and experiment reports. Every file is written to a temporary name and
//! renamed when complete.

pub mod atomic;
pub mod report;
pub mod scene;
pub mod skin;
pub mod vtk;
