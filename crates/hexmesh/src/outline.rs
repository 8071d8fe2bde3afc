//! Planar shapes for the 2D element: outlines read from SVG drawings or
//! from planar surface meshes, and an outline carried by a
//! [`RectLattice`] ([`OutlineEmbedding`], the 2D twin of [`crate::embed`]).
//!
//! **SVG** (`.svg`): `<polygon>`, `<polyline>` (closed), `<rect>`,
//! `<circle>`, `<ellipse>` and `<path>` with the commands M, L, H, V, C, S,
//! Q, T and Z (absolute and relative; curves flattened into 16 segments),
//! under `transform` attributes of the element and its groups (`matrix`,
//! `translate`, `scale`, `rotate`). Coordinates are the drawing's user units
//! with y turned up (SVG's y points down); a scene's `[mesh] units` and
//! `scale` say what a unit is. Every subpath is a closed polygon; inside
//! is decided by the even-odd rule, so a shape drawn inside another is a
//! hole.
//!
//! **Planar meshes** (OBJ, STL, PLY, VTK whose vertices share one plane):
//! the boundary loops of the triangles, in coordinates of that plane (x and
//! y when it is parallel to z = 0).
//!
//! ```
//! use hexmesh::outline::{OutlineEmbedding, outline_from_svg};
//! use hexmesh::plane::rasterize;
//!
//! let svg = r#"<svg><rect x="0" y="-1" width="2" height="1"/></svg>"#;
//! let outline = outline_from_svg(svg.as_bytes(), "bar.svg").unwrap();
//! assert!((outline.area() - 2.0).abs() < 1e-12);
//! let lattice = rasterize(&outline, [0.25, 0.25]).unwrap();
//! assert_eq!(lattice.num_cells(), 32);
//! // The outline follows the lattice's nodes.
//! let carried = OutlineEmbedding::new(&lattice, &outline);
//! let moved: Vec<[f64; 2]> = lattice.nodes().iter().map(|p| [p[0] + 1.0, 2.0 * p[1]]).collect();
//! let loops = carried.deform(&moved);
//! assert!((loops[0][0][0] - (outline.polygons()[0][0][0] + 1.0)).abs() < 1e-12);
//! ```

use std::path::Path;

use thiserror::Error;

use crate::plane::{Outline, PlaneError, RectLattice};

/// Why an outline could not be read.
#[derive(Debug, Error)]
pub enum OutlineError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The SVG is malformed or uses something not read here.
    #[error("{path}:{line}: {message}")]
    Svg {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The mesh's vertices do not share a plane.
    #[error(
        "{path}: the mesh is not planar (a vertex lies {deviation:.3e} off the plane of the \
         others, {relative:.1e} of its size): a 2D body needs a flat outline"
    )]
    NotPlanar {
        /// The file.
        path: String,
        /// Largest distance from the plane (file units).
        deviation: f64,
        /// The same relative to the mesh's extent.
        relative: f64,
    },
    /// The mesh could not be loaded.
    #[error(transparent)]
    Mesh(#[from] crate::LoadError),
    /// The outline is unusable.
    #[error("{path}: {source}")]
    Outline {
        /// The file.
        path: String,
        /// Why.
        source: PlaneError,
    },
}

/// Reads the outline of the file at `path` (SVG by its extension, else a
/// planar surface mesh).
pub fn load_outline(path: &Path) -> Result<Outline, OutlineError> {
    let name = path.display().to_string();
    let is_svg = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if is_svg {
        let bytes = std::fs::read(path).map_err(|source| OutlineError::Io {
            path: name.clone(),
            source,
        })?;
        outline_from_svg(&bytes, &name)
    } else {
        let mesh = crate::load::load_mesh(path)?.mesh;
        outline_from_planar_mesh(&mesh, &name)
    }
}

