//! NRRD (`NRRD0001` to `NRRD0005`): a text header, then the data attached
//! after a blank line (`.nrrd`) or in the file a `.nhdr` names (`data file`),
//! encoded `raw`, `gzip` or `ascii`, in either byte order.
//!
//! The world transform is `space origin + sum_a index_a * direction_a` over
//! the spatial axes (`space directions`, `none` marking an axis that is not
//! spatial, which must then hold one sample); without directions, the
//! `spacings` (default 1) along the coordinate axes from the origin.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use flate2::read::MultiGzDecoder;

use super::{
    ImageError, ImageFormat, ImageLimits, LabelImage, Space, VoxelLayout, VoxelType, skip_bytes,
};

/// Longest header read (bytes): headers are a few hundred bytes; past this
/// the file is not a NRRD header.
const MAX_HEADER_BYTES: u64 = 1 << 20;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Raw,
    Gzip,
    Ascii,
}

impl Header {
    fn into_image(self, labels: Vec<i32>, name: &str) -> Result<LabelImage, ImageError> {
        let h = self;
        LabelImage::from_reader(
            h.layout.dims,
            labels,
            h.affine,
            h.unit_metres,
            h.space,
            ImageFormat::Nrrd,
            name,
        )
    }
}

struct Header {
    layout: VoxelLayout,
    affine: [[f64; 4]; 3],
    unit_metres: Option<f64>,
    space: Space,
    encoding: Encoding,
    data_file: Option<String>,
    line_skip: u64,
    byte_skip: i64,
}

/// Reads header lines up to the blank line (or the end), with the line
/// number of each, and the number of bytes they took with the blank line.
fn header_lines(
    reader: &mut dyn BufRead,
    name: &str,
) -> Result<(Vec<(usize, String)>, u64), ImageError> {
    let mut lines = Vec::new();
    let mut consumed = 0u64;
    let mut buf = Vec::new();
    loop {
        buf.clear();
        let n = reader
            .take(MAX_HEADER_BYTES - consumed)
            .read_until(b'\n', &mut buf)
            .map_err(super::io_error(name))?;
        if n == 0 {
            if consumed >= MAX_HEADER_BYTES {
                return Err(ImageError::BadLine {
                    path: name.to_owned(),
                    line: lines.len() + 1,
                    message: format!(
                        "no blank line ends the header within {MAX_HEADER_BYTES} bytes: not a NRRD header"
                    ),
                });
            }
            break;
        }
        consumed += n as u64;
        let text = String::from_utf8_lossy(&buf);
        let line = text.trim_end_matches(['\n', '\r']).to_owned();
        if line.is_empty() && !lines.is_empty() {
            break;
        }
        lines.push((lines.len() + 1, line));
    }
    Ok((lines, consumed))
}

