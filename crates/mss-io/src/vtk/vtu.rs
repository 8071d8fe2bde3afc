//! XML UnstructuredGrid (`.vtu`) writer.
//!
//! Written here rather than through vtkio's XML writer: vtkio needs every array
//! copied into its owned model, then builds the whole base64 (and compressed)
//! text in memory before serialising it, and compresses single-threaded. This
//! writer streams each array straight from the caller's slices into the file
//! and compresses the 32 KiB blocks of an array in parallel, 64 at a time,
//! writing each group before the next (the output does not depend on the
//! number of threads; the array's header, which lists the blocks' sizes and
//! comes first, is filled in afterwards). Computed fields
//! ([`super::ComputedValues`]) are asked for when their array is written,
//! block by block when they can be. The `write` bench compares both.
//! vtkio is still used to read the files back in the tests.
//!
//! Layout, as written by VTK itself: `header_type="UInt64"`, little-endian,
//! inline `format="binary"` (base64) or `format="ascii"`. Uncompressed binary
//! arrays are one base64 stream of `[byte count][data]`; ZLib-compressed ones
//! are a base64 header `[blocks][block size][last block size][compressed
//! sizes...]` followed by a separate base64 stream of the compressed blocks.
//! The last block size is always its true size (never 0), which VTK, meshio
//! and vtkio all read correctly.

use super::{
    ComputedValues, Field, FieldValues, Grid, LatticeFrame, VTK_HEXAHEDRON, VTK_LINE, validate_grid,
};
use crate::IoError;
use crate::atomic::{WriteSeek, write_atomic_seekable};
use crate::numfmt::write_f64;
use base64::Engine as _;
use base64::engine::general_purpose::STANDARD;
use flate2::Compression;
use flate2::write::ZlibEncoder;
use rayon::prelude::*;
use std::io::{self, Write};
use std::path::Path;

/// How the arrays of a `.vtu` file are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum VtuEncoding {
    /// Human-readable numbers (shortest digits that parse back exactly).
    /// Large and slow; for debugging and tiny meshes.
    Ascii,
    /// Raw little-endian bytes, base64-encoded inline.
    Base64,
    /// ZLib-compressed blocks, base64-encoded inline (the default: smallest
    /// files, read by ParaView/VTK, meshio and vtkio).
    #[default]
    Base64Zlib,
}

/// Uncompressed size of one compressed block (VTK's default).
const BLOCK_BYTES: usize = 1 << 15;
/// Elements converted to bytes at a time when streaming an uncompressed array.
const CHUNK_ELEMS: usize = 1 << 13;
/// ZLib level: fast compression. On smooth `f64` fields of a 64^3 lattice,
/// level 1 gave 13.2 MB -> 4.6 MB in 97 ms, level 6 -> 3.6 MB in 271 ms (one
/// thread, zlib-rs): frames are written often, so speed wins.
const ZLIB_LEVEL: u32 = 1;

/// Writes one lattice frame as an XML UnstructuredGrid of VTK_HEXAHEDRON
/// cells, atomically. Points and float fields are written as `Float64`,
/// flags as `UInt8`, ids as `UInt32`, connectivity and offsets as `Int64`.
pub fn write_vtu(path: &Path, frame: &LatticeFrame, encoding: VtuEncoding) -> Result<(), IoError> {
    frame.validate(path)?;
    let grid = Grid {
        points: frame.points,
        connectivity: frame.cells.as_flattened(),
        nodes_per_cell: 8,
        cell_type: VTK_HEXAHEDRON,
        point_data: &frame.point_data,
        cell_data: &frame.cell_data,
    };
    write_atomic_seekable(path, |w| write_grid(w, &grid, encoding))
}

