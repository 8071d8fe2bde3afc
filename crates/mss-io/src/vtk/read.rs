//! Reading back the files of a run: the `.pvd` collection
//! ([`read_pvd`]), the lattice frames it lists ([`read_lattice_vtu`]) and
//! the embedded surface's frames ([`read_surface_vtu`]), for replaying a
//! run (the viewer) without ParaView.
//!
//! A run folder is input like any other: a `.pvd` may name files outside
//! its folder or be truncated, a `.vtu` may be malformed. The `.pvd` is
//! parsed as XML and only plain file names beside it are accepted; a `.vtu`
//! is read by vtkio under `catch_unwind` (it is a pre-release that panics
//! on some malformed files) after its size is checked against a limit, and
//! its hexahedra and field lengths are checked before they are returned.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::{PvdEntry, VTK_HEXAHEDRON};

/// Why a run's file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The operating system refused to read it.
    #[error("cannot read {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not what the run writes.
    #[error("{}: {reason}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

fn invalid(path: &Path, reason: impl Into<String>) -> ReadError {
    ReadError::Invalid {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

/// The files a `.pvd` collection lists, in file order (a frame of several
/// parts has one entry per part, `part` 0 first). A file name must be
/// a plain name in the `.pvd`'s own folder (no separators, no `..`), so that
/// reading a collection never reaches outside that folder; times must be
/// finite.
pub fn read_pvd(path: &Path) -> Result<Vec<PvdEntry>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut reader = quick_xml::Reader::from_str(&text);
    let mut entries = Vec::new();
    loop {
        let event = reader
            .read_event()
            .map_err(|e| invalid(path, format!("not valid XML: {e}")))?;
        match event {
            quick_xml::events::Event::Eof => break,
            quick_xml::events::Event::Empty(tag) | quick_xml::events::Event::Start(tag)
                if tag.name().as_ref() == b"DataSet" =>
            {
                let mut time = None;
                let mut file = None;
                let mut part = None;
                let mut name = None;
                for attr in tag.attributes() {
                    let attr = attr.map_err(|e| invalid(path, format!("bad attribute: {e}")))?;
                    let value = attr
                        .unescape_value()
                        .map_err(|e| invalid(path, format!("bad attribute value: {e}")))?;
                    match attr.key.as_ref() {
                        b"timestep" => time = Some(value.trim().parse::<f64>().ok()),
                        b"file" => file = Some(value.into_owned()),
                        b"part" => part = Some(value.trim().parse::<u32>().ok()),
                        b"name" => name = Some(value.into_owned()),
                        _ => {}
                    }
                }
                let n = entries.len() + 1;
                let time = match time {
                    Some(Some(t)) if t.is_finite() => t,
                    Some(_) => {
                        return Err(invalid(
                            path,
                            format!("DataSet #{n}: timestep is not a finite number"),
                        ));
                    }
                    None => return Err(invalid(path, format!("DataSet #{n} has no timestep"))),
                };
                let file =
                    file.ok_or_else(|| invalid(path, format!("DataSet #{n} has no file")))?;
                let plain =
                    !file.is_empty() && !file.contains(['/', '\\']) && file != "." && file != "..";
                if !plain {
                    return Err(invalid(
                        path,
                        format!(
                            "DataSet #{n}: file \"{file}\" is not a plain file name beside the .pvd"
                        ),
                    ));
                }
                let part = match part {
                    None => 0,
                    Some(Some(p)) => p,
                    Some(None) => {
                        return Err(invalid(
                            path,
                            format!("DataSet #{n}: part is not a whole number"),
                        ));
                    }
                };
                entries.push(PvdEntry {
                    time,
                    part,
                    name,
                    file,
                });
            }
            _ => {}
        }
    }
    if entries.is_empty() {
        return Err(invalid(path, "the collection lists no frame"));
    }
    Ok(entries)
}

/// A lattice frame read back from a `.vtu`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LatticeFrameData {
    /// Point positions (m).
    pub points: Vec<[f64; 3]>,
    /// Hexahedra, VTK_HEXAHEDRON node order.
    pub cells: Vec<[u32; 8]>,
    /// Point fields by name: the values, flattened, and their components.
    pub point_fields: HashMap<String, (Vec<f64>, usize)>,
    /// Cell fields by name, as `point_fields`.
    pub cell_fields: HashMap<String, (Vec<f64>, usize)>,
}