fn parse_header(lines: &[(usize, String)], name: &str) -> Result<Header, ImageError> {
    let bad_line = |line: usize, message: String| ImageError::BadLine {
        path: name.to_owned(),
        line,
        message,
    };
    match lines.first() {
        Some((_, magic))
            if magic.len() == 8
                && magic.starts_with("NRRD000")
                && matches!(magic.as_bytes()[7], b'1'..=b'5') => {}
        Some((_, magic)) => {
            return Err(bad_line(
                1,
                format!(
                    "starts with {:?}, not NRRD0001 to NRRD0005: not a NRRD file",
                    magic.chars().take(16).collect::<String>()
                ),
            ));
        }
        None => return Err(bad_line(1, "the file is empty".into())),
    }
    let mut fields: Vec<(usize, String, String)> = Vec::new();
    for (no, line) in &lines[1..] {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        if let Some((key, _)) = line.split_once(":=")
            && !key.contains(": ")
        {
            continue; // a key/value pair, not a field
        }
        let Some((field, value)) = line.split_once(": ") else {
            return Err(bad_line(*no, format!("{line:?} is not \"field: value\"")));
        };
        let field = field.trim().to_ascii_lowercase();
        if fields.iter().any(|(_, f, _)| *f == field) {
            return Err(bad_line(
                *no,
                format!("the field \"{field}\" is given twice"),
            ));
        }
        fields.push((*no, field, value.trim().to_owned()));
    }
    let get = |names: &[&str]| {
        fields
            .iter()
            .find(|(_, f, _)| names.contains(&f.as_str()))
            .map(|(no, _, v)| (*no, v.as_str()))
    };
    let bad = |field: &str, value: &str, why: &str| ImageError::BadField {
        path: name.to_owned(),
        field: field.to_owned(),
        value: value.to_owned(),
        why: why.to_owned(),
    };
    let required = |field: &str| {
        get(&[field]).ok_or_else(|| bad(field, "(missing)", "a NRRD header must give it"))
    };

    let (_, type_name) = required("type")?;
    let kind = match type_name.to_ascii_lowercase().as_str() {
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => VoxelType::U8,
        "signed char" | "int8" | "int8_t" => VoxelType::I8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            VoxelType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            VoxelType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => VoxelType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => VoxelType::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => VoxelType::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            VoxelType::U64
        }
        "float" => VoxelType::F32,
        "double" => VoxelType::F64,
        _ => {
            return Err(bad(
                "type",
                type_name,
                "is not a type label images use (uchar, short, ushort, int, uint, ... float, double)",
            ));
        }
    };
    let (_, dimension) = required("dimension")?;
    let ndim: usize = match dimension.parse() {
        Ok(n @ 1..=16) => n,
        _ => {
            return Err(bad(
                "dimension",
                dimension,
                "must be a whole number from 1 to 16",
            ));
        }
    };
    let (_, sizes_text) = required("sizes")?;
    let sizes: Vec<u64> = sizes_text
        .split_whitespace()
        .map(|s| s.parse::<u64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad("sizes", sizes_text, "must be whole numbers"))?;
    if sizes.len() != ndim {
        return Err(bad(
            "sizes",
            sizes_text,
            &format!("gives {} sizes for a dimension of {ndim}", sizes.len()),
        ));
    }
    if sizes.contains(&0) {
        return Err(bad(
            "sizes",
            sizes_text,
            "every axis needs at least one sample",
        ));
    }

    // Which axes are spatial, and their direction vectors.
    let space_text = get(&["space"]).map(|(_, v)| v);
    let space_dim_text = get(&["space dimension"]).map(|(_, v)| v);
    let space_dim = match (space_text, space_dim_text) {
        (Some(s), _) => match s.to_ascii_lowercase().as_str() {
            "right-anterior-superior"
            | "ras"
            | "left-anterior-superior"
            | "las"
            | "left-posterior-superior"
            | "lps"
            | "scanner-xyz"
            | "3d-right-handed"
            | "3d-left-handed" => 3,
            _ => {
                return Err(bad(
                    "space",
                    s,
                    "is not a 3D space (a label volume needs one: left-posterior-superior, \
                     right-anterior-superior, scanner-xyz, 3D-right-handed, ...)",
                ));
            }
        },
        (None, Some(d)) => match d.parse::<usize>() {
            // A 2D image (a slice for a 2D body) lies in the plane z = 0.
            Ok(n @ (2 | 3)) => n,
            _ => {
                return Err(bad(
                    "space dimension",
                    d,
                    "must be 3 for a label volume (2 for a slice)",
                ));
            }
        },
        (None, None) => 0,
    };
    let space = match space_text.map(|s| s.to_ascii_lowercase()) {
        Some(s) if s == "right-anterior-superior" || s == "ras" => Space::Ras,
        Some(s) if s == "left-posterior-superior" || s == "lps" => Space::Lps,
        Some(s) => Space::Other(s),
        None => Space::Other(String::new()),
    };
    let mut directions: Vec<Option<[f64; 3]>> = vec![None; ndim];
    let mut spatial = vec![ndim <= 3; ndim];
    if let Some((_, text)) = get(&["space directions"]) {
        if space_dim < 2 {
            return Err(bad(
                "space directions",
                text,
                "needs a 3D \"space\" or \"space dimension: 3\" (or 2)",
            ));
        }
        let items = split_vectors(text).ok_or_else(|| {
            bad(
                "space directions",
                text,
                "must be one \"(x,y,z)\" or \"none\" per axis",
            )
        })?;
        if items.len() != ndim {
            return Err(bad(
                "space directions",
                text,
                &format!("gives {} directions for {ndim} axes", items.len()),
            ));
        }
        for (a, item) in items.iter().enumerate() {
            match item {
                None => spatial[a] = false,
                Some(v) if v.len() == space_dim && v.iter().all(|c| c.is_finite()) => {
                    spatial[a] = true;
                    directions[a] = Some([v[0], v[1], v.get(2).copied().unwrap_or(0.0)]);
                }
                Some(_) => {
                    return Err(bad(
                        "space directions",
                        text,
                        &format!("each direction needs {space_dim} finite components"),
                    ));
                }
            }
        }
    } else if ndim > 3 {
        return Err(bad(
            "dimension",
            dimension,
            "a label volume has 3 spatial axes; give \"space directions\" with \"none\" for the others",
        ));
    }
    let spatial_axes: Vec<usize> = (0..ndim).filter(|&a| spatial[a]).collect();
    if spatial_axes.len() > 3 {
        return Err(bad(
            "space directions",
            get(&["space directions"]).map_or("", |(_, v)| v),
            "names more than 3 spatial axes",
        ));
    }
    if let Some(a) = (0..ndim).find(|&a| !spatial[a] && sizes[a] > 1) {
        return Err(bad(
            "sizes",
            sizes_text,
            &format!(
                "axis {a} is not spatial but holds {} samples: a label volume has one label per \
                 voxel (a segmentation with overlapping layers must be flattened first)",
                sizes[a]
            ),
        ));
    }
    let mut dims = [1usize; 3];
    for (slot, &a) in spatial_axes.iter().enumerate() {
        dims[slot] = usize::try_from(sizes[a])
            .map_err(|_| bad("sizes", sizes_text, "is too large for this machine"))?;
    }
    let mut linear = [[0.0f64; 3]; 3]; // columns: the spatial axes
    let have_directions = directions.iter().any(Option::is_some);
    if have_directions {
        for (slot, &a) in spatial_axes.iter().enumerate() {
            let d = directions[a].expect("a spatial axis has a direction");
            for r in 0..3 {
                linear[r][slot] = d[r];
            }
        }
    } else {
        let spacings: Vec<f64> = match get(&["spacings"]) {
            Some((_, text)) => {
                let v: Vec<f64> = text
                    .split_whitespace()
                    .map(|s| s.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad("spacings", text, "must be numbers"))?;
                if v.len() != ndim {
                    return Err(bad(
                        "spacings",
                        text,
                        &format!("gives {} spacings for {ndim} axes", v.len()),
                    ));
                }
                for &a in &spatial_axes {
                    if !(v[a].is_finite() && v[a] != 0.0) {
                        return Err(bad(
                            "spacings",
                            text,
                            "the spacing of every spatial axis must be a non-zero finite number",
                        ));
                    }
                }
                v
            }
            None => vec![1.0; ndim],
        };
        for (slot, &a) in spatial_axes.iter().enumerate() {
            linear[slot][slot] = spacings[a];
        }
    }
    if spatial_axes.len() < 3 {
        // A slice (or a line): the missing axes span one voxel across it,
        // as thick as the mean of the others' spacings, so that the map
        // stays invertible; a 2D body takes the slice's own plane.
        let column = |c: usize| [linear[0][c], linear[1][c], linear[2][c]];
        let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let (u, v) = (column(0), column(1));
        let across = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        if spatial_axes.len() == 2 && norm(across) > 0.0 {
            let thick = 0.5 * (norm(u) + norm(v)) / norm(across);
            for r in 0..3 {
                linear[r][2] = across[r] * thick;
            }
        }
    }
    let origin = match get(&["space origin"]) {
        Some((_, text)) => {
            let v = split_vectors(text)
                .filter(|v| v.len() == 1)
                .and_then(|v| v.into_iter().next().flatten())
                .filter(|v| {
                    v.len() == if space_dim == 2 { 2 } else { 3 }
                        && v.iter().all(|c| c.is_finite())
                })
                .ok_or_else(|| {
                    bad(
                        "space origin",
                        text,
                        "must be one \"(x,y,z)\" of finite numbers (\"(x,y)\" with space dimension 2)",
                    )
                })?;
            [v[0], v[1], v.get(2).copied().unwrap_or(0.0)]
        }
        None => [0.0; 3],
    };
    let affine = std::array::from_fn(|r| [linear[r][0], linear[r][1], linear[r][2], origin[r]]);

    let encoding = match get(&["encoding"]) {
        Some((_, e)) => match e.to_ascii_lowercase().as_str() {
            "raw" => Encoding::Raw,
            "gzip" | "gz" => Encoding::Gzip,
            "ascii" | "text" | "txt" => Encoding::Ascii,
            _ => {
                return Err(bad(
                    "encoding",
                    e,
                    "is not read here (use raw, gzip or ascii)",
                ));
            }
        },
        None => return Err(bad("encoding", "(missing)", "a NRRD header must give it")),
    };
    let big_endian = match get(&["endian"]) {
        Some((_, e)) => match e.to_ascii_lowercase().as_str() {
            "little" => false,
            "big" => true,
            _ => return Err(bad("endian", e, "must be little or big")),
        },
        None => false,
    };
    let unit_metres = match get(&["space units"]) {
        Some((_, text)) => {
            let units: Vec<String> = text
                .split('"')
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(str::to_ascii_lowercase)
                .collect();
            let factor = |u: &str| match u {
                "m" | "meter" | "metre" | "meters" | "metres" => Some(1.0),
                "cm" => Some(1e-2),
                "mm" => Some(1e-3),
                "um" | "µm" | "micron" | "microns" => Some(1e-6),
                _ => None,
            };
            let factors: Vec<Option<f64>> = units.iter().map(|u| factor(u)).collect();
            match factors.first() {
                Some(&Some(f)) if factors.iter().all(|&g| g == Some(f)) => Some(f),
                _ => {
                    return Err(bad(
                        "space units",
                        text,
                        "must name one length unit for every axis (\"mm\" \"mm\" \"mm\")",
                    ));
                }
            }
        }
        None => None,
    };
    let data_file = get(&["data file", "datafile"]).map(|(_, v)| v.to_owned());
    if let Some(f) = &data_file
        && (f.starts_with("LIST") || f.split_whitespace().count() > 1)
    {
        return Err(bad(
            "data file",
            f,
            "names several files; one data file is read here",
        ));
    }
    let skip_field = |names: &[&str], field: &str| -> Result<i64, ImageError> {
        match get(names) {
            Some((_, v)) => v
                .parse::<i64>()
                .ok()
                .filter(|&n| n >= -1)
                .ok_or_else(|| bad(field, v, "must be a whole number (-1 or more)")),
            None => Ok(0),
        }
    };
    let line_skip = skip_field(&["line skip", "lineskip"], "line skip")?;
    if line_skip < 0 {
        return Err(bad("line skip", "-1", "must be 0 or more"));
    }
    let byte_skip = skip_field(&["byte skip", "byteskip"], "byte skip")?;
    if byte_skip == -1 && encoding != Encoding::Raw {
        return Err(bad(
            "byte skip",
            "-1",
            "means \"the data ends the file\", which only raw encoding allows",
        ));
    }
    Ok(Header {
        layout: VoxelLayout {
            dims,
            kind,
            big_endian,
            slope: 1.0,
            intercept: 0.0,
        },
        affine,
        unit_metres,
        space,
        encoding,
        data_file,
        line_skip: line_skip as u64,
        byte_skip,
    })
}