/// Writes line cells (VTK_LINE), e.g. the springs of a lattice with their
/// strain as a cell field, as an XML UnstructuredGrid, atomically.
/// `cell_data` fields have one entry per line.
pub fn write_lines_vtu(
    path: &Path,
    points: &[[f64; 3]],
    lines: &[[u32; 2]],
    cell_data: &[Field],
    encoding: VtuEncoding,
) -> Result<(), IoError> {
    write_cells_vtu(path, points, lines, VTK_LINE, &[], cell_data, encoding)
}

/// Writes quadrilateral cells (VTK_QUAD, 4 points counter-clockwise), e.g.
/// a 2D lattice with its point and cell fields, as an XML
/// UnstructuredGrid, atomically.
pub fn write_quads_vtu(
    path: &Path,
    points: &[[f64; 3]],
    quads: &[[u32; 4]],
    point_data: &[Field],
    cell_data: &[Field],
    encoding: VtuEncoding,
) -> Result<(), IoError> {
    let quad = super::VTK_QUAD;
    write_cells_vtu(path, points, quads, quad, point_data, cell_data, encoding)
}

/// Writes a triangulated surface (VTK_TRIANGLE cells), e.g. the embedded
/// input surface of a frame, with its point fields, as an XML
/// UnstructuredGrid, atomically.
pub fn write_triangles_vtu(
    path: &Path,
    points: &[[f64; 3]],
    triangles: &[[u32; 3]],
    point_data: &[Field],
    encoding: VtuEncoding,
) -> Result<(), IoError> {
    let triangle = super::VTK_TRIANGLE;
    write_cells_vtu(path, points, triangles, triangle, point_data, &[], encoding)
}

/// Cells of `N` nodes and one `cell_type`, checked, as an XML
/// UnstructuredGrid, atomically.
fn write_cells_vtu<const N: usize>(
    path: &Path,
    points: &[[f64; 3]],
    cells: &[[u32; N]],
    cell_type: u8,
    point_data: &[Field],
    cell_data: &[Field],
    encoding: VtuEncoding,
) -> Result<(), IoError> {
    let connectivity = cells.as_flattened();
    validate_grid(path, points, connectivity, N, point_data, cell_data)?;
    let grid = Grid {
        points,
        connectivity,
        nodes_per_cell: N,
        cell_type,
        point_data,
        cell_data,
    };
    write_atomic_seekable(path, |w| write_grid(w, &grid, encoding))
}

