//! Legacy `.vtk` writer (through vtkio's legacy writer).
//!
//! Always file version 4.2: vtkio writes 5.x cells as OFFSETS/CONNECTIVITY but
//! drops the leading 0 of OFFSETS, which VTK then misreads; 4.2 uses the classic
//! `CELLS n size` list that every reader understands. Binary files are
//! big-endian, as the legacy format requires (VTK crashes on little-endian
//! legacy binary).

use super::{FieldValues, LatticeFrame};
use crate::IoError;
use crate::atomic::write_atomic;
use std::io;
use std::path::Path;
use vtkio::model::{
    Attribute, Attributes, ByteOrder, CellType, Cells, DataSet, IOBuffer, UnstructuredGridPiece,
    Version, VertexNumbers, Vtk,
};

/// Encoding of a legacy `.vtk` file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LegacyFormat {
    /// Text; numbers printed with the shortest digits that parse back exactly.
    Ascii,
    /// Big-endian binary (the default).
    #[default]
    Binary,
}

/// Writes one lattice frame as a legacy VTK 4.2 UNSTRUCTURED_GRID of
/// hexahedra, atomically. Scalars and vectors are `double`, flags
/// `unsigned_char`, ids `unsigned_int`; `title` goes on the header line
/// (line breaks are replaced by spaces, and it is cut to the 255 characters
/// the format allows).
pub fn write_legacy_vtk(
    path: &Path,
    frame: &LatticeFrame,
    format: LegacyFormat,
    title: &str,
) -> Result<(), IoError> {
    frame.validate(path)?;
    let title: String = title
        .chars()
        .map(|c| if c == '\n' || c == '\r' { ' ' } else { c })
        .take(255)
        .collect();
    let num_cells = frame.cells.len();
    let num_cells_u32 = u32::try_from(num_cells)
        .map_err(|_| IoError::invalid(path, format!("{num_cells} cells exceed u32")))?;
    let mut vertices = Vec::with_capacity(num_cells * 9);
    for c in frame.cells {
        vertices.push(8);
        vertices.extend_from_slice(c);
    }
    // vtkio's model owns its arrays, so a computed field is copied like the
    // others.
    let attribute = |f: &super::Field| -> Result<Attribute, IoError> {
        Ok(match f.values {
            FieldValues::Scalars(v) => Attribute::scalars(f.name, 1).with_data(v.to_vec()),
            FieldValues::Vectors(v) => {
                Attribute::vectors(f.name).with_data(v.as_flattened().to_vec())
            }
            FieldValues::Flags(v) => Attribute::scalars(f.name, 1)
                .with_data(IOBuffer::U8(v.iter().map(|&b| u8::from(b)).collect())),
            FieldValues::Ids(v) => Attribute::scalars(f.name, 1).with_data(v.to_vec()),
            FieldValues::Labels(v) => Attribute::scalars(f.name, 1).with_data(v.to_vec()),
            FieldValues::Computed(c) => {
                let mut values = Vec::new();
                c.with_values(&mut |v| {
                    values.extend_from_slice(v);
                    Ok(())
                })
                .map_err(|e| IoError::io(path, e))?;
                if values.len() != c.len() * c.num_components() {
                    return Err(IoError::invalid(
                        path,
                        format!(
                            "computed field {:?} gave {} numbers, expected {}",
                            f.name,
                            values.len(),
                            c.len() * c.num_components()
                        ),
                    ));
                }
                if c.num_components() == 3 {
                    Attribute::vectors(f.name).with_data(values)
                } else {
                    Attribute::scalars(f.name, 1).with_data(values)
                }
            }
        })
    };
    let vtk = Vtk {
        version: Version::new_legacy(4, 2),
        byte_order: ByteOrder::BigEndian,
        title,
        file_path: None,
        data: DataSet::inline(UnstructuredGridPiece {
            points: frame.points.as_flattened().to_vec().into(),
            cells: Cells {
                cell_verts: VertexNumbers::Legacy {
                    num_cells: num_cells_u32,
                    vertices,
                },
                types: vec![CellType::Hexahedron; num_cells],
            },
            data: Attributes {
                point: frame
                    .point_data
                    .iter()
                    .map(attribute)
                    .collect::<Result<_, _>>()?,
                cell: frame
                    .cell_data
                    .iter()
                    .map(attribute)
                    .collect::<Result<_, _>>()?,
            },
        }),
    };
    match format {
        LegacyFormat::Binary => write_atomic(path, |w| {
            vtk.write_legacy(w)
                .map_err(|e| io::Error::other(e.to_string()))
        }),
        LegacyFormat::Ascii => {
            let mut text = String::new();
            vtk.write_legacy_ascii(&mut text)
                .map_err(|e| IoError::io(path, io::Error::other(e.to_string())))?;
            write_atomic(path, |w| w.write_all(text.as_bytes()))
        }
    }
}