/// `(1,0,0) none (0,2,0)` to vectors (`None` for `none`).
fn split_vectors(text: &str) -> Option<Vec<Option<Vec<f64>>>> {
    let mut out = Vec::new();
    let mut rest = text.trim();
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("none") {
            out.push(None);
            rest = after.trim_start();
            continue;
        }
        let inner = rest.strip_prefix('(')?;
        let close = inner.find(')')?;
        let v: Vec<f64> = inner[..close]
            .split(',')
            .map(|c| c.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .ok()?;
        out.push(Some(v));
        rest = inner[close + 1..].trim_start();
    }
    Some(out)
}

/// Reads the voxels from `reader`, positioned at the data's first byte
/// (before line and byte skips); `len` is what is left of it when known
/// (an attached or detached file, not a stream).
fn read_data(
    header: &Header,
    mut reader: Box<dyn BufRead + '_>,
    len: Option<u64>,
    name: &str,
) -> Result<Vec<i32>, ImageError> {
    let mut consumed = 0u64;
    for _ in 0..header.line_skip {
        let mut line = Vec::new();
        let n = reader
            .read_until(b'\n', &mut line)
            .map_err(super::io_error(name))?;
        if n == 0 {
            return Err(ImageError::Truncated {
                path: name.to_owned(),
                what: "lines to skip",
                needed: header.line_skip,
                got: consumed,
            });
        }
        consumed += n as u64;
    }
    let left = len.map(|l| l.saturating_sub(consumed));
    let data_bytes = header.layout.data_bytes();
    match header.encoding {
        Encoding::Raw => {
            let skip = if header.byte_skip == -1 {
                match left {
                    Some(l) if l >= data_bytes => l - data_bytes,
                    Some(l) => {
                        return Err(ImageError::Truncated {
                            path: name.to_owned(),
                            what: "voxel data",
                            needed: data_bytes,
                            got: l,
                        });
                    }
                    None => 0,
                }
            } else {
                header.byte_skip as u64
            };
            if let Some(l) = left
                && l < skip.saturating_add(data_bytes)
            {
                return Err(ImageError::Truncated {
                    path: name.to_owned(),
                    what: "voxel data",
                    needed: data_bytes,
                    got: l.saturating_sub(skip),
                });
            }
            skip_bytes(&mut reader, skip, "bytes to skip", name)?;
            header.layout.read_labels(&mut reader, name, false)
        }
        Encoding::Gzip => {
            let mut decoded = MultiGzDecoder::new(reader);
            skip_bytes(
                &mut decoded,
                header.byte_skip.max(0) as u64,
                "bytes to skip",
                name,
            )?;
            header.layout.read_labels(&mut decoded, name, true)
        }
        Encoding::Ascii => {
            skip_bytes(
                &mut reader,
                header.byte_skip.max(0) as u64,
                "bytes to skip",
                name,
            )?;
            read_ascii(&header.layout, reader, name)
        }
    }
}