/// The boundary loops of a planar triangle mesh, in the plane's
/// coordinates.
pub fn outline_from_planar_mesh(
    mesh: &crate::TriMesh,
    name: &str,
) -> Result<Outline, OutlineError> {
    let bad = |source| OutlineError::Outline {
        path: name.to_owned(),
        source,
    };
    if mesh.triangles.is_empty() {
        return Err(bad(PlaneError::Empty));
    }
    // The plane: area-weighted normal through the centroid.
    let v = &mesh.vertices;
    let mut normal = [0.0; 3];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| v[i as usize]);
        let (e1, e2) = (sub3(b, a), sub3(c, a));
        let n = cross(e1, e2);
        for k in 0..3 {
            normal[k] += n[k];
        }
    }
    let len = dot(normal, normal).sqrt();
    if len == 0.0 {
        return Err(bad(PlaneError::Empty));
    }
    let normal = normal.map(|c| c / len);
    let centroid = {
        let mut c = [0.0; 3];
        for p in v {
            for k in 0..3 {
                c[k] += p[k] / v.len() as f64;
            }
        }
        c
    };
    let extent = mesh
        .bounding_box()
        .map_or(0.0, |b| b.extent().into_iter().fold(0.0, f64::max));
    let deviation = v
        .iter()
        .map(|p| dot(sub3(*p, centroid), normal).abs())
        .fold(0.0, f64::max);
    if deviation > 1e-6 * extent {
        return Err(OutlineError::NotPlanar {
            path: name.to_owned(),
            deviation,
            relative: deviation / extent.max(f64::MIN_POSITIVE),
        });
    }
    // In-plane axes: x and y for a plane parallel to z = 0.
    let (u, w) = if normal[2].abs() > 1.0 - 1e-9 {
        ([1.0, 0.0, 0.0], [0.0, normal[2].signum(), 0.0])
    } else {
        let u = {
            let c = cross([0.0, 0.0, 1.0], normal);
            let l = dot(c, c).sqrt();
            c.map(|x| x / l)
        };
        (u, cross(normal, u))
    };
    // Boundary edges: used by one triangle.
    let mut count = std::collections::HashMap::new();
    for t in &mesh.triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0u32) += 1;
        }
    }
    let mut next = std::collections::BTreeMap::new();
    for t in &mesh.triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if count[&(a.min(b), a.max(b))] == 1 {
                next.insert(a, b);
            }
        }
    }
    let mut polygons = Vec::new();
    while let Some((&start, _)) = next.iter().next() {
        let mut loop_ = Vec::new();
        let mut at = start;
        while let Some(b) = next.remove(&at) {
            let p = sub3(v[at as usize], centroid);
            loop_.push([dot(p, u), dot(p, w)]);
            at = b;
            if at == start {
                break;
            }
        }
        if loop_.len() >= 3 {
            polygons.push(loop_);
        }
    }
    Outline::new(polygons).map_err(bad)
}

fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// An affine map `[a, b, c, d, e, f]`: `(x, y) -> (a x + c y + e, b x + d y + f)`.
type Affine = [f64; 6];
const IDENTITY: Affine = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0];

fn compose(outer: &Affine, inner: &Affine) -> Affine {
    let [a, b, c, d, e, f] = *outer;
    let [a2, b2, c2, d2, e2, f2] = *inner;
    [
        a * a2 + c * b2,
        b * a2 + d * b2,
        a * c2 + c * d2,
        b * c2 + d * d2,
        a * e2 + c * f2 + e,
        b * e2 + d * f2 + f,
    ]
}

fn apply(m: &Affine, p: [f64; 2]) -> [f64; 2] {
    [
        m[0] * p[0] + m[2] * p[1] + m[4],
        m[1] * p[0] + m[3] * p[1] + m[5],
    ]
}