impl LatticeFrameData {
    /// A point field with `components` values per point, if present.
    pub fn point_field(&self, name: &str, components: usize) -> Option<&[f64]> {
        self.point_fields
            .get(name)
            .filter(|(_, c)| *c == components)
            .map(|(v, _)| v.as_slice())
    }

    /// A cell field with `components` values per cell, if present.
    pub fn cell_field(&self, name: &str, components: usize) -> Option<&[f64]> {
        self.cell_fields
            .get(name)
            .filter(|(_, c)| *c == components)
            .map(|(v, _)| v.as_slice())
    }
}

fn fields(
    path: &Path,
    attributes: Vec<vtkio::model::Attribute>,
    count: usize,
    what: &str,
) -> Result<HashMap<String, (Vec<f64>, usize)>, ReadError> {
    let mut out = HashMap::new();
    for a in attributes {
        if let vtkio::model::Attribute::DataArray(d) = a {
            let components = d.elem.num_comp() as usize;
            let values = d
                .data
                .cast_into::<f64>()
                .ok_or_else(|| invalid(path, format!("{what} field {} is not numeric", d.name)))?;
            if components == 0 || values.len() != components * count {
                return Err(invalid(
                    path,
                    format!(
                        "{what} field {} has {} values for {count} entries of {components} components",
                        d.name,
                        values.len()
                    ),
                ));
            }
            out.insert(d.name, (values, components));
        }
    }
    Ok(out)
}

/// Reads a lattice frame written by [`super::write_vtu`] (any encoding):
/// hexahedra only, every index in range, fields of the right lengths. Files
/// larger than `max_bytes` are refused before they are read, and compressed
/// arrays whose headers declare more than their piece holds, or more than
/// `max_bytes` in all, before they are decompressed.
pub fn read_lattice_vtu(path: &Path, max_bytes: u64) -> Result<LatticeFrameData, ReadError> {
    let piece = read_cells_vtu(path, max_bytes, VTK_HEXAHEDRON, 8)?;
    let points = piece.points;
    let cells: Vec<[u32; 8]> = piece
        .cells
        .chunks_exact(8)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect();
    let point_fields = fields(path, piece.data.point, points.len(), "point")?;
    let cell_fields = fields(path, piece.data.cell, cells.len(), "cell")?;
    Ok(LatticeFrameData {
        points,
        cells,
        point_fields,
        cell_fields,
    })
}

/// A 2D lattice frame read back from a `.vtu` of quads
/// ([`super::write_quads_vtu`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct QuadFrameData {
    /// Point positions (m; z = 0 for a 2D body).
    pub points: Vec<[f64; 3]>,
    /// Quads, VTK_QUAD node order (counter-clockwise).
    pub quads: Vec<[u32; 4]>,
    /// Point fields by name: the values, flattened, and their components.
    pub point_fields: HashMap<String, (Vec<f64>, usize)>,
    /// Cell fields by name, as `point_fields`.
    pub cell_fields: HashMap<String, (Vec<f64>, usize)>,
}

/// Reads a 2D lattice frame written by [`super::write_quads_vtu`], with the
/// guards of [`read_lattice_vtu`]: quads only, every index in range, fields
/// of the right lengths.
pub fn read_quads_vtu(path: &Path, max_bytes: u64) -> Result<QuadFrameData, ReadError> {
    let piece = read_cells_vtu(path, max_bytes, super::VTK_QUAD, 4)?;
    let points = piece.points;
    let quads: Vec<[u32; 4]> = piece
        .cells
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let point_fields = fields(path, piece.data.point, points.len(), "point")?;
    let cell_fields = fields(path, piece.data.cell, quads.len(), "cell")?;
    Ok(QuadFrameData {
        points,
        quads,
        point_fields,
        cell_fields,
    })
}

/// A surface frame read back from a `.vtu` of triangles (the embedded
/// surface's series, [`super::write_triangles_vtu`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceFrameData {
    /// Vertex positions (m).
    pub points: Vec<[f64; 3]>,
    /// Triangles, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

