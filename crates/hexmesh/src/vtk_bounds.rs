//! What the compressed arrays of a VTK XML file will cost to read, known
//! before any of them is decompressed.
//!
//! A compressed inline array starts with a header, base64-encoded on its
//! own: the number of blocks `nb`, the block size `nu`, the size of the
//! last block `np` and the compressed size of every block (VTK's XML
//! format; 32- or 64-bit integers per `header_type`). The reader allocates
//! `nu (nb - 1) + np` bytes for the array and slices the compressed blocks
//! out of the text by those sizes. A header that lies makes it allocate
//! gigabytes for a file of a megabyte, or slice past the text's end (a
//! panic inside the reader). So every header is checked first: its blocks
//! must lie within the array's text, and what it will allocate within what
//! the piece declares (its points and cells, the array's components and
//! type) and within the caller's budget for the whole file.

use base64::Engine as _;
use quick_xml::events::Event;

/// Bytes an element of a VTK scalar type takes (`None`: not a VTK type).
fn type_bytes(name: &[u8]) -> Option<u64> {
    Some(match name {
        b"Int8" | b"UInt8" => 1,
        b"Int16" | b"UInt16" => 2,
        b"Int32" | b"UInt32" | b"Float32" => 4,
        b"Int64" | b"UInt64" | b"Float64" => 8,
        _ => return None,
    })
}

/// Vertices a cell of a surface or volume mesh may list at most, for the
/// bound of a connectivity array (a polygon of more is not a mesh this
/// loader reads).
const MAX_CELL_VERTICES: u64 = 256;

/// The file-wide facts that set a compressed array's layout.
struct Layout {
    compressed: bool,
    header_bytes: usize,
    big_endian: bool,
}

/// Bytes of the base64 text that encodes `n` bytes.
fn b64_len(n: u64) -> Option<u64> {
    n.div_ceil(3).checked_mul(4)
}

fn read_uint(bytes: &[u8], layout: &Layout) -> u64 {
    let mut v = 0u64;
    if layout.big_endian {
        for &b in bytes {
            v = (v << 8) | u64::from(b);
        }
    } else {
        for &b in bytes.iter().rev() {
            v = (v << 8) | u64::from(b);
        }
    }
    v
}

/// Bytes the reader will allocate for one compressed array whose base64
/// text is `text`, or why its header cannot be trusted.
fn array_bytes(text: &[u8], layout: &Layout) -> Result<u64, String> {
    let engine = base64::engine::general_purpose::STANDARD;
    let isz = layout.header_bytes as u64;
    let decode = |n: u64| -> Result<Vec<u8>, String> {
        let chars = b64_len(n).filter(|&c| c <= text.len() as u64).ok_or_else(|| {
            format!(
                "its compression header needs {n} bytes, more than the array's {} characters hold",
                text.len()
            )
        })?;
        engine
            .decode(&text[..chars as usize])
            .map_err(|e| format!("its compression header is not base64 ({e})"))
    };
    let first = decode(isz)?;
    let blocks = read_uint(&first[..layout.header_bytes], layout);
    if blocks == 0 {
        return Err("its compression header declares no block".into());
    }
    let full = blocks
        .checked_add(3)
        .and_then(|n| n.checked_mul(isz))
        .filter(|&n| b64_len(n).is_some_and(|c| c <= text.len() as u64))
        .ok_or_else(|| {
            format!(
                "its compression header declares {blocks} blocks, more than the array's {} characters hold",
                text.len()
            )
        })?;
    let header = decode(full)?;
    let field = |i: usize| {
        read_uint(
            &header[i * layout.header_bytes..][..layout.header_bytes],
            layout,
        )
    };
    let (block, last) = (field(1), field(2));
    let compressed = (0..blocks as usize)
        .try_fold(0u64, |sum, i| sum.checked_add(field(3 + i)))
        .ok_or("its compressed block sizes overflow")?;
    let needed = b64_len(full)
        .zip(b64_len(compressed))
        .and_then(|(h, d)| h.checked_add(d));
    if needed.is_none_or(|n| n > text.len() as u64) {
        return Err(format!(
            "its compression header declares {compressed} compressed bytes, more than the array's {} characters hold",
            text.len()
        ));
    }
    (blocks - 1)
        .checked_mul(block)
        .and_then(|n| n.checked_add(last))
        .ok_or_else(|| format!("its compression header declares {blocks} blocks of {block} bytes"))
}