/// An array as the writer sees it: a typed source of elements, some generated
/// on the fly so that nothing is copied before encoding.
#[derive(Clone, Copy)]
enum Source<'a> {
    F64(&'a [f64]),
    /// `Float64` values computed a block at a time
    /// ([`ComputedValues::values_of`]); the second field is the components
    /// per entry.
    Ranged(&'a dyn ComputedValues, usize),
    /// Written as Int64 (connectivity).
    U32AsI64(&'a [u32]),
    /// Written as UInt32.
    U32(&'a [u32]),
    /// Written as Int32.
    I32(&'a [i32]),
    /// Written as UInt8 0/1.
    Bool(&'a [bool]),
    /// Int64 offsets `step, 2 step, ..., count step`.
    Offsets {
        count: usize,
        step: usize,
    },
    /// `count` copies of one UInt8 (cell types).
    ConstU8 {
        count: usize,
        value: u8,
    },
}

impl Source<'_> {
    fn len(&self) -> usize {
        match *self {
            Source::F64(v) => v.len(),
            Source::Ranged(c, comps) => c.len() * comps,
            Source::U32AsI64(v) | Source::U32(v) => v.len(),
            Source::I32(v) => v.len(),
            Source::Bool(v) => v.len(),
            Source::Offsets { count, .. } | Source::ConstU8 { count, .. } => count,
        }
    }

    fn elem_size(&self) -> usize {
        match self {
            Source::F64(_) | Source::Ranged(..) | Source::U32AsI64(_) | Source::Offsets { .. } => 8,
            Source::U32(_) | Source::I32(_) => 4,
            Source::Bool(_) | Source::ConstU8 { .. } => 1,
        }
    }

    fn vtk_type(&self) -> &'static str {
        match self {
            Source::F64(_) | Source::Ranged(..) => "Float64",
            Source::U32AsI64(_) | Source::Offsets { .. } => "Int64",
            Source::U32(_) => "UInt32",
            Source::I32(_) => "Int32",
            Source::Bool(_) | Source::ConstU8 { .. } => "UInt8",
        }
    }

    /// Appends the little-endian bytes of elements `range` to `out`.
    fn push_bytes(&self, range: std::ops::Range<usize>, out: &mut Vec<u8>) -> io::Result<()> {
        match *self {
            Source::Ranged(c, comps) => {
                // Elements are numbers; a block may start or end inside an
                // entry.
                let entries = range.start / comps..range.end.div_ceil(comps);
                let skip = range.start - entries.start * comps;
                let expected = entries.len() * comps;
                let mut values = Vec::with_capacity(expected);
                if !c.values_of(entries, &mut values) || values.len() != expected {
                    return Err(io::Error::other(format!(
                        "a computed field gave {} numbers for a block, expected {expected}",
                        values.len()
                    )));
                }
                values[skip..skip + range.len()]
                    .iter()
                    .for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
            }
            Source::F64(v) => v[range]
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Source::U32AsI64(v) => v[range]
                .iter()
                .for_each(|&x| out.extend_from_slice(&i64::from(x).to_le_bytes())),
            Source::U32(v) => v[range]
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Source::I32(v) => v[range]
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Source::Bool(v) => out.extend(v[range].iter().map(|&b| u8::from(b))),
            Source::Offsets { step, .. } => range
                .for_each(|k| out.extend_from_slice(&((k as i64 + 1) * step as i64).to_le_bytes())),
            Source::ConstU8 { value, .. } => out.extend(range.map(|_| value)),
        }
        Ok(())
    }

    fn write_ascii_elem(&self, w: &mut dyn Write, k: usize) -> io::Result<()> {
        match *self {
            Source::F64(v) => write_f64(w, v[k]),
            // `field_array` hands the ASCII writer computed values whole.
            Source::Ranged(..) => Err(io::Error::other("ranged values are not written as ASCII")),
            Source::U32AsI64(v) | Source::U32(v) => write!(w, "{}", v[k]),
            Source::I32(v) => write!(w, "{}", v[k]),
            Source::Bool(v) => write!(w, "{}", u8::from(v[k])),
            Source::Offsets { step, .. } => write!(w, "{}", (k + 1) * step),
            Source::ConstU8 { value, .. } => write!(w, "{value}"),
        }
    }
}

/// Writes `f` as a `DataArray`; a computed field's values exist only for
/// the call.
fn field_array(w: &mut dyn WriteSeek, f: &Field, enc: VtuEncoding) -> io::Result<()> {
    let comps = f.values.num_components();
    let src = match f.values {
        FieldValues::Scalars(v) => Source::F64(v),
        FieldValues::Vectors(v) => Source::F64(v.as_flattened()),
        FieldValues::Flags(v) => Source::Bool(v),
        FieldValues::Ids(v) => Source::U32(v),
        FieldValues::Labels(v) => Source::I32(v),
        FieldValues::Computed(c)
            if enc != VtuEncoding::Ascii && c.values_of(0..0, &mut Vec::new()) =>
        {
            return data_array(w, f.name, comps, Source::Ranged(c, comps), enc)
                .map_err(|e| io::Error::other(format!("computed field {:?}: {e}", f.name)));
        }
        FieldValues::Computed(c) => {
            let expected = c.len() * comps;
            return c.with_values(&mut |v| {
                if v.len() != expected {
                    return Err(io::Error::other(format!(
                        "computed field {:?} gave {} numbers, expected {expected}",
                        f.name,
                        v.len()
                    )));
                }
                data_array(w, f.name, comps, Source::F64(v), enc)
            });
        }
    };
    data_array(w, f.name, comps, src, enc)
}

pub(crate) fn write_grid(w: &mut dyn WriteSeek, g: &Grid, enc: VtuEncoding) -> io::Result<()> {
    let compressor = if enc == VtuEncoding::Base64Zlib {
        " compressor=\"vtkZLibDataCompressor\""
    } else {
        ""
    };
    let num_cells = g.num_cells();
    write!(
        w,
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\"{compressor}>\n  <UnstructuredGrid>\n    \
         <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{num_cells}\">\n",
        g.points.len()
    )?;
    write_attributes(w, "PointData", g.point_data, enc)?;
    write_attributes(w, "CellData", g.cell_data, enc)?;
    w.write_all(b"      <Points>\n")?;
    data_array(w, "Points", 3, Source::F64(g.points.as_flattened()), enc)?;
    w.write_all(b"      </Points>\n      <Cells>\n")?;
    data_array(w, "connectivity", 1, Source::U32AsI64(g.connectivity), enc)?;
    let offsets = Source::Offsets {
        count: num_cells,
        step: g.nodes_per_cell,
    };
    data_array(w, "offsets", 1, offsets, enc)?;
    let types = Source::ConstU8 {
        count: num_cells,
        value: g.cell_type,
    };
    data_array(w, "types", 1, types, enc)?;
    w.write_all(b"      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n")
}

fn write_attributes(
    w: &mut dyn WriteSeek,
    tag: &str,
    fields: &[Field],
    enc: VtuEncoding,
) -> io::Result<()> {
    if fields.is_empty() {
        return Ok(());
    }
    writeln!(w, "      <{tag}>")?;
    for f in fields {
        field_array(w, f, enc)?;
    }
    writeln!(w, "      </{tag}>")
}

fn data_array(
    w: &mut dyn WriteSeek,
    name: &str,
    num_comp: usize,
    src: Source,
    enc: VtuEncoding,
) -> io::Result<()> {
    let format = if enc == VtuEncoding::Ascii {
        "ascii"
    } else {
        "binary"
    };
    write!(
        w,
        "        <DataArray type=\"{}\" Name=\"{name}\" NumberOfComponents=\"{num_comp}\" \
         format=\"{format}\">\n          ",
        src.vtk_type()
    )?;
    match enc {
        VtuEncoding::Ascii => write_ascii(w, src, num_comp)?,
        VtuEncoding::Base64 => write_base64(w, src)?,
        VtuEncoding::Base64Zlib => write_zlib(w, src)?,
    }
    w.write_all(b"\n        </DataArray>\n")
}

fn write_ascii(w: &mut dyn Write, src: Source, num_comp: usize) -> io::Result<()> {
    // A few tuples per line keeps lines short without bloating the file.
    let per_line = (6 / num_comp).max(1) * num_comp;
    for k in 0..src.len() {
        if k > 0 {
            w.write_all(if k % per_line == 0 {
                b"\n          "
            } else {
                b" "
            })?;
        }
        src.write_ascii_elem(w, k)?;
    }
    Ok(())
}

/// Streams raw bytes as one base64 text, encoding large chunks at a time
/// (much faster than `base64::write::EncoderWriter`'s 1 KiB writes).
struct Base64Stream<'w> {
    w: &'w mut dyn Write,
    raw: Vec<u8>,
    text: Vec<u8>,
}

impl<'w> Base64Stream<'w> {
    /// Raw bytes encoded per write; a multiple of 3 so chunks join seamlessly.
    const CHUNK: usize = 3 << 16;

    fn new(w: &'w mut dyn Write) -> Self {
        Base64Stream {
            w,
            raw: Vec::with_capacity(Self::CHUNK + BLOCK_BYTES),
            text: Vec::with_capacity(4 * (Self::CHUNK + BLOCK_BYTES) / 3 + 4),
        }
    }

    /// Gives access to the pending raw bytes; call [`Self::flush_full`] after.
    fn raw(&mut self) -> &mut Vec<u8> {
        &mut self.raw
    }

    fn push(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.raw.extend_from_slice(bytes);
        self.flush_full()
    }

    /// Encodes and writes the largest multiple of 3 bytes once enough is pending.
    fn flush_full(&mut self) -> io::Result<()> {
        if self.raw.len() >= Self::CHUNK {
            let n = self.raw.len() / 3 * 3;
            self.encode(n)?;
            self.raw.drain(..n);
        }
        Ok(())
    }

    fn encode(&mut self, n: usize) -> io::Result<()> {
        self.text.resize(4 * n.div_ceil(3), 0);
        let len = STANDARD
            .encode_slice(&self.raw[..n], &mut self.text)
            .map_err(io::Error::other)?;
        self.w.write_all(&self.text[..len])
    }

    /// Encodes the rest, with padding.
    fn finish(mut self) -> io::Result<()> {
        let n = self.raw.len();
        self.encode(n)
    }
}

fn write_base64(w: &mut dyn Write, src: Source) -> io::Result<()> {
    let n = src.len();
    let total = (n * src.elem_size()) as u64;
    let mut b64 = Base64Stream::new(w);
    b64.push(&total.to_le_bytes())?;
    let mut start = 0;
    while start < n {
        let end = (start + CHUNK_ELEMS).min(n);
        src.push_bytes(start..end, b64.raw())?;
        b64.flush_full()?;
        start = end;
    }
    b64.finish()
}

/// Blocks compressed at once (2 MiB of raw bytes): in parallel within a
/// group, written before the next group is compressed.
const BLOCKS_PER_GROUP: usize = 64;

/// Writes `src` as a ZLib-compressed array. The header (block count and
/// sizes) comes first in the file but is known only once every block is
/// compressed; its base64 text has a known length, so a placeholder is
/// written and filled in afterwards, and the compressed blocks are written
/// a group at a time instead of being held until the end (for a large
/// lattice they are most of a frame's memory).
fn write_zlib(w: &mut dyn WriteSeek, src: Source) -> io::Result<()> {
    let elem = src.elem_size();
    let per_block = BLOCK_BYTES / elem;
    let n = src.len();
    let num_blocks = n.div_ceil(per_block);
    let header_bytes = 8 * (3 + num_blocks);
    let header_at = w.stream_position()?;
    w.write_all(&vec![b'A'; 4 * header_bytes.div_ceil(3)])?;
    let mut sizes: Vec<u64> = Vec::with_capacity(num_blocks);
    let mut b64 = Base64Stream::new(w);
    for group in (0..num_blocks).step_by(BLOCKS_PER_GROUP) {
        // Blocks are independent: compress them in parallel, keep their order.
        let blocks: Vec<io::Result<Vec<u8>>> = (group..(group + BLOCKS_PER_GROUP).min(num_blocks))
            .into_par_iter()
            .map(|b| {
                let range = b * per_block..((b + 1) * per_block).min(n);
                let mut raw = Vec::with_capacity(BLOCK_BYTES);
                src.push_bytes(range, &mut raw)?;
                let mut z = ZlibEncoder::new(
                    Vec::with_capacity(BLOCK_BYTES / 2),
                    Compression::new(ZLIB_LEVEL),
                );
                z.write_all(&raw)?;
                z.finish()
            })
            .collect();
        for block in blocks {
            let block = block?;
            sizes.push(block.len() as u64);
            b64.push(&block)?;
        }
    }
    b64.finish()?;
    let end = w.stream_position()?;
    let last = n * elem - num_blocks.saturating_sub(1) * per_block * elem;
    let mut header: Vec<u8> = Vec::with_capacity(header_bytes);
    for x in [num_blocks, per_block * elem, last] {
        header.extend((x as u64).to_le_bytes());
    }
    for size in sizes {
        header.extend(size.to_le_bytes());
    }
    w.seek(io::SeekFrom::Start(header_at))?;
    w.write_all(STANDARD.encode(&header).as_bytes())?;
    w.seek(io::SeekFrom::Start(end))?;
    Ok(())
}
