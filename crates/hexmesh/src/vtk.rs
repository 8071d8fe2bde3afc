//! The VTK surface loader: legacy `.vtk` (ASCII or binary), XML `.vtu`
//! (unstructured grid) and `.vtp` (poly data), read with vtkio.
//!
//! The surface taken from a file:
//! - poly data: its polygons (fans) and triangle strips; vertices and lines
//!   enclose nothing and are ignored;
//! - an unstructured grid with volume cells (tetrahedra, hexahedra, voxels,
//!   wedges, pyramids): the boundary of the volume, that is every cell face
//!   that no other cell shares, turned to face away from its cell, so a
//!   tetrahedral FEM mesh voxelizes as the body it fills; surface cells
//!   beside volume cells are then ignored (they usually mark boundaries);
//! - an unstructured grid of surface cells only (triangles, quads, pixels,
//!   polygons, strips): those cells.
//!
//! The format is told from the content (`<?xml` / `<VTKFile` or
//! `# vtk DataFile`), not the extension. Legacy binary data is big-endian, as
//! the format defines. Pieces stored in other files (parallel formats) are
//! refused.
//!
//! ```
//! use hexmesh::load::MeshLoader;
//! use hexmesh::vtk::VtkLoader;
//!
//! // One tetrahedron as an unstructured grid: its 4 faces become the surface,
//! // wound outward.
//! let text = "# vtk DataFile Version 4.2\ntet\nASCII\nDATASET UNSTRUCTURED_GRID\n\
//!             POINTS 4 double\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n\
//!             CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n";
//! let mesh = VtkLoader.load(text.as_bytes(), "tet.vtk").unwrap();
//! assert_eq!(mesh.triangles.len(), 4);
//! assert!((mesh.signed_volume() - 1.0 / 6.0).abs() < 1e-15);
//! ```

use std::collections::HashMap;
use std::io::Cursor;
use std::path::PathBuf;

use vtkio::model::{CellType, DataSet, Piece, VertexNumbers, Vtk};

use crate::TriMesh;
use crate::loader::{LoadError, MeshLoader, one_line};

/// The built-in VTK loader (`.vtk`, `.vtu`, `.vtp`).
#[derive(Debug, Clone, Copy, Default)]
pub struct VtkLoader;

/// vtkio's message as a sentence for the user: its parser states
/// ("Parse error: Complete", nom's error kinds) say the data does not
/// follow the header.
fn plain_vtk_message(text: &str) -> String {
    if text.contains("Deserialization error") {
        "an attribute or value does not have the type VTK's XML format defines for it \
         (a count that is not a whole number, a name VTK does not know)"
            .to_owned()
    } else if text.contains("Parse error") {
        "the data does not follow the header: a count, a type or a keyword is wrong, \
         or the file ends early (truncated?)"
            .to_owned()
    } else {
        format!("the VTK reader refused it: {text}")
    }
}