/// Checks every compressed inline array of a VTK XML file before the reader
/// decompresses it: its header agrees with its text, what it will allocate
/// fits what its piece declares, and the file's total fits `budget` bytes.
/// The error is the line of the array and what is wrong.
pub fn check_compressed_arrays(bytes: &[u8], budget: u64) -> Result<(), (usize, String)> {
    let mut reader = quick_xml::Reader::from_reader(bytes);
    let line_at = |pos: u64| {
        let pos = (pos as usize).min(bytes.len());
        bytes[..pos].iter().filter(|&&b| b == b'\n').count() + 1
    };
    let mut layout = Layout {
        compressed: false,
        header_bytes: 4,
        big_endian: false,
    };
    let (mut points, mut cells) = (0u64, 0u64);
    // The enclosing element of the array being read, its bound and line.
    let mut section: Vec<u8> = Vec::new();
    let mut array: Option<(u64, usize)> = None;
    let mut total = 0u64;
    let mut buf = Vec::new();
    loop {
        let event = match reader.read_event_into(&mut buf) {
            Ok(event) => event,
            // Malformed XML is reported by the well-formedness check.
            Err(_) => return Ok(()),
        };
        match event {
            Event::Eof => return Ok(()),
            Event::Start(e) => {
                let attr = |key: &[u8]| {
                    e.attributes()
                        .flatten()
                        .find(|a| a.key.as_ref() == key)
                        .map(|a| a.value.into_owned())
                };
                let number = |key: &[u8]| {
                    attr(key)
                        .and_then(|v| std::str::from_utf8(&v).ok()?.trim().parse::<u64>().ok())
                        .unwrap_or(0)
                };
                match e.name().as_ref() {
                    b"VTKFile" => {
                        layout.compressed = attr(b"compressor").is_some_and(|c| !c.is_empty());
                        layout.header_bytes = match attr(b"header_type").as_deref() {
                            Some(b"UInt64") => 8,
                            _ => 4,
                        };
                        layout.big_endian = attr(b"byte_order").as_deref() == Some(b"BigEndian");
                    }
                    b"Piece" => {
                        points = number(b"NumberOfPoints");
                        cells = [
                            &b"NumberOfCells"[..],
                            b"NumberOfVerts",
                            b"NumberOfLines",
                            b"NumberOfStrips",
                            b"NumberOfPolys",
                        ]
                        .iter()
                        .map(|k| number(k))
                        .fold(0u64, u64::saturating_add);
                    }
                    b"DataArray" => {
                        let binary = attr(b"format").as_deref() == Some(b"binary");
                        if layout.compressed && binary {
                            let components = number(b"NumberOfComponents").max(1);
                            let element = attr(b"type").and_then(|t| type_bytes(&t)).unwrap_or(8);
                            let count = match section.as_slice() {
                                b"Points" | b"PointData" => points,
                                b"CellData" => cells,
                                _ => cells.saturating_mul(MAX_CELL_VERTICES),
                            };
                            let bound = count.saturating_mul(components).saturating_mul(element);
                            array = Some((bound, line_at(reader.buffer_position())));
                        }
                    }
                    other => section = other.to_vec(),
                }
            }
            Event::Text(text) => {
                if let Some((bound, line)) = array.take() {
                    let text: Vec<u8> = text
                        .iter()
                        .copied()
                        .filter(|b| !b.is_ascii_whitespace())
                        .collect();
                    let size = array_bytes(&text, &layout)
                        .map_err(|why| (line, format!("a compressed data array: {why}")))?;
                    if size > bound {
                        return Err((
                            line,
                            format!(
                                "a compressed data array in <{}> declares {size} bytes \
                                 uncompressed, more than its piece's {points} points and \
                                 {cells} cells can need ({bound} bytes)",
                                String::from_utf8_lossy(&section)
                            ),
                        ));
                    }
                    total = total.saturating_add(size);
                    if total > budget {
                        return Err((
                            line,
                            format!(
                                "the compressed data arrays declare {total} bytes uncompressed, \
                                 more than the {budget} bytes allowed for reading a mesh"
                            ),
                        ));
                    }
                }
            }
            Event::End(e) => {
                if e.name().as_ref() == b"DataArray" {
                    array = None;
                } else if e.name().as_ref() == section.as_slice() {
                    section.clear();
                }
            }
            _ => {}
        }
        buf.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A compressed inline array's text: the header (32-bit, little
    /// endian) and the blocks, base64 each.
    fn array_text(blocks: u32, block: u32, last: u32, sizes: &[u32], data: &[u8]) -> String {
        let engine = base64::engine::general_purpose::STANDARD;
        let mut header = Vec::new();
        for v in [blocks, block, last].iter().chain(sizes) {
            header.extend_from_slice(&v.to_le_bytes());
        }
        format!("{}{}", engine.encode(header), engine.encode(data))
    }

    fn file(points: u64, text: &str) -> Vec<u8> {
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" \
             byte_order=\"LittleEndian\" header_type=\"UInt32\" compressor=\"vtkZLibDataCompressor\">\n\
             <PolyData>\n<Piece NumberOfPoints=\"{points}\" NumberOfPolys=\"1\">\n<Points>\n\
             <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"binary\">\n{text}\n\
             </DataArray>\n</Points>\n</Piece>\n</PolyData>\n</VTKFile>\n"
        )
        .into_bytes()
    }

    #[test]
    fn honest_headers_pass_and_lying_ones_are_refused_with_their_line() {
        // 3 points of 3 Float64: 72 bytes, one block of 10 compressed bytes.
        let ok = file(3, &array_text(1, 72, 72, &[10], &[0; 10]));
        assert_eq!(check_compressed_arrays(&ok, 1 << 20), Ok(()));
        // A gigabyte for three points.
        let big = file(
            3,
            &array_text(1 << 10, 1 << 20, 1 << 20, &[1; 1024], &[0; 1024]),
        );
        let (line, why) = check_compressed_arrays(&big, u64::MAX).unwrap_err();
        assert_eq!(line, 6);
        assert!(why.contains("more than its piece's 3 points"), "{why}");
        // Within the piece, over the budget.
        let (_, why) = check_compressed_arrays(&ok, 10).unwrap_err();
        assert!(why.contains("more than the 10 bytes allowed"), "{why}");
        // Blocks past the end of the text: the reader would slice past it.
        let short = file(3, &array_text(1, 72, 72, &[1_000_000], &[0; 10]));
        let (_, why) = check_compressed_arrays(&short, 1 << 20).unwrap_err();
        assert!(why.contains("1000000 compressed bytes"), "{why}");
        // More blocks than the header has room for.
        let many = file(3, &array_text(u32::MAX, 72, 72, &[], &[]));
        let (_, why) = check_compressed_arrays(&many, 1 << 20).unwrap_err();
        assert!(why.contains("4294967295 blocks"), "{why}");
        let none = file(3, &array_text(0, 72, 72, &[], &[]));
        assert!(check_compressed_arrays(&none, 1 << 20).is_err());
        let garbage = file(3, "!!!!not base64!!!!");
        assert!(check_compressed_arrays(&garbage, 1 << 20).is_err());
    }
}
