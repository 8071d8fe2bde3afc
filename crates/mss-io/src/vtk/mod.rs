//! VTK output of lattice frames: XML `.vtu` ([`write_vtu`]), legacy `.vtk`
//! ([`write_legacy_vtk`]), springs as line cells ([`write_lines_vtu`]), `.pvd`
//! time-series collections ([`PvdWriter`]) and exporter plugins
//! ([`FrameExporter`], registered in [`crate::exporters::Exporters`]).
//!
//! A frame is plain borrowed data ([`LatticeFrame`]): point positions, hexahedra
//! as `[u32; 8]` in VTK_HEXAHEDRON order, and named point and cell fields. Every
//! writer validates the frame (indices in range, field lengths, names) before
//! creating any file, and writes atomically.

#[cfg(feature = "legacy-vtk")]
mod legacy;
mod pvd;
#[cfg(feature = "read")]
pub mod read;
mod series;
mod vtu;

#[cfg(feature = "legacy-vtk")]
pub use legacy::{LegacyFormat, write_legacy_vtk};
pub use pvd::{PvdEntry, PvdWriter, time_decimals};
#[cfg(feature = "legacy-vtk")]
pub use series::LegacyVtkSeries;
pub(crate) use series::check_index;
pub use series::{FrameExporter, SurfaceVtuSeries, VtuSeries};
pub use vtu::{VtuEncoding, write_lines_vtu, write_quads_vtu, write_triangles_vtu, write_vtu};

use crate::IoError;
use std::path::Path;

/// VTK cell type of a two-node line.
pub const VTK_LINE: u8 = 3;
/// VTK cell type of a four-node quadrilateral.
pub const VTK_QUAD: u8 = 9;
/// VTK cell type id of a triangle.
pub const VTK_TRIANGLE: u8 = 5;
/// VTK cell type of an eight-node hexahedron.
pub const VTK_HEXAHEDRON: u8 = 12;

/// Values of a field, one entry per point (point data) or per cell (cell data).
#[derive(Clone, Copy)]
pub enum FieldValues<'a> {
    /// One `f64` per entry (written as `Float64`; legacy: `SCALARS name double`).
    Scalars(&'a [f64]),
    /// One 3-vector per entry (`Float64`, 3 components; legacy: `VECTORS`).
    Vectors(&'a [[f64; 3]]),
    /// One flag per entry, written as `UInt8` 0 or 1 (e.g. fixed nodes).
    Flags(&'a [bool]),
    /// One unsigned integer per entry (`UInt32`; legacy: `unsigned_int`), e.g.
    /// cell or material ids.
    Ids(&'a [u32]),
    /// One signed integer per entry (`Int32`; legacy: `int`), e.g. the
    /// image label of each cell.
    Labels(&'a [i32]),
    /// `Float64` scalars or 3-vectors computed when the writer reaches
    /// them ([`ComputedValues`]).
    Computed(&'a dyn ComputedValues),
}

/// Values that a writer asks for when it writes them, instead of a slice
/// held for the whole frame.
///
/// A frame of a large lattice carries several derived arrays (displacement,
/// forces, strains); held at once they cost more than the simulation's own
/// state. A writer writes one array after the other, so a source that
/// computes each into one buffer it reuses keeps a single array alive.
///
/// Contract: [`ComputedValues::with_values`] passes exactly `len() *
/// num_components()` numbers (entry after entry, the components of an entry
/// together), the same ones on every call for the same frame; writers may
/// call it more than once (once per file written), never from inside
/// another field's call.
pub trait ComputedValues: Sync {
    /// Number of entries (points or cells).
    fn len(&self) -> usize;
    /// True when there are no entries.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Components per entry: 1 (scalars) or 3 (vectors).
    fn num_components(&self) -> usize;
    /// Computes the values and passes them to `write`, returning what it
    /// returns.
    fn with_values(
        &self,
        write: &mut dyn FnMut(&[f64]) -> std::io::Result<()>,
    ) -> std::io::Result<()>;
    /// Puts the values of entries `entries` alone into `out` (replacing its
    /// contents) and returns true, for a source that computes any range of
    /// entries on its own (cell by cell): a writer then asks block by block,
    /// possibly from several threads at once, and never holds the whole
    /// array. The default returns false (the source computes whole arrays,
    /// through [`ComputedValues::with_values`]); a writer may ask with an
    /// empty range to learn which.
    fn values_of(&self, entries: std::ops::Range<usize>, out: &mut Vec<f64>) -> bool {
        let _ = (entries, out);
        false
    }
}

impl std::fmt::Debug for FieldValues<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FieldValues::Scalars(v) => f.debug_tuple("Scalars").field(v).finish(),
            FieldValues::Vectors(v) => f.debug_tuple("Vectors").field(v).finish(),
            FieldValues::Flags(v) => f.debug_tuple("Flags").field(v).finish(),
            FieldValues::Ids(v) => f.debug_tuple("Ids").field(v).finish(),
            FieldValues::Labels(v) => f.debug_tuple("Labels").field(v).finish(),
            FieldValues::Computed(c) => f
                .debug_struct("Computed")
                .field("len", &c.len())
                .field("num_components", &c.num_components())
                .finish(),
        }
    }
}

impl PartialEq for FieldValues<'_> {
    /// Slices compare by value; computed values are equal only to the same
    /// source.
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (FieldValues::Scalars(a), FieldValues::Scalars(b)) => a == b,
            (FieldValues::Vectors(a), FieldValues::Vectors(b)) => a == b,
            (FieldValues::Flags(a), FieldValues::Flags(b)) => a == b,
            (FieldValues::Ids(a), FieldValues::Ids(b)) => a == b,
            (FieldValues::Labels(a), FieldValues::Labels(b)) => a == b,
            (FieldValues::Computed(a), FieldValues::Computed(b)) => std::ptr::addr_eq(*a, *b),
            _ => false,
        }
    }
}

