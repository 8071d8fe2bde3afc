//! NIfTI-1 (348-byte header) and NIfTI-2 (540-byte header), either byte
//! order (told by the header size field), single file (`n+1`, `n+2`) or a
//! header with an `.img` beside it (`ni1`, `ni2`), gzip-compressed or not.
//!
//! The world transform follows the standard's order of preference: the
//! sform when `sform_code > 0`, else the qform (quaternion, pixel sizes
//! and `qfac`) when `qform_code > 0`, else the pixel sizes alone with the
//! origin at voxel (0, 0, 0) (the standard's "method 1").

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;

use super::{
    ImageError, ImageFormat, ImageLimits, LabelImage, Space, VoxelLayout, VoxelType, io_error,
    is_gzip, skip_bytes,
};

const V1_LEN: usize = 348;
const V2_LEN: usize = 540;

impl Header {
    fn into_image(self, labels: Vec<i32>, name: &str) -> Result<LabelImage, ImageError> {
        let h = self;
        LabelImage::from_reader(
            h.layout.dims,
            labels,
            h.affine,
            h.unit_metres,
            h.space,
            ImageFormat::Nifti,
            name,
        )
    }
}

struct Header {
    layout: VoxelLayout,
    affine: [[f64; 4]; 3],
    unit_metres: Option<f64>,
    space: Space,
    vox_offset: u64,
    /// The data lives in a separate `.img` file.
    pair: bool,
    len: usize,
}

/// Reads `len` bytes of header, or says how far the file got.
fn read_header_bytes(reader: &mut dyn Read, name: &str) -> Result<(Vec<u8>, usize), ImageError> {
    let mut buf = vec![0u8; V2_LEN];
    let got = read_up_to(reader, &mut buf[..4], name)?;
    if got < 4 {
        return Err(truncated_header(name, V1_LEN, got));
    }
    let size = header_size(&buf[..4]).ok_or_else(|| ImageError::BadField {
        path: name.to_owned(),
        field: "sizeof_hdr".into(),
        value: format!(
            "{}",
            i32::from_le_bytes(buf[..4].try_into().expect("4 bytes"))
        ),
        why: "is neither 348 (NIfTI-1) nor 540 (NIfTI-2) in either byte order: not a NIfTI file"
            .into(),
    })?;
    let got = 4 + read_up_to(reader, &mut buf[4..size], name)?;
    if got < size {
        return Err(truncated_header(name, size, got));
    }
    buf.truncate(size);
    Ok((buf, size))
}

fn truncated_header(name: &str, needed: usize, got: usize) -> ImageError {
    ImageError::Truncated {
        path: name.to_owned(),
        what: "header",
        needed: needed as u64,
        got: got as u64,
    }
}

fn header_size(b: &[u8]) -> Option<usize> {
    let raw: [u8; 4] = b.try_into().ok()?;
    [i32::from_le_bytes(raw), i32::from_be_bytes(raw)]
        .into_iter()
        .find_map(|v| match v {
            348 => Some(V1_LEN),
            540 => Some(V2_LEN),
            _ => None,
        })
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
fn read_up_to(reader: &mut dyn Read, buf: &mut [u8], name: &str) -> Result<usize, ImageError> {
    let mut n = 0;
    while n < buf.len() {
        match reader.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                return Err(ImageError::Decompress {
                    path: name.to_owned(),
                    message: e.to_string(),
                });
            }
        }
    }
    Ok(n)
}

/// Field reader in the header's byte order.
struct Fields<'a> {
    b: &'a [u8],
    big: bool,
}

impl Fields<'_> {
    fn bytes<const N: usize>(&self, at: usize) -> [u8; N] {
        self.b[at..at + N]
            .try_into()
            .expect("header field within the header")
    }
    fn i16(&self, at: usize) -> i64 {
        let r = self.bytes::<2>(at);
        (if self.big {
            i16::from_be_bytes(r)
        } else {
            i16::from_le_bytes(r)
        }) as i64
    }
    fn i32(&self, at: usize) -> i64 {
        let r = self.bytes::<4>(at);
        (if self.big {
            i32::from_be_bytes(r)
        } else {
            i32::from_le_bytes(r)
        }) as i64
    }
    fn i64(&self, at: usize) -> i64 {
        let r = self.bytes::<8>(at);
        if self.big {
            i64::from_be_bytes(r)
        } else {
            i64::from_le_bytes(r)
        }
    }
    fn f32(&self, at: usize) -> f64 {
        let r = self.bytes::<4>(at);
        (if self.big {
            f32::from_be_bytes(r)
        } else {
            f32::from_le_bytes(r)
        }) as f64
    }
    fn f64(&self, at: usize) -> f64 {
        let r = self.bytes::<8>(at);
        if self.big {
            f64::from_be_bytes(r)
        } else {
            f64::from_le_bytes(r)
        }
    }
}