/// Text data: numbers separated by white space (or commas), read a line at
/// a time so that memory follows the voxels, not the file.
fn read_ascii(
    layout: &VoxelLayout,
    mut reader: Box<dyn BufRead + '_>,
    name: &str,
) -> Result<Vec<i32>, ImageError> {
    let voxels = layout.voxels() as usize;
    let mut labels = Vec::with_capacity(voxels.min(1 << 20));
    let mut raw = Vec::new();
    let mut line_no = 0usize;
    while labels.len() < voxels {
        raw.clear();
        let n = (&mut reader)
            .take(1 << 20)
            .read_until(b'\n', &mut raw)
            .map_err(super::io_error(name))?;
        // Bytes that are not text fail as numbers below, naming the line.
        let line = String::from_utf8_lossy(&raw);
        if n == 0 {
            return Err(ImageError::Truncated {
                path: name.to_owned(),
                what: "voxel values",
                needed: voxels as u64,
                got: labels.len() as u64,
            });
        }
        line_no += 1;
        for token in line.split(|c: char| c.is_whitespace() || c == ',') {
            if token.is_empty() || labels.len() == voxels {
                continue;
            }
            let value: f64 = token.parse().map_err(|_| ImageError::BadLine {
                path: name.to_owned(),
                line: line_no,
                message: format!("{token:?} in the data is not a number"),
            })?;
            let label = layout.to_label(value, labels.len(), name)?;
            labels.push(label);
        }
    }
    Ok(labels)
}