/// Numbers in an SVG attribute (separated by white space or commas; signs
/// and exponents start new numbers as SVG allows: `1-2` is 1 and -2).
fn numbers(text: &str) -> Result<Vec<f64>, String> {
    let mut out = Vec::new();
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_ascii_whitespace() || c == b',' {
            i += 1;
            continue;
        }
        let start = i;
        if c == b'+' || c == b'-' {
            i += 1;
        }
        let mut dot_seen = false;
        while i < b.len() && (b[i].is_ascii_digit() || (b[i] == b'.' && !dot_seen)) {
            dot_seen |= b[i] == b'.';
            i += 1;
        }
        if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
            i += 1;
            if i < b.len() && (b[i] == b'+' || b[i] == b'-') {
                i += 1;
            }
            while i < b.len() && b[i].is_ascii_digit() {
                i += 1;
            }
        }
        let token = &text[start..i];
        let v: f64 = token
            .parse()
            .map_err(|_| format!("{:?} is not a number", &text[start..(start + 1).max(i)]))?;
        if !v.is_finite() {
            return Err(format!("{token} is not finite"));
        }
        out.push(v);
    }
    Ok(out)
}

fn transform_of(text: &str) -> Result<Affine, String> {
    let mut m = IDENTITY;
    let mut rest = text.trim();
    while !rest.is_empty() {
        let open = rest
            .find('(')
            .ok_or_else(|| format!("transform {text:?}: expected name(values)"))?;
        let close = rest[open..]
            .find(')')
            .ok_or_else(|| format!("transform {text:?}: a ( is not closed"))?
            + open;
        let name = rest[..open].trim().trim_start_matches(',').trim();
        let v = numbers(&rest[open + 1..close])?;
        let t: Affine = match (name, v.as_slice()) {
            ("matrix", [a, b, c, d, e, f]) => [*a, *b, *c, *d, *e, *f],
            ("translate", [x]) => [1.0, 0.0, 0.0, 1.0, *x, 0.0],
            ("translate", [x, y]) => [1.0, 0.0, 0.0, 1.0, *x, *y],
            ("scale", [s]) => [*s, 0.0, 0.0, *s, 0.0, 0.0],
            ("scale", [sx, sy]) => [*sx, 0.0, 0.0, *sy, 0.0, 0.0],
            ("rotate", [a]) | ("rotate", [a, _, _]) => {
                let (s, c) = a.to_radians().sin_cos();
                let r = [c, s, -s, c, 0.0, 0.0];
                if let [_, cx, cy] = v.as_slice() {
                    let to = [1.0, 0.0, 0.0, 1.0, *cx, *cy];
                    let back = [1.0, 0.0, 0.0, 1.0, -cx, -cy];
                    compose(&to, &compose(&r, &back))
                } else {
                    r
                }
            }
            _ => {
                return Err(format!(
                    "transform {name}({}) is not read here (matrix, translate, scale, rotate are)",
                    &rest[open + 1..close]
                ));
            }
        };
        m = compose(&m, &t);
        rest = rest[close + 1..].trim();
    }
    Ok(m)
}

/// Segments a curve is flattened into.
const CURVE_SEGMENTS: usize = 16;