/// Reads a surface frame written by [`super::write_triangles_vtu`], with the
/// guards of [`read_lattice_vtu`]: triangles only, every index in range.
pub fn read_surface_vtu(path: &Path, max_bytes: u64) -> Result<SurfaceFrameData, ReadError> {
    let piece = read_cells_vtu(path, max_bytes, super::VTK_TRIANGLE, 3)?;
    let triangles = piece
        .cells
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    Ok(SurfaceFrameData {
        points: piece.points,
        triangles,
    })
}

/// A `.vtu` piece of one cell type, checked.
struct CellsPiece {
    points: Vec<[f64; 3]>,
    /// The cells' nodes, flattened, each in range.
    cells: Vec<u32>,
    data: vtkio::model::Attributes,
}

/// The piece of a `.vtu` whose cells are all `cell_type` of `nodes` nodes,
/// read under the guards of [`read_lattice_vtu`].
fn read_cells_vtu(
    path: &Path,
    max_bytes: u64,
    cell_type: u8,
    nodes: usize,
) -> Result<CellsPiece, ReadError> {
    let size = std::fs::metadata(path)
        .map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .len();
    if size > max_bytes {
        return Err(invalid(
            path,
            format!("{size} bytes, more than the {max_bytes} a frame may have here"),
        ));
    }
    let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // vtkio allocates what a compressed array's header declares and slices
    // its blocks by the header's sizes: a forged frame of a megabyte asked
    // for gigabytes, or panicked. The headers are checked first, against
    // what the frame's pieces declare and `max_bytes` for the whole frame.
    if let Err((line, why)) = hexmesh::vtk_bounds::check_compressed_arrays(&bytes, max_bytes) {
        return Err(invalid(path, format!("line {line}: {why}")));
    }
    let imported = hexmesh::vtk::catch_quietly(|| {
        vtkio::Vtk::parse_xml(std::io::Cursor::new(bytes.as_slice()))
    })
    .map_err(|_| {
        invalid(
            path,
            "the VTK reader failed on this file (malformed XML VTK)",
        )
    })?
    .map_err(|e| invalid(path, format!("not a readable VTK file: {e}")))?;
    let vtkio::model::DataSet::UnstructuredGrid { mut pieces, .. } = imported.data else {
        return Err(invalid(path, "not an unstructured grid (.vtu)"));
    };
    if pieces.len() != 1 {
        return Err(invalid(
            path,
            format!("{} pieces, expected 1", pieces.len()),
        ));
    }
    let vtkio::model::Piece::Inline(piece) = pieces.remove(0) else {
        return Err(invalid(path, "the piece is not inline"));
    };
    let piece = *piece;
    let flat = piece
        .points
        .cast_into::<f64>()
        .ok_or_else(|| invalid(path, "points are not numeric"))?;
    if flat.len() % 3 != 0 {
        return Err(invalid(path, "points do not come in triples"));
    }
    let points: Vec<[f64; 3]> = flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let (_, legacy) = piece.cells.cell_verts.into_legacy();
    let types = piece.cells.types;
    let what = match cell_type {
        VTK_HEXAHEDRON => "a hexahedron",
        _ => "a triangle",
    };
    let mut cells = Vec::with_capacity(types.len() * nodes);
    let mut at = 0usize;
    for (c, t) in types.iter().enumerate() {
        if *t as u8 != cell_type {
            return Err(invalid(path, format!("cell {c} is not {what}")));
        }
        if legacy.get(at) != Some(&(nodes as u32)) || legacy.len() < at + 1 + nodes {
            return Err(invalid(
                path,
                format!("cell {c} does not have {nodes} nodes"),
            ));
        }
        let cell = &legacy[at + 1..at + 1 + nodes];
        if cell.iter().any(|&n| n as usize >= points.len()) {
            return Err(invalid(
                path,
                format!("cell {c} names a node beyond the {} points", points.len()),
            ));
        }
        cells.extend_from_slice(cell);
        at += 1 + nodes;
    }
    Ok(CellsPiece {
        points,
        cells,
        data: piece.data,
    })
}