pub(super) fn read_bytes(
    bytes: &[u8],
    name: &str,
    limits: &ImageLimits,
) -> Result<LabelImage, ImageError> {
    let mut cursor = bytes;
    let (lines, _) = header_lines(&mut cursor, name)?;
    let header = parse_header(&lines, name)?;
    if header.data_file.is_some() {
        return Err(ImageError::BadField {
            path: name.to_owned(),
            field: "data file".into(),
            value: header.data_file.clone().unwrap_or_default(),
            why: "the data is in another file: read the header from its path".into(),
        });
    }
    header.layout.check_memory(name, limits)?;
    let left = cursor.len() as u64;
    let labels = read_data(&header, Box::new(cursor), Some(left), name)?;
    header.into_image(labels, name)
}

pub(super) fn read_file(
    path: &Path,
    name: &str,
    limits: &ImageLimits,
) -> Result<LabelImage, ImageError> {
    let file = File::open(path).map_err(super::io_error(name))?;
    let len = file.metadata().map_err(super::io_error(name))?.len();
    let mut reader = BufReader::new(file);
    let (lines, header_bytes) = header_lines(&mut reader, name)?;
    let header = parse_header(&lines, name)?;
    header.layout.check_memory(name, limits)?;
    let labels = match &header.data_file {
        None => {
            let left = len.saturating_sub(header_bytes);
            read_data(&header, Box::new(reader), Some(left), name)?
        }
        Some(data) => {
            let data_path = path.parent().unwrap_or_else(|| Path::new(".")).join(data);
            let data_name = data_path.display().to_string();
            let file = File::open(&data_path).map_err(super::io_error(&data_name))?;
            let len = file.metadata().map_err(super::io_error(&data_name))?.len();
            read_data(
                &header,
                Box::new(BufReader::new(file)),
                Some(len),
                &data_name,
            )?
        }
    };
    header.into_image(labels, name)
}