/// The subpaths of a path's `d` attribute, as polygons in user units.
fn path_polygons(d: &str) -> Result<Vec<Vec<[f64; 2]>>, String> {
    let mut polygons: Vec<Vec<[f64; 2]>> = Vec::new();
    let mut current: Vec<[f64; 2]> = Vec::new();
    let mut pos = [0.0; 2];
    let mut start = [0.0; 2];
    // The last control point, for S and T.
    let mut last_cubic: Option<[f64; 2]> = None;
    let mut last_quad: Option<[f64; 2]> = None;
    let mut command: Option<char> = None;
    let mut args = String::new();
    let mut flush = |cmd: char,
                     args: &str,
                     polygons: &mut Vec<Vec<[f64; 2]>>|
     -> Result<(), String> {
        let v = numbers(args)?;
        let rel = cmd.is_ascii_lowercase();
        let base = |pos: [f64; 2]| if rel { pos } else { [0.0; 2] };
        let arity = match cmd.to_ascii_uppercase() {
            'M' | 'L' | 'T' => 2,
            'H' | 'V' => 1,
            'C' => 6,
            'S' | 'Q' => 4,
            'Z' => 0,
            'A' => return Err("arc commands (A) are not read here: convert arcs to curves".into()),
            other => return Err(format!("unknown path command {other:?}")),
        };
        if arity == 0 {
            if !v.is_empty() {
                return Err("Z takes no numbers".into());
            }
            if current.len() >= 3 {
                polygons.push(std::mem::take(&mut current));
            }
            current.clear();
            pos = start;
            return Ok(());
        }
        if v.is_empty() || v.len() % arity != 0 {
            return Err(format!(
                "{cmd} takes {arity} numbers per segment, got {}",
                v.len()
            ));
        }
        for (k, c) in v.chunks(arity).enumerate() {
            let b = base(pos);
            let upper = cmd.to_ascii_uppercase();
            // M's further pairs are L.
            let upper = if upper == 'M' && k > 0 { 'L' } else { upper };
            match upper {
                'M' => {
                    if current.len() >= 3 {
                        polygons.push(std::mem::take(&mut current));
                    }
                    current.clear();
                    pos = [b[0] + c[0], b[1] + c[1]];
                    start = pos;
                    current.push(pos);
                }
                'L' => {
                    pos = [b[0] + c[0], b[1] + c[1]];
                    current.push(pos);
                }
                'H' => {
                    pos = [b[0] + c[0], pos[1]];
                    current.push(pos);
                }
                'V' => {
                    pos = [pos[0], (if rel { pos[1] } else { 0.0 }) + c[0]];
                    current.push(pos);
                }
                'C' | 'S' => {
                    let (c1, c2, end) = if upper == 'C' {
                        (
                            [b[0] + c[0], b[1] + c[1]],
                            [b[0] + c[2], b[1] + c[3]],
                            [b[0] + c[4], b[1] + c[5]],
                        )
                    } else {
                        let c1 =
                            last_cubic.map_or(pos, |l| [2.0 * pos[0] - l[0], 2.0 * pos[1] - l[1]]);
                        (c1, [b[0] + c[0], b[1] + c[1]], [b[0] + c[2], b[1] + c[3]])
                    };
                    for s in 1..=CURVE_SEGMENTS {
                        let t = s as f64 / CURVE_SEGMENTS as f64;
                        let m = 1.0 - t;
                        current.push(std::array::from_fn(|k| {
                            m * m * m * pos[k]
                                + 3.0 * m * m * t * c1[k]
                                + 3.0 * m * t * t * c2[k]
                                + t * t * t * end[k]
                        }));
                    }
                    last_cubic = Some(c2);
                    pos = end;
                }
                'Q' | 'T' => {
                    let (ctrl, end) = if upper == 'Q' {
                        ([b[0] + c[0], b[1] + c[1]], [b[0] + c[2], b[1] + c[3]])
                    } else {
                        let ctrl =
                            last_quad.map_or(pos, |l| [2.0 * pos[0] - l[0], 2.0 * pos[1] - l[1]]);
                        (ctrl, [b[0] + c[0], b[1] + c[1]])
                    };
                    for s in 1..=CURVE_SEGMENTS {
                        let t = s as f64 / CURVE_SEGMENTS as f64;
                        let m = 1.0 - t;
                        current.push(std::array::from_fn(|k| {
                            m * m * pos[k] + 2.0 * m * t * ctrl[k] + t * t * end[k]
                        }));
                    }
                    last_quad = Some(ctrl);
                    pos = end;
                }
                _ => unreachable!("commands checked above"),
            }
            if !matches!(upper, 'C' | 'S') {
                last_cubic = None;
            }
            if !matches!(upper, 'Q' | 'T') {
                last_quad = None;
            }
        }
        Ok(())
    };
    for ch in d.chars() {
        if ch.is_ascii_alphabetic() && ch != 'e' && ch != 'E' {
            if let Some(cmd) = command.take() {
                flush(cmd, &args, &mut polygons)?;
            }
            command = Some(ch);
            args.clear();
        } else {
            if command.is_none() && !ch.is_whitespace() {
                return Err("the path data does not start with a command (M)".into());
            }
            args.push(ch);
        }
    }
    if let Some(cmd) = command {
        flush(cmd, &args, &mut polygons)?;
    }
    if current.len() >= 3 {
        polygons.push(current);
    }
    Ok(polygons)
}