/// Offsets of the fields both versions have, and how wide they are.
struct Offsets {
    datatype: usize,
    dim: usize,
    pixdim: usize,
    vox_offset: usize,
    scl_slope: usize,
    scl_inter: usize,
    qform_code: usize,
    sform_code: usize,
    quatern: usize,
    srow: usize,
    xyzt_units: usize,
    /// Whether dimensions, sizes and transforms are 64-bit (NIfTI-2) rather
    /// than 16-bit integers and 32-bit floats (NIfTI-1).
    wide: bool,
}

const V1: Offsets = Offsets {
    datatype: 70,
    dim: 40,
    pixdim: 76,
    vox_offset: 108,
    scl_slope: 112,
    scl_inter: 116,
    qform_code: 252,
    sform_code: 254,
    quatern: 256,
    srow: 280,
    xyzt_units: 123,
    wide: false,
};

const V2: Offsets = Offsets {
    datatype: 12,
    dim: 16,
    pixdim: 104,
    vox_offset: 168,
    scl_slope: 176,
    scl_inter: 184,
    qform_code: 344,
    sform_code: 348,
    quatern: 352,
    srow: 400,
    xyzt_units: 500,
    wide: true,
};

fn parse_header(b: &[u8], name: &str) -> Result<Header, ImageError> {
    let len = b.len();
    let big = i32::from_le_bytes(b[..4].try_into().expect("4 bytes")) != len as i32;
    let f = Fields { b, big };
    let bad = |field: &str, value: String, why: &str| ImageError::BadField {
        path: name.to_owned(),
        field: field.to_owned(),
        value,
        why: why.to_owned(),
    };
    let (o, pair) = if len == V1_LEN {
        let magic = &b[344..348];
        let pair = match magic {
            b"n+1\0" => false,
            b"ni1\0" => true,
            _ => {
                return Err(bad(
                    "magic",
                    format!("{:?}", String::from_utf8_lossy(magic)),
                    "is not \"n+1\" or \"ni1\": an Analyze 7.5 file or not a NIfTI-1 file",
                ));
            }
        };
        (V1, pair)
    } else {
        let magic = &b[4..12];
        let pair = match magic {
            b"n+2\0\r\n\x1a\n" => false,
            b"ni2\0\r\n\x1a\n" => true,
            _ => {
                return Err(bad(
                    "magic",
                    format!("{:?}", String::from_utf8_lossy(magic)),
                    "is not \"n+2\" or \"ni2\" followed by the check bytes: not a NIfTI-2 file",
                ));
            }
        };
        (V2, pair)
    };
    let int = |at: usize, i: usize| {
        if o.wide {
            f.i64(at + 8 * i)
        } else {
            f.i16(at + 2 * i)
        }
    };
    let float = |at: usize, i: usize| {
        if o.wide {
            f.f64(at + 8 * i)
        } else {
            f.f32(at + 4 * i)
        }
    };
    let code = |at: usize| if o.wide { f.i32(at) } else { f.i16(at) };

    let ndim = int(o.dim, 0);
    if !(1..=7).contains(&ndim) {
        return Err(bad(
            "dim[0]",
            ndim.to_string(),
            "must be 1 to 7 (the number of dimensions)",
        ));
    }
    let mut dims = [1usize; 3];
    for i in 1..=ndim as usize {
        let d = int(o.dim, i);
        if d < 1 {
            return Err(bad(
                &format!("dim[{i}]"),
                d.to_string(),
                "every dimension needs at least one voxel",
            ));
        }
        if i <= 3 {
            dims[i - 1] = usize::try_from(d).map_err(|_| {
                bad(
                    &format!("dim[{i}]"),
                    d.to_string(),
                    "is too large for this machine",
                )
            })?;
        } else if d > 1 {
            return Err(bad(
                &format!("dim[{i}]"),
                d.to_string(),
                "a label image has 3 dimensions; this one has more than one volume (split it, \
                 or pick the volume to segment)",
            ));
        }
    }
    // A 16-bit field in both versions.
    let datatype = f.i16(o.datatype);
    let kind = match datatype {
        2 => VoxelType::U8,
        4 => VoxelType::I16,
        8 => VoxelType::I32,
        16 => VoxelType::F32,
        64 => VoxelType::F64,
        256 => VoxelType::I8,
        512 => VoxelType::U16,
        768 => VoxelType::U32,
        1024 => VoxelType::I64,
        1280 => VoxelType::U64,
        other => {
            return Err(bad(
                "datatype",
                other.to_string(),
                "is not an integer or real type (labels are stored as uint8, int8, int16, \
                 uint16, int32, uint32, int64, uint64, float32 or float64)",
            ));
        }
    };
    let (slope, intercept) = {
        let s = float(o.scl_slope, 0);
        let i = float(o.scl_inter, 0);
        if s == 0.0 || !s.is_finite() {
            (1.0, 0.0)
        } else {
            (s, if i.is_finite() { i } else { 0.0 })
        }
    };
    let vox_offset_raw = if o.wide {
        f.i64(o.vox_offset) as f64
    } else {
        f.f32(o.vox_offset)
    };
    if !(0.0..1e15).contains(&vox_offset_raw) || (!pair && vox_offset_raw < len as f64) {
        return Err(bad(
            "vox_offset",
            vox_offset_raw.to_string(),
            &format!(
                "must be a byte offset at or after the {len}-byte header (0 or more for a header \
                 with a separate .img)"
            ),
        ));
    }
    let vox_offset = vox_offset_raw as u64;
    let pixdim: [f64; 4] = std::array::from_fn(|i| float(o.pixdim, i));
    let spacing_checked = |axis: usize| -> Result<f64, ImageError> {
        let p = pixdim[axis];
        if p.is_finite() && p > 0.0 {
            Ok(p)
        } else if p.is_finite() && p < 0.0 {
            // Some writers store a negative size; the standard's readers use
            // its magnitude.
            Ok(-p)
        } else {
            Err(bad(
                &format!("pixdim[{axis}]"),
                p.to_string(),
                "the voxel spacing must be a positive finite number",
            ))
        }
    };
    let sform_code = code(o.sform_code);
    let qform_code = code(o.qform_code);
    let affine = if sform_code > 0 {
        std::array::from_fn(|r| std::array::from_fn(|c| float(o.srow, 4 * r + c)))
    } else if qform_code > 0 {
        let [qb, qc, qd] = [0, 1, 2].map(|i| float(o.quatern, i));
        let offset = [3, 4, 5].map(|i| float(o.quatern, i));
        let qa = (1.0 - (qb * qb + qc * qc + qd * qd)).max(0.0).sqrt();
        let r = [
            [
                qa * qa + qb * qb - qc * qc - qd * qd,
                2.0 * (qb * qc - qa * qd),
                2.0 * (qb * qd + qa * qc),
            ],
            [
                2.0 * (qb * qc + qa * qd),
                qa * qa + qc * qc - qb * qb - qd * qd,
                2.0 * (qc * qd - qa * qb),
            ],
            [
                2.0 * (qb * qd - qa * qc),
                2.0 * (qc * qd + qa * qb),
                qa * qa + qd * qd - qb * qb - qc * qc,
            ],
        ];
        let qfac = if pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let s = [
            spacing_checked(1)?,
            spacing_checked(2)?,
            qfac * spacing_checked(3)?,
        ];
        std::array::from_fn(|row| {
            [
                r[row][0] * s[0],
                r[row][1] * s[1],
                r[row][2] * s[2],
                offset[row],
            ]
        })
    } else {
        let s = [
            spacing_checked(1)?,
            spacing_checked(2)?,
            spacing_checked(3)?,
        ];
        std::array::from_fn(|row| {
            let mut line = [0.0; 4];
            line[row] = s[row];
            line
        })
    };
    let units_code = if o.wide {
        f.i32(o.xyzt_units)
    } else {
        b[o.xyzt_units] as i64
    };
    let unit_metres = match units_code & 0x07 {
        1 => Some(1.0),
        2 => Some(1e-3),
        3 => Some(1e-6),
        _ => None,
    };
    let space = if sform_code > 0 || qform_code > 0 {
        Space::Ras
    } else {
        Space::Other("voxel grid".into())
    };
    Ok(Header {
        layout: VoxelLayout {
            dims,
            kind,
            big_endian: big,
            slope,
            intercept,
        },
        affine,
        unit_metres,
        space,
        vox_offset,
        pair,
        len,
    })
}