thread_local! {
    /// Whether a panic on this thread is being caught by [`catch_quietly`].
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f`, a call into a reader that may panic on malformed input,
/// catching its panic without the panic hook printing it: the caller turns
/// it into one error line. Other threads' panics print as before (the
/// previous hook runs for them).
pub fn catch_quietly<R>(f: impl FnOnce() -> R + std::panic::UnwindSafe) -> std::thread::Result<R> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let result = std::panic::catch_unwind(f);
    QUIET.with(|q| q.set(was));
    result
}

/// Cell lists as (vertex list) per cell, from either vtkio layout. `None`
/// when the offsets are inconsistent with the connectivity.
fn cell_lists(numbers: &VertexNumbers) -> Option<Vec<Vec<u64>>> {
    match numbers {
        VertexNumbers::Legacy {
            num_cells,
            vertices,
        } => {
            let mut out = Vec::new();
            let mut at = 0usize;
            for _ in 0..*num_cells {
                let n = *vertices.get(at)? as usize;
                let cell = vertices.get(at + 1..at + 1 + n)?;
                out.push(cell.iter().map(|&v| u64::from(v)).collect());
                at += 1 + n;
            }
            Some(out)
        }
        VertexNumbers::XML {
            connectivity,
            offsets,
        } => {
            // Offsets are cell ends; some writers add a leading 0.
            let ends: &[u64] = match offsets.first() {
                Some(0) => &offsets[1..],
                _ => offsets,
            };
            let mut out = Vec::with_capacity(ends.len());
            let mut start = 0u64;
            for &end in ends {
                if end < start || end > connectivity.len() as u64 {
                    return None;
                }
                out.push(connectivity[start as usize..end as usize].to_vec());
                start = end;
            }
            Some(out)
        }
    }
}

/// Faces (vertex lists, any orientation) of a volume cell in VTK order, or
/// `None` for a cell that is not a volume.
fn volume_faces(kind: CellType, v: &[u64]) -> Option<Vec<Vec<u64>>> {
    let pick = |faces: &[&[usize]]| -> Option<Vec<Vec<u64>>> {
        faces
            .iter()
            .map(|f| f.iter().map(|&i| v.get(i).copied()).collect())
            .collect()
    };
    match kind {
        CellType::Tetra => pick(&[&[0, 1, 2], &[0, 1, 3], &[1, 2, 3], &[0, 2, 3]]),
        CellType::Hexahedron => pick(&[
            &[0, 1, 2, 3],
            &[4, 5, 6, 7],
            &[0, 1, 5, 4],
            &[1, 2, 6, 5],
            &[2, 3, 7, 6],
            &[3, 0, 4, 7],
        ]),
        // A voxel's points run x fastest, then y, then z.
        CellType::Voxel => pick(&[
            &[0, 1, 3, 2],
            &[4, 5, 7, 6],
            &[0, 1, 5, 4],
            &[1, 3, 7, 5],
            &[3, 2, 6, 7],
            &[2, 0, 4, 6],
        ]),
        CellType::Wedge => pick(&[
            &[0, 1, 2],
            &[3, 4, 5],
            &[0, 1, 4, 3],
            &[1, 2, 5, 4],
            &[2, 0, 3, 5],
        ]),
        CellType::Pyramid => pick(&[
            &[0, 1, 2, 3],
            &[0, 1, 4],
            &[1, 2, 4],
            &[2, 3, 4],
            &[3, 0, 4],
        ]),
        _ => None,
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn centroid(points: &[[f64; 3]], ids: &[u64]) -> [f64; 3] {
    let mut c = [0.0; 3];
    for &i in ids {
        for k in 0..3 {
            c[k] += points[i as usize][k];
        }
    }
    c.map(|x| x / ids.len() as f64)
}

/// Newell's normal of a polygon (robust for non-planar quads).
fn newell(points: &[[f64; 3]], ids: &[u64]) -> [f64; 3] {
    let mut n = [0.0; 3];
    for (k, &i) in ids.iter().enumerate() {
        let a = points[i as usize];
        let b = points[ids[(k + 1) % ids.len()] as usize];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

fn fan(ids: &[u64], out: &mut Vec<[u32; 3]>) {
    for pair in ids[1..].windows(2) {
        out.push([ids[0] as u32, pair[0] as u32, pair[1] as u32]);
    }
}

fn strip(ids: &[u64], out: &mut Vec<[u32; 3]>) {
    for (k, w) in ids.windows(3).enumerate() {
        let [a, b, c] = [w[0] as u32, w[1] as u32, w[2] as u32];
        // Every second triangle of a strip is wound the other way.
        out.push(if k % 2 == 0 { [a, b, c] } else { [b, a, c] });
    }
}

struct Surface<'a> {
    name: &'a str,
    points: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl Surface<'_> {
    fn error(&self, message: String) -> LoadError {
        LoadError::Parse {
            file: PathBuf::from(self.name),
            line: None,
            message,
        }
    }

    fn check_ids(&self, cell: usize, ids: &[u64]) -> Result<(), LoadError> {
        let n = self.points.len();
        match ids
            .iter()
            .find(|&&i| i >= n as u64 || i > u64::from(u32::MAX))
        {
            Some(&bad) => Err(LoadError::IndexOutOfRange {
                file: PathBuf::from(self.name),
                triangle: cell,
                index: bad,
                vertices: n,
            }),
            None => Ok(()),
        }
    }

    fn add_polys(
        &mut self,
        numbers: &Option<VertexNumbers>,
        strips: bool,
    ) -> Result<(), LoadError> {
        let Some(numbers) = numbers else {
            return Ok(());
        };
        let cells = cell_lists(numbers)
            .ok_or_else(|| self.error("cell offsets do not match the connectivity".into()))?;
        for (c, ids) in cells.iter().enumerate() {
            self.check_ids(c, ids)?;
            if ids.len() >= 3 {
                let mut out = std::mem::take(&mut self.triangles);
                if strips {
                    strip(ids, &mut out)
                } else {
                    fan(ids, &mut out)
                }
                self.triangles = out;
            }
        }
        Ok(())
    }

    /// Surface of an unstructured grid: the boundary of its volume cells,
    /// or its surface cells when it has no volume cells.
    fn add_grid(&mut self, cells: &[Vec<u64>], types: &[CellType]) -> Result<(), LoadError> {
        if cells.len() != types.len() {
            return Err(self.error(format!(
                "{} cells but {} cell types",
                cells.len(),
                types.len()
            )));
        }
        for (c, ids) in cells.iter().enumerate() {
            self.check_ids(c, ids)?;
        }
        let has_volume = types
            .iter()
            .zip(cells)
            .any(|(&t, ids)| volume_faces(t, ids).is_some());
        if !has_volume {
            for (ids, &t) in cells.iter().zip(types) {
                match t {
                    CellType::Triangle | CellType::Quad | CellType::Polygon if ids.len() >= 3 => {
                        fan(ids, &mut self.triangles)
                    }
                    CellType::Pixel if ids.len() == 4 => {
                        fan(&[ids[0], ids[1], ids[3], ids[2]], &mut self.triangles)
                    }
                    CellType::TriangleStrip => strip(ids, &mut self.triangles),
                    _ => {}
                }
            }
            return Ok(());
        }
        // Each face keyed by its sorted vertices: count it, and keep the
        // copy turned away from its own cell's centre.
        let mut faces: HashMap<Vec<u64>, (u32, Vec<u64>)> = HashMap::new();
        for (ids, &t) in cells.iter().zip(types) {
            let Some(cell_faces) = volume_faces(t, ids) else {
                continue;
            };
            let centre = centroid(&self.points, ids);
            for mut face in cell_faces {
                let n = newell(&self.points, &face);
                let out = sub(centroid(&self.points, &face), centre);
                if n[0] * out[0] + n[1] * out[1] + n[2] * out[2] < 0.0 {
                    face.reverse();
                }
                let mut key = face.clone();
                key.sort_unstable();
                faces
                    .entry(key)
                    .and_modify(|e| e.0 += 1)
                    .or_insert((1, face));
            }
        }
        // Sorted, so the triangle order does not depend on hashing.
        let mut boundary: Vec<Vec<u64>> = faces
            .into_values()
            .filter(|(count, _)| *count == 1)
            .map(|(_, face)| face)
            .collect();
        boundary.sort_unstable();
        for face in &boundary {
            fan(face, &mut self.triangles);
        }
        Ok(())
    }
}

impl MeshLoader for VtkLoader {
    fn extensions(&self) -> &[&str] {
        &["vtk", "vtu", "vtp"]
    }

    fn load(&self, bytes: &[u8], name: &str) -> Result<TriMesh, LoadError> {
        self.load_within(bytes, name, crate::load::MAX_UNPACKED_BYTES)
    }

    /// Reads the file, refusing compressed XML arrays whose headers declare
    /// more than their pieces can need or more than `budget` bytes in all,
    /// before any is decompressed.
    fn load_within(&self, bytes: &[u8], name: &str, budget: u64) -> Result<TriMesh, LoadError> {
        let parse_error = |message: String| LoadError::Parse {
            file: PathBuf::from(name),
            line: None,
            message,
        };
        let head = bytes.trim_ascii_start();
        let is_xml = head.starts_with(b"<?xml") || head.starts_with(b"<VTKFile");
        let is_legacy = head.starts_with(b"# vtk DataFile");
        if !is_xml && !is_legacy {
            return Err(LoadError::Parse {
                file: PathBuf::from(name),
                line: Some(1),
                message: "neither a legacy VTK file (\"# vtk DataFile ...\") nor VTK XML".into(),
            });
        }
        // vtkio passes over text it does not expect (a misspelt section is
        // silently dropped) and its errors carry no position: check the
        // geometry sections of ASCII surface files first.
        if is_legacy
            && !is_binary_legacy(bytes)
            && is_surface_dataset(bytes)
            && let Some((line, message)) = locate_legacy_problem(bytes)
        {
            return Err(LoadError::Parse {
                file: PathBuf::from(name),
                line: Some(line),
                message,
            });
        }
        // vtkio's XML reader asserts on mismatched tags (a panic, and no
        // position): check that the XML is well formed first, with lines.
        if is_xml && let Err((line, message)) = check_xml(bytes) {
            return Err(LoadError::Parse {
                file: PathBuf::from(name),
                line: Some(line),
                message,
            });
        }
        // vtkio allocates what a compressed array's header declares and
        // slices its blocks by the header's sizes: check the headers first.
        if is_xml
            && let Err((line, message)) = crate::vtk_bounds::check_compressed_arrays(bytes, budget)
        {
            return Err(LoadError::Parse {
                file: PathBuf::from(name),
                line: Some(line),
                message,
            });
        }
        // vtkio is a pre-release: a panic inside it on a malformed file must
        // still be an error about that file, not an abort of the program,
        // and its message must not reach the user's terminal.
        let parsed = catch_quietly(|| {
            if is_xml {
                Vtk::parse_xml(Cursor::new(bytes))
            } else {
                Vtk::parse_legacy_be(Cursor::new(bytes))
            }
        })
        .map_err(|_| parse_error("the VTK reader failed on this file (malformed data)".into()))?
        .map_err(|e| parse_error(plain_vtk_message(&one_line(&e.to_string()))))?;

        let mut surface = Surface {
            name,
            points: Vec::new(),
            triangles: Vec::new(),
        };
        let points_of = |buffer: &vtkio::model::IOBuffer| -> Result<Vec<[f64; 3]>, LoadError> {
            let flat: Vec<f64> = buffer
                .cast_into::<f64>()
                .ok_or_else(|| parse_error("points are not numbers".into()))?;
            if !flat.len().is_multiple_of(3) {
                return Err(parse_error(format!(
                    "{} point coordinates, not a multiple of 3",
                    flat.len()
                )));
            }
            Ok(flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
        };
        let inline = |kind: &str, count: usize| -> Result<(), LoadError> {
            if count != 1 {
                return Err(parse_error(format!(
                    "{kind} with {count} pieces; give a file with one inline piece"
                )));
            }
            Ok(())
        };
        match parsed.data {
            DataSet::PolyData { pieces, .. } => {
                inline("poly data", pieces.len())?;
                let Some(Piece::Inline(piece)) = pieces.into_iter().next() else {
                    return Err(parse_error("poly data stored in another file".into()));
                };
                surface.points = points_of(&piece.points)?;
                surface.add_polys(&piece.polys, false)?;
                surface.add_polys(&piece.strips, true)?;
            }
            DataSet::UnstructuredGrid { pieces, .. } => {
                inline("unstructured grid", pieces.len())?;
                let Some(Piece::Inline(piece)) = pieces.into_iter().next() else {
                    return Err(parse_error(
                        "unstructured grid stored in another file".into(),
                    ));
                };
                surface.points = points_of(&piece.points)?;
                let cells = cell_lists(&piece.cells.cell_verts).ok_or_else(|| {
                    parse_error("cell offsets do not match the connectivity".into())
                })?;
                surface.add_grid(&cells, &piece.cells.types)?;
            }
            _ => {
                return Err(parse_error(
                    "the data set is neither poly data nor an unstructured grid: it holds no surface"
                        .into(),
                ));
            }
        }
        Ok(TriMesh {
            vertices: surface.points,
            triangles: surface.triangles,
        })
    }
}

/// Checks that `bytes` is well-formed XML (tags balanced and matching);
/// on error, the 1-based line and what is wrong. Files with raw appended
/// data (arbitrary bytes after `<AppendedData encoding="raw">`) are checked
/// only up to it.
fn check_xml(bytes: &[u8]) -> Result<(), (usize, String)> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_reader(bytes);
    reader.config_mut().check_end_names = true;
    let mut buf = Vec::new();
    let line_at = |pos: u64| {
        let pos = (pos as usize).min(bytes.len());
        bytes[..pos].iter().filter(|&&b| b == b'\n').count() + 1
    };
    // Open elements: name and line.
    let mut open: Vec<(String, usize)> = Vec::new();
    loop {
        match reader.read_event_into(&mut buf) {
            Ok(Event::Eof) => {
                return match open.last() {
                    None => Ok(()),
                    Some((name, line)) => Err((
                        line_at(bytes.len() as u64),
                        format!(
                            "the file ends inside <{name}> (opened on line {line}): is it truncated?"
                        ),
                    )),
                };
            }
            Ok(Event::Start(e)) => {
                if e.name().as_ref() == b"AppendedData"
                    && e.attributes()
                        .flatten()
                        .any(|a| a.key.as_ref() == b"encoding" && a.value.as_ref() == b"raw")
                {
                    return Ok(());
                }
                let name = String::from_utf8_lossy(e.name().as_ref()).into_owned();
                open.push((name, line_at(reader.buffer_position())));
            }
            Ok(Event::End(_)) => {
                open.pop();
            }
            Ok(_) => {}
            Err(e) => {
                return Err((
                    line_at(reader.error_position()),
                    format!("malformed XML: {}", one_line(&e.to_string())),
                ));
            }
        }
        buf.clear();
    }
}

/// Whether a legacy file's fourth line is `DATASET POLYDATA` or
/// `DATASET UNSTRUCTURED_GRID`.
fn is_surface_dataset(bytes: &[u8]) -> bool {
    bytes.split(|&b| b == b'\n').nth(3).is_some_and(|l| {
        let words: Vec<String> = String::from_utf8_lossy(l)
            .split_whitespace()
            .map(str::to_ascii_uppercase)
            .collect();
        words.len() == 2
            && words[0] == "DATASET"
            && (words[1] == "POLYDATA" || words[1] == "UNSTRUCTURED_GRID")
    })
}

/// Whether a legacy file says `BINARY` on its third line.
fn is_binary_legacy(bytes: &[u8]) -> bool {
    bytes
        .split(|&b| b == b'\n')
        .nth(2)
        .is_some_and(|l| l.trim_ascii().eq_ignore_ascii_case(b"BINARY"))
}

/// For an ASCII legacy file vtkio refused: the first line that is clearly
/// wrong in the geometry sections (an unknown keyword, a token that is not a
/// number where numbers are due, a section shorter than its header says),
/// and what is wrong. Attribute data from `POINT_DATA` / `CELL_DATA` on is not
/// checked.
fn locate_legacy_problem(bytes: &[u8]) -> Option<(usize, String)> {
    let text = String::from_utf8_lossy(bytes);
    let lines: Vec<&str> = text.lines().collect();
    // After the version, title, encoding and DATASET lines.
    let mut at = 4;
    while at < lines.len() {
        let words: Vec<&str> = lines[at].split_whitespace().collect();
        let header = at + 1;
        at += 1;
        let Some(first) = words.first() else {
            continue;
        };
        let count = |i: usize| words.get(i).and_then(|w| w.parse::<u64>().ok());
        let version5 = lines
            .get(at)
            .is_some_and(|l| l.trim_start().to_ascii_uppercase().starts_with("OFFSETS"));
        let blocks: Vec<(Option<u64>, &str)> = match first.to_ascii_uppercase().as_str() {
            "POINT_DATA" | "CELL_DATA" | "FIELD" | "METADATA" => return None,
            "POINTS" => vec![(count(1).and_then(|n| n.checked_mul(3)), "point coordinates")],
            "CELLS" if version5 => vec![(count(1), "offsets"), (count(2), "connectivity entries")],
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" | "CELLS" => {
                vec![(count(2), "cell entries")]
            }
            "CELL_TYPES" => vec![(count(1), "cell types")],
            _ => {
                return Some((
                    header,
                    format!(
                        "unexpected {:?} where a section keyword is due",
                        lines[header - 1].trim()
                    ),
                ));
            }
        };
        for (n, what) in blocks {
            let Some(n) = n else {
                return Some((
                    header,
                    format!("bad section header {:?}", lines[header - 1].trim()),
                ));
            };
            if version5 {
                // The OFFSETS / CONNECTIVITY line before each block.
                at += 1;
            }
            if let Err(e) = take_numbers(&lines, &mut at, n, what) {
                return Some(e);
            }
        }
    }
    None
}

/// Consumes `count` numbers from `lines` starting at `*at`; an error names
/// the line of a token that is not a number, or where the section ended.
fn take_numbers(
    lines: &[&str],
    at: &mut usize,
    count: u64,
    what: &str,
) -> Result<(), (usize, String)> {
    let mut left = count;
    while left > 0 {
        let Some(line) = lines.get(*at) else {
            return Err((
                lines.len(),
                format!("the file ends {left} {what} short of the {count} announced"),
            ));
        };
        for token in line.split_whitespace() {
            if left == 0 {
                return Err((
                    *at + 1,
                    format!("more values than the {count} {what} announced"),
                ));
            }
            if token.parse::<f64>().is_err() {
                return Err((
                    *at + 1,
                    format!(
                        "{token:?} is not a number ({count} {what} announced, {left} still due)"
                    ),
                ));
            }
            left -= 1;
        }
        *at += 1;
    }
    Ok(())
}