/// The polygons of an SVG drawing (`name` in errors), y turned up.
pub fn outline_from_svg(bytes: &[u8], name: &str) -> Result<Outline, OutlineError> {
    use quick_xml::events::{BytesStart, Event};
    let mut reader = quick_xml::Reader::from_reader(bytes);
    reader.config_mut().check_end_names = true;
    let line_at = |pos: u64| {
        let pos = (pos as usize).min(bytes.len());
        bytes[..pos].iter().filter(|&&b| b == b'\n').count() + 1
    };
    let svg_error = |line: usize, message: String| OutlineError::Svg {
        path: name.to_owned(),
        line,
        message,
    };
    let mut stack: Vec<Affine> = vec![IDENTITY];
    let mut polygons: Vec<Vec<[f64; 2]>> = Vec::new();
    let mut buf = Vec::new();
    let attr = |e: &BytesStart<'_>, key: &str| -> Option<String> {
        e.attributes()
            .flatten()
            .find(|a| a.key.as_ref() == key.as_bytes())
            .map(|a| String::from_utf8_lossy(&a.value).into_owned())
    };
    loop {
        let event = reader.read_event_into(&mut buf);
        let line = line_at(reader.buffer_position());
        let (e, empty) = match event {
            Ok(Event::Eof) => break,
            Ok(Event::Start(e)) => (e.into_owned(), false),
            Ok(Event::Empty(e)) => (e.into_owned(), true),
            Ok(Event::End(_)) => {
                if stack.len() > 1 {
                    stack.pop();
                }
                buf.clear();
                continue;
            }
            Ok(_) => {
                buf.clear();
                continue;
            }
            Err(e) => {
                return Err(svg_error(
                    line_at(reader.error_position()),
                    format!(
                        "malformed XML: {}",
                        e.to_string().lines().next().unwrap_or("")
                    ),
                ));
            }
        };
        let parent = *stack.last().expect("the root transform");
        let own = match attr(&e, "transform") {
            Some(t) => transform_of(&t).map_err(|m| svg_error(line, m))?,
            None => IDENTITY,
        };
        let m = compose(&parent, &own);
        let num = |key: &str| -> Result<f64, OutlineError> {
            match attr(&e, key) {
                None => Ok(0.0),
                Some(t) => {
                    let t = t.trim().trim_end_matches("px");
                    let v = numbers(t).map_err(|m| svg_error(line, format!("{key}: {m}")))?;
                    match v.as_slice() {
                        [x] => Ok(*x),
                        _ => Err(svg_error(line, format!("{key} = {t:?} is not one number"))),
                    }
                }
            }
        };
        let tag = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        let mut shapes: Vec<Vec<[f64; 2]>> = Vec::new();
        match tag.as_str() {
            "polygon" | "polyline" => {
                let v = numbers(&attr(&e, "points").unwrap_or_default())
                    .map_err(|m| svg_error(line, format!("points: {m}")))?;
                if v.len() % 2 != 0 {
                    return Err(svg_error(line, "points: an odd count of numbers".into()));
                }
                shapes.push(v.chunks(2).map(|c| [c[0], c[1]]).collect());
            }
            "rect" => {
                let (x, y, w, h) = (num("x")?, num("y")?, num("width")?, num("height")?);
                shapes.push(vec![[x, y], [x + w, y], [x + w, y + h], [x, y + h]]);
            }
            "circle" | "ellipse" => {
                let (cx, cy) = (num("cx")?, num("cy")?);
                let (rx, ry) = if tag == "circle" {
                    (num("r")?, num("r")?)
                } else {
                    (num("rx")?, num("ry")?)
                };
                shapes.push(
                    (0..64)
                        .map(|i| {
                            let a = i as f64 / 64.0 * std::f64::consts::TAU;
                            [cx + rx * a.cos(), cy + ry * a.sin()]
                        })
                        .collect(),
                );
            }
            "path" => {
                let d = attr(&e, "d").unwrap_or_default();
                shapes = path_polygons(&d).map_err(|m| svg_error(line, format!("path: {m}")))?;
            }
            _ => {}
        }
        for s in shapes {
            polygons.push(
                s.into_iter()
                    .map(|p| {
                        let q = apply(&m, p);
                        [q[0], -q[1]]
                    })
                    .collect(),
            );
        }
        if !empty {
            stack.push(m);
        }
        buf.clear();
    }
    Outline::new(polygons).map_err(|source| OutlineError::Outline {
        path: name.to_owned(),
        source,
    })
}