impl FieldValues<'_> {
    /// Number of entries (points or cells), not of components.
    pub fn len(&self) -> usize {
        match self {
            FieldValues::Scalars(v) => v.len(),
            FieldValues::Vectors(v) => v.len(),
            FieldValues::Flags(v) => v.len(),
            FieldValues::Ids(v) => v.len(),
            FieldValues::Labels(v) => v.len(),
            FieldValues::Computed(c) => c.len(),
        }
    }

    /// True when there are no entries.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of components per entry (3 for vectors, else 1).
    pub fn num_components(&self) -> usize {
        match self {
            FieldValues::Vectors(_) => 3,
            FieldValues::Computed(c) => c.num_components(),
            _ => 1,
        }
    }
}

/// A named field of a frame.
///
/// Names must be non-empty and consist of ASCII letters, digits, `_`, `-` and
/// `.` only: legacy VTK separates tokens by whitespace and XML attributes must
/// not contain markup characters, so anything else is refused rather than
/// escaped differently per format.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field<'a> {
    /// Array name shown by ParaView.
    pub name: &'a str,
    /// The values.
    pub values: FieldValues<'a>,
}

impl<'a> Field<'a> {
    /// A scalar field.
    pub fn scalars(name: &'a str, values: &'a [f64]) -> Self {
        Field {
            name,
            values: FieldValues::Scalars(values),
        }
    }

    /// A 3-vector field.
    pub fn vectors(name: &'a str, values: &'a [[f64; 3]]) -> Self {
        Field {
            name,
            values: FieldValues::Vectors(values),
        }
    }

    /// A flag field (written as 0/1 bytes).
    pub fn flags(name: &'a str, values: &'a [bool]) -> Self {
        Field {
            name,
            values: FieldValues::Flags(values),
        }
    }

    /// An unsigned integer field.
    pub fn ids(name: &'a str, values: &'a [u32]) -> Self {
        Field {
            name,
            values: FieldValues::Ids(values),
        }
    }

    /// A signed integer field (labels).
    pub fn labels(name: &'a str, values: &'a [i32]) -> Self {
        Field {
            name,
            values: FieldValues::Labels(values),
        }
    }

    /// A field computed when written (see [`ComputedValues`]).
    pub fn computed(name: &'a str, values: &'a dyn ComputedValues) -> Self {
        Field {
            name,
            values: FieldValues::Computed(values),
        }
    }
}

/// One frame of a hexahedral lattice as plain borrowed data.
///
/// `points` are the positions to draw (usually the current, deformed ones;
/// add the displacement as a point field so ParaView can also warp the rest
/// shape). `cells` index `points` in VTK_HEXAHEDRON order (bottom face
/// counter-clockwise seen from above, then the top face), exactly as
/// `hexmesh::Lattice::cells` stores them. `point_data` fields have one entry
/// per point, `cell_data` fields one per cell.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LatticeFrame<'a> {
    /// Point positions.
    pub points: &'a [[f64; 3]],
    /// Hexahedra as 8 point indices each.
    pub cells: &'a [[u32; 8]],
    /// Per-point fields.
    pub point_data: Vec<Field<'a>>,
    /// Per-cell fields.
    pub cell_data: Vec<Field<'a>>,
}

impl<'a> LatticeFrame<'a> {
    /// A frame without fields.
    pub fn new(points: &'a [[f64; 3]], cells: &'a [[u32; 8]]) -> Self {
        LatticeFrame {
            points,
            cells,
            point_data: Vec::new(),
            cell_data: Vec::new(),
        }
    }

    /// Adds a per-point field (builder style).
    pub fn with_point_field(mut self, field: Field<'a>) -> Self {
        self.point_data.push(field);
        self
    }

    /// Adds a per-cell field (builder style).
    pub fn with_cell_field(mut self, field: Field<'a>) -> Self {
        self.cell_data.push(field);
        self
    }