pub(super) fn read_bytes(
    bytes: &[u8],
    name: &str,
    limits: &ImageLimits,
) -> Result<LabelImage, ImageError> {
    let compressed = is_gzip(bytes);
    let mut reader: Box<dyn Read + '_> = if compressed {
        Box::new(MultiGzDecoder::new(bytes))
    } else {
        Box::new(bytes)
    };
    let (raw, _) = read_header_bytes(&mut reader, name)?;
    let header = parse_header(&raw, name)?;
    if header.pair {
        return Err(ImageError::BadField {
            path: name.to_owned(),
            field: "magic".into(),
            value: "a header with a separate .img".into(),
            why: "the data is in another file: read it from its path".into(),
        });
    }
    header.layout.check_memory(name, limits)?;
    if !compressed
        && (bytes.len() as u64) < header.vox_offset.saturating_add(header.layout.data_bytes())
    {
        return Err(ImageError::Truncated {
            path: name.to_owned(),
            what: "voxel data",
            needed: header.layout.data_bytes(),
            got: (bytes.len() as u64).saturating_sub(header.vox_offset),
        });
    }
    skip_bytes(
        &mut reader,
        header.vox_offset - header.len as u64,
        "header extensions",
        name,
    )?;
    let labels = header.layout.read_labels(&mut reader, name, compressed)?;
    header.into_image(labels, name)
}