/// An outline carried by a [`RectLattice`]: each vertex bound to a cell by
/// bilinear coordinates (a vertex outside every cell to the nearest cell,
/// with coordinates outside [0, 1]).
#[derive(Debug, Clone, PartialEq)]
pub struct OutlineEmbedding {
    /// Per loop, per vertex: the cell's 4 nodes and their weights.
    loops: Vec<Vec<([u32; 4], [f64; 4])>>,
}

impl OutlineEmbedding {
    /// Binds `outline`'s vertices to `lattice`'s cells.
    pub fn new(lattice: &RectLattice, outline: &Outline) -> Self {
        let [l0, h0] = lattice.cell_size();
        let o = lattice.origin();
        let index: std::collections::HashMap<[u32; 2], usize> = lattice
            .cell_coords()
            .iter()
            .enumerate()
            .map(|(i, c)| (*c, i))
            .collect();
        let loops = outline
            .polygons()
            .iter()
            .map(|poly| {
                poly.iter()
                    .map(|&p| {
                        let g = [(p[0] - o[0]) / l0, (p[1] - o[1]) / h0];
                        let home = [g[0].floor(), g[1].floor()];
                        let cell = (home[0] >= 0.0 && home[1] >= 0.0)
                            .then(|| index.get(&[home[0] as u32, home[1] as u32]))
                            .flatten()
                            .copied()
                            .unwrap_or_else(|| {
                                // The nearest cell by its centre.
                                lattice
                                    .cell_coords()
                                    .iter()
                                    .enumerate()
                                    .min_by(|(_, a), (_, b)| {
                                        let d = |c: &[u32; 2]| {
                                            (c[0] as f64 + 0.5 - g[0]).powi(2)
                                                + (c[1] as f64 + 0.5 - g[1]).powi(2)
                                        };
                                        d(a).total_cmp(&d(b))
                                    })
                                    .map(|(i, _)| i)
                                    .expect("a lattice has cells")
                            });
                        let c = lattice.cell_coords()[cell];
                        let (s, t) = (g[0] - c[0] as f64, g[1] - c[1] as f64);
                        (
                            lattice.cells()[cell],
                            [(1.0 - s) * (1.0 - t), s * (1.0 - t), s * t, (1.0 - s) * t],
                        )
                    })
                    .collect()
            })
            .collect();
        Self { loops }
    }

    /// The outline's loops where the lattice's nodes are at `nodes`.
    pub fn deform(&self, nodes: &[[f64; 2]]) -> Vec<Vec<[f64; 2]>> {
        self.loops
            .iter()
            .map(|l| {
                l.iter()
                    .map(|(cell, w)| {
                        let mut p = [0.0; 2];
                        for k in 0..4 {
                            let q = nodes[cell[k] as usize];
                            p[0] += w[k] * q[0];
                            p[1] += w[k] * q[1];
                        }
                        p
                    })
                    .collect()
            })
            .collect()
    }
}