    /// Checks that the frame can be written to `path` (used in error messages):
    /// at least one point and one cell, every cell index below the number of
    /// points, field lengths matching, names valid and unique.
    pub fn validate(&self, path: &Path) -> Result<(), IoError> {
        validate_grid(
            path,
            self.points,
            self.cells.as_flattened(),
            8,
            &self.point_data,
            &self.cell_data,
        )
    }
}

/// Topology-agnostic view used by the writers: `connectivity` holds
/// `nodes_per_cell` indices per cell.
pub(crate) struct Grid<'a> {
    pub points: &'a [[f64; 3]],
    pub connectivity: &'a [u32],
    pub nodes_per_cell: usize,
    pub cell_type: u8,
    pub point_data: &'a [Field<'a>],
    pub cell_data: &'a [Field<'a>],
}

impl Grid<'_> {
    pub fn num_cells(&self) -> usize {
        self.connectivity.len() / self.nodes_per_cell
    }
}

pub(crate) fn validate_grid(
    path: &Path,
    points: &[[f64; 3]],
    connectivity: &[u32],
    nodes_per_cell: usize,
    point_data: &[Field],
    cell_data: &[Field],
) -> Result<(), IoError> {
    if points.is_empty() {
        return Err(IoError::invalid(path, "the frame has no points"));
    }
    if connectivity.is_empty() {
        return Err(IoError::invalid(path, "the frame has no cells"));
    }
    // VTK stores counts as signed 32/64-bit values in places; u32 indices are
    // the project's convention, so the point count must fit them.
    if u32::try_from(points.len()).is_err() {
        return Err(IoError::invalid(
            path,
            format!("{} points exceed the u32 index range", points.len()),
        ));
    }
    let n = points.len() as u32;
    if let Some(pos) = connectivity.iter().position(|&i| i >= n) {
        return Err(IoError::invalid(
            path,
            format!(
                "cell {} refers to point {} but there are only {} points",
                pos / nodes_per_cell,
                connectivity[pos],
                n
            ),
        ));
    }
    let num_cells = connectivity.len() / nodes_per_cell;
    check_fields(path, "point", point_data, points.len())?;
    check_fields(path, "cell", cell_data, num_cells)?;
    Ok(())
}

fn check_fields(path: &Path, kind: &str, fields: &[Field], expected: usize) -> Result<(), IoError> {
    for (i, f) in fields.iter().enumerate() {
        let valid_name = !f.name.is_empty()
            && f.name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.'));
        if !valid_name {
            return Err(IoError::invalid(
                path,
                format!(
                    "{kind} field name {:?} is not allowed: use ASCII letters, digits, '_', '-' \
                     or '.'",
                    f.name
                ),
            ));
        }
        if fields[..i].iter().any(|g| g.name == f.name) {
            return Err(IoError::invalid(
                path,
                format!("{kind} field name {:?} is used twice", f.name),
            ));
        }
        let components = f.values.num_components();
        if components != 1 && components != 3 {
            return Err(IoError::invalid(
                path,
                format!(
                    "{kind} field {:?} has {components} components per entry; 1 or 3 can be written",
                    f.name
                ),
            ));
        }
        if f.values.len() != expected {
            return Err(IoError::invalid(
                path,
                format!(
                    "{kind} field {:?} has {} entries, expected one per {kind} ({expected})",
                    f.name,
                    f.values.len()
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_problem() {
        let points = [[0.0; 3]; 8];
        let cells = [[0, 1, 2, 3, 4, 5, 6, 8]];
        let p = Path::new("x.vtu");
        let err = LatticeFrame::new(&points, &cells).validate(p).unwrap_err();
        assert!(err.to_string().contains("point 8"), "{err}");

        let cells = [[0, 1, 2, 3, 4, 5, 6, 7]];
        let short = [1.0; 7];
        let err = LatticeFrame::new(&points, &cells)
            .with_point_field(Field::scalars("s", &short))
            .validate(p)
            .unwrap_err();
        assert!(err.to_string().contains("7 entries"), "{err}");

        let ok = [1.0; 8];
        let err = LatticeFrame::new(&points, &cells)
            .with_point_field(Field::scalars("bad name", &ok))
            .validate(p)
            .unwrap_err();
        assert!(err.to_string().contains("bad name"), "{err}");

        let err = LatticeFrame::new(&points, &cells)
            .with_point_field(Field::scalars("a", &ok))
            .with_point_field(Field::scalars("a", &ok))
            .validate(p)
            .unwrap_err();
        assert!(err.to_string().contains("twice"), "{err}");

        assert!(LatticeFrame::new(&[], &[]).validate(p).is_err());
        assert!(
            LatticeFrame::new(&points, &cells)
                .with_cell_field(Field::scalars("a", &[1.0]))
                .validate(p)
                .is_ok()
        );
    }
}