/// Opens `path`, gunzipping it if it is compressed. Returns the reader and
/// the file's length when it is not compressed.
fn open(path: &Path, name: &str) -> Result<(Box<dyn Read>, Option<u64>), ImageError> {
    let mut file = File::open(path).map_err(io_error(name))?;
    let len = file.metadata().map_err(io_error(name))?.len();
    let mut magic = [0u8; 2];
    let got = read_up_to(&mut file, &mut magic, name)?;
    file.seek(SeekFrom::Start(0)).map_err(io_error(name))?;
    let buffered = BufReader::new(file);
    if got == 2 && is_gzip(&magic) {
        Ok((Box::new(MultiGzDecoder::new(buffered)), None))
    } else {
        Ok((Box::new(buffered), Some(len)))
    }
}

/// The `.img` (or `.img.gz`) beside a `.hdr`.
fn image_file_of(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?.to_string_lossy().into_owned();
    let lower = name.to_ascii_lowercase();
    let stem_len = lower.rfind(".hdr")?;
    let stem = &name[..stem_len];
    ["img", "IMG", "img.gz", "IMG.gz"]
        .iter()
        .map(|ext| path.with_file_name(format!("{stem}.{ext}")))
        .find(|p| p.exists())
}

pub(super) fn read_file(
    path: &Path,
    name: &str,
    limits: &ImageLimits,
) -> Result<LabelImage, ImageError> {
    let (mut reader, len) = open(path, name)?;
    let (raw, _) = read_header_bytes(&mut reader, name)?;
    let header = parse_header(&raw, name)?;
    header.layout.check_memory(name, limits)?;
    let (mut data, data_len, data_name, skip) = if header.pair {
        let img = image_file_of(path).ok_or_else(|| ImageError::Io {
            path: name.to_owned(),
            source: std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "the header's .img file is not beside it",
            ),
        })?;
        let img_name = img.display().to_string();
        let (reader, len) = open(&img, &img_name)?;
        (reader, len, img_name, header.vox_offset)
    } else {
        (
            reader,
            len,
            name.to_owned(),
            header.vox_offset - header.len as u64,
        )
    };
    if let Some(len) = data_len {
        let start = header.vox_offset;
        if len < start.saturating_add(header.layout.data_bytes()) {
            return Err(ImageError::Truncated {
                path: data_name,
                what: "voxel data",
                needed: header.layout.data_bytes(),
                got: len.saturating_sub(start),
            });
        }
    }
    skip_bytes(&mut data, skip, "bytes before the data", &data_name)?;
    let labels = header
        .layout
        .read_labels(&mut data, &data_name, data_len.is_none())?;
    header.into_image(labels, name)
}
