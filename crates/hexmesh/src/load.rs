//! Loading surface meshes: OBJ (tobj), STL ASCII and binary (stl_io), PLY
//! ([`ply`](crate::ply)), VTK legacy and XML ([`vtk`](crate::vtk)), and user
//! formats through [`MeshLoader`].
//!
//! Every loader's output goes through the same cleaning and checks
//! ([`clean_mesh`]): non-finite coordinates and out-of-range indices are errors;
//! duplicate vertices are welded (exactly, or within a tolerance); triangles
//! with a repeated index or zero area are dropped; a mesh left without
//! triangles, or whose bounding box has zero extent along some axis (it cannot
//! enclose any volume), is an error. Nothing here panics on any input.

use std::collections::HashMap;
use std::io::{BufRead, Cursor};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::TriMesh;
pub use crate::loader::{LoadError, LoadReport, LoadedMesh, MeshLoader};

/// Built-in mesh formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (text).
    Obj,
    /// STL, ASCII or binary (detected from the content).
    Stl,
    /// PLY, ASCII or binary of either endianness (from the header).
    Ply,
    /// VTK: legacy, or XML unstructured grid / poly data (from the content).
    Vtk,
}

impl MeshFormat {
    /// The format's name, as errors print it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Obj => "OBJ",
            Self::Stl => "STL",
            Self::Ply => "PLY",
            Self::Vtk => "VTK",
        }
    }

    /// The cargo feature of hexmesh that builds the format's reader in
    /// (`None`: always built).
    pub fn feature(self) -> Option<&'static str> {
        match self {
            Self::Obj | Self::Stl => None,
            Self::Ply => Some("ply"),
            Self::Vtk => Some("vtk"),
        }
    }

    /// The format for a file extension (case-insensitive), if built in.
    pub fn from_extension(ext: &str) -> Option<Self> {
        match ext.to_ascii_lowercase().as_str() {
            "obj" => Some(Self::Obj),
            "stl" => Some(Self::Stl),
            "ply" => Some(Self::Ply),
            "vtk" | "vtu" | "vtp" => Some(Self::Vtk),
            _ => None,
        }
    }
}

/// The built-in OBJ loader (tobj; all objects and groups merged, polygons
/// triangulated, normals, texture coordinates, lines and points ignored).
#[derive(Debug, Clone, Copy, Default)]
pub struct ObjLoader;

/// The built-in STL loader (stl_io), ASCII or binary detected from the
/// content: binary if the file is exactly `84 + 50 n` bytes long with `n` the
/// little-endian u32 at offset 80, ASCII otherwise (a binary file whose header
/// starts with "solid" still loads as binary).
#[derive(Debug, Clone, Copy, Default)]
pub struct StlLoader;

fn file(name: &str) -> PathBuf {
    PathBuf::from(name)
}

impl MeshLoader for ObjLoader {
    fn extensions(&self) -> &[&str] {
        &["obj"]
    }

    fn load(&self, bytes: &[u8], name: &str) -> Result<TriMesh, LoadError> {
        // OBJ is text: tobj skips a line it cannot read, so a NUL byte (a
        // binary or corrupted file) would silently drop vertices or faces.
        if let Some(at) = bytes.iter().position(|&b| b == 0) {
            let line = bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
            return Err(LoadError::Parse {
                file: file(name),
                line: Some(line),
                message: format!(
                    "NUL byte at offset {at}: an OBJ file is text (is this a binary or corrupted file?)"
                ),
            });
        }
        // tobj's option fields depend on its features: keep the struct update.
        #[allow(clippy::needless_update)]
        let options = tobj::LoadOptions {
            single_index: false,
            triangulate: true,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        // tobj reads a polyline of 3+ points ("l 1 2 3") as a polygon even
        // with ignore_lines: blank line and point elements (keeping line numbers).
        let filtered = strip_line_elements(bytes);
        let mut reader = Cursor::new(filtered.as_deref().unwrap_or(bytes));
        let (models, _materials) = tobj::load_obj_buf(&mut reader, &options, |_| {
            // Materials are irrelevant to geometry; never touch other files.
            Err(tobj::LoadError::OpenFileFailed)
        })
        .map_err(|e| {
            let (line, message) =
                locate_obj_problem(bytes).unwrap_or((None, format!("OBJ parser: {e}")));
            LoadError::Parse {
                file: file(name),
                line,
                message,
            }
        })?;
        let mut mesh = TriMesh::default();
        for model in &models {
            let m = &model.mesh;
            let base = mesh.vertices.len() as u64;
            for p in m.positions.chunks_exact(3) {
                // tobj is built with `use_f64`.
                mesh.vertices.push([p[0], p[1], p[2]]);
            }
            for (t, tri) in m.indices.chunks_exact(3).enumerate() {
                let mut out = [0u32; 3];
                for k in 0..3 {
                    let idx = base + tri[k] as u64;
                    if idx >= mesh.vertices.len() as u64 || idx > u32::MAX as u64 {
                        return Err(LoadError::IndexOutOfRange {
                            file: file(name),
                            triangle: mesh.triangles.len() + t,
                            index: idx,
                            vertices: mesh.vertices.len(),
                        });
                    }
                    out[k] = idx as u32;
                }
                mesh.triangles.push(out);
            }
        }
        Ok(mesh)
    }
}

/// `bytes` with every `l` and `p` element line blanked, or `None` if it has none.
fn strip_line_elements(bytes: &[u8]) -> Option<Vec<u8>> {
    let is_element = |line: &[u8]| {
        let t = line.trim_ascii_start();
        (t.starts_with(b"l") || t.starts_with(b"p"))
            && t.get(1).is_none_or(|c| c.is_ascii_whitespace())
    };
    if !bytes.split(|&b| b == b'\n').any(is_element) {
        return None;
    }
    let mut out = Vec::with_capacity(bytes.len());
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        if i > 0 {
            out.push(b'\n');
        }
        if !is_element(line) {
            out.extend_from_slice(line);
        }
    }
    Some(out)
}

/// Finds the first line of an OBJ text that is clearly wrong, to give a line
/// number for an error tobj reports without one.
fn locate_obj_problem(bytes: &[u8]) -> Option<(Option<usize>, String)> {
    let mut vertices = 0i64;
    for (no, line) in Cursor::new(bytes).lines().enumerate() {
        let Ok(line) = line else {
            return Some((Some(no + 1), "line is not valid UTF-8 text".into()));
        };
        let mut tokens = line.split_whitespace();
        match tokens.next() {
            Some("v") => {
                let coords: Vec<&str> = tokens.collect();
                if coords.len() < 3 || coords.iter().any(|c| c.parse::<f64>().is_err()) {
                    return Some((Some(no + 1), format!("bad vertex line {line:?}")));
                }
                vertices += 1;
            }
            Some("f") => {
                for tok in tokens {
                    let first = tok.split('/').next().unwrap_or("");
                    match first.parse::<i64>() {
                        Ok(i) if i > 0 && i <= vertices => {}
                        Ok(i) if i < 0 && -i <= vertices => {}
                        Ok(i) => {
                            return Some((
                                Some(no + 1),
                                format!(
                                    "face refers to vertex {i}, but only {vertices} are defined"
                                ),
                            ));
                        }
                        Err(_) => {
                            return Some((Some(no + 1), format!("bad face line {line:?}")));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}

impl MeshLoader for StlLoader {
    fn extensions(&self) -> &[&str] {
        &["stl"]
    }

    fn load(&self, bytes: &[u8], name: &str) -> Result<TriMesh, LoadError> {
        let len = bytes.len() as u64;
        let parse = |message: String| LoadError::Parse {
            file: file(name),
            line: None,
            message,
        };
        let binary_count = (bytes.len() >= 84)
            .then(|| u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]));
        let is_binary = binary_count.is_some_and(|n| 84 + 50 * n as u64 == len);
        let triangles: Vec<stl_io::Triangle> = if is_binary {
            // stl_io decides ASCII vs binary by a leading "solid ": blank the
            // header (which carries no geometry) so it cannot misread this file.
            let mut copy = bytes.to_vec();
            copy[..80].fill(0);
            let mut reader = Cursor::new(copy);
            let iter = stl_io::create_stl_reader(&mut reader)
                .map_err(|e| parse(format!("binary STL: {e}")))?;
            iter.collect::<Result<_, _>>()
                .map_err(|e| parse(format!("binary STL: {e}")))?
        } else {
            let text_start = bytes.iter().take(512).all(|&b| b != 0);
            let starts_solid = bytes.trim_ascii_start().starts_with(b"solid");
            if !(text_start && starts_solid) {
                if let Some(n) = binary_count {
                    let expected = 84 + 50 * n as u64;
                    if expected > len {
                        return Err(LoadError::TruncatedStl {
                            file: file(name),
                            triangles: n,
                            expected,
                            actual: len,
                        });
                    }
                    return Err(parse(format!(
                        "binary STL length {len} does not match its {n} triangles \
                         ({expected} bytes), and the file is not ASCII STL"
                    )));
                }
                return Err(parse(format!(
                    "file of {len} bytes is neither ASCII STL (no leading \"solid\") \
                     nor binary STL (shorter than the 84-byte header)"
                )));
            }
            // stl_io wants "solid " with a space: normalize the first line.
            let text = bytes.trim_ascii_start();
            let rest = match text.iter().position(|&b| b == b'\n') {
                Some(i) => &text[i + 1..],
                None => &[][..],
            };
            let mut fixed = b"solid mesh\n".to_vec();
            fixed.extend_from_slice(rest);
            let mut reader = Cursor::new(fixed);
            let iter = stl_io::create_stl_reader(&mut reader)
                .map_err(|e| parse(format!("ASCII STL: {e}")))?;
            iter.collect::<Result<_, _>>()
                .map_err(|e| parse(format!("ASCII STL: {e}")))?
        };
        let mut mesh = TriMesh::default();
        for (t, tri) in triangles.iter().enumerate() {
            let base = (3 * t) as u32;
            for v in &tri.vertices {
                mesh.vertices.push(v.0.map(|c| c as f64));
            }
            mesh.triangles.push([base, base + 1, base + 2]);
        }
        Ok(mesh)
    }
}

/// A set of mesh loaders, chosen by file extension: a value that a program
/// builds, extends and passes where meshes are read (no global state, so two
/// programs in one process, or two tests, cannot disturb each other).
///
/// [`Loaders::default`] serves the built-in formats (OBJ, STL, PLY, VTK). A loader added
/// later wins for an extension that several loaders serve.
///
/// ```
/// use std::sync::Arc;
/// use hexmesh::load::{LoadError, Loaders, MeshLoader};
/// use hexmesh::TriMesh;
///
/// /// A toy format: one triangle per line, nine numbers.
/// struct Tri;
/// impl MeshLoader for Tri {
///     fn extensions(&self) -> &[&str] {
///         &["tri"]
///     }
///     fn load(&self, bytes: &[u8], name: &str) -> Result<TriMesh, LoadError> {
///         let text = std::str::from_utf8(bytes).map_err(|_| LoadError::Parse {
///             file: name.into(),
///             line: None,
///             message: "not UTF-8".into(),
///         })?;
///         let mut mesh = TriMesh::default();
///         for (i, line) in text.lines().enumerate() {
///             let v: Vec<f64> = line.split_whitespace().filter_map(|t| t.parse().ok()).collect();
///             if v.len() != 9 {
///                 return Err(LoadError::Parse {
///                     file: name.into(),
///                     line: Some(i + 1),
///                     message: format!("{} numbers, expected 9", v.len()),
///                 });
///             }
///             let base = mesh.vertices.len() as u32;
///             for k in 0..3 {
///                 mesh.vertices.push([v[3 * k], v[3 * k + 1], v[3 * k + 2]]);
///             }
///             mesh.triangles.push([base, base + 1, base + 2]);
///         }
///         Ok(mesh)
///     }
/// }
///
/// let mut loaders = Loaders::default();
/// assert!(loaders.for_extension("tri").is_none());
/// loaders.register(Arc::new(Tri));
/// assert!(loaders.for_extension("TRI").is_some());
/// assert_eq!(loaders.known_extensions(), "obj, ply, stl, tri, vtk, vtp, vtu");
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("one.tri");
/// std::fs::write(&path, "0 0 0 1 0 0 0 1 0\n0 0 0 0 1 0 0 0 1\n0 0 0 0 0 1 1 0 0\n1 0 0 0 0 1 0 1 0\n").unwrap();
/// let loaded = loaders.load(&path).unwrap();
/// assert_eq!(loaded.mesh.triangles.len(), 4);
/// std::fs::write(&path, "0 0 0\n").unwrap();
/// assert!(loaders.load(&path).unwrap_err().to_string().contains("expected 9"));
/// ```
#[derive(Clone)]
pub struct Loaders {
    loaders: Vec<Arc<dyn MeshLoader>>,
    /// Largest mesh file read (bytes; default [`MAX_MESH_BYTES`]).
    pub max_bytes: u64,
    /// Most bytes a file's compressed content may unpack to, checked from
    /// what it declares before anything is unpacked (default
    /// [`MAX_UNPACKED_BYTES`]; a job lowers it to its memory limit).
    pub max_unpacked_bytes: u64,
}

/// Default most bytes a compressed mesh file may unpack to: twice the
/// largest file read.
pub const MAX_UNPACKED_BYTES: u64 = 2 * MAX_MESH_BYTES;

/// Largest coordinate magnitude accepted (m).
pub const MAX_COORDINATE: f64 = 1e9;

/// Default largest mesh file [`Loaders::load`] reads (bytes): a triangle
/// surface of a few million triangles.
pub const MAX_MESH_BYTES: u64 = 1 << 30;

impl Default for Loaders {
    fn default() -> Self {
        Self {
            loaders: vec![
                Arc::new(ObjLoader),
                Arc::new(StlLoader),
                #[cfg(feature = "ply")]
                Arc::new(crate::ply::PlyLoader),
                #[cfg(feature = "vtk")]
                Arc::new(crate::vtk::VtkLoader),
            ],
            max_bytes: MAX_MESH_BYTES,
            max_unpacked_bytes: MAX_UNPACKED_BYTES,
        }
    }
}

impl std::fmt::Debug for Loaders {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Loaders")
            .field("extensions", &self.known_extensions())
            .finish()
    }
}

impl Loaders {
    /// Adds a loader; it wins over earlier ones for the extensions it serves.
    pub fn register(&mut self, loader: Arc<dyn MeshLoader>) {
        self.loaders.push(loader);
    }

    /// The loader serving `ext` (case-insensitive, without the dot).
    pub fn for_extension(&self, ext: &str) -> Option<&dyn MeshLoader> {
        self.loaders
            .iter()
            .rev()
            .find(|l| l.extensions().iter().any(|e| e.eq_ignore_ascii_case(ext)))
            .map(|l| &**l)
    }

    /// Every extension served, sorted, comma-separated (for messages).
    pub fn known_extensions(&self) -> String {
        let mut all: Vec<String> = self
            .loaders
            .iter()
            .flat_map(|l| l.extensions().iter().map(|e| e.to_string()))
            .collect();
        all.sort();
        all.dedup();
        all.join(", ")
    }

    /// Loads and cleans a mesh file; the format comes from the extension.
    pub fn load(&self, path: &Path) -> Result<LoadedMesh, LoadError> {
        let name = path.display().to_string();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let loader = self.for_extension(&ext).ok_or_else(|| {
            match MeshFormat::from_extension(&ext).filter(|f| f.feature().is_some()) {
                // A built-in format compiled out says so, rather than "unknown".
                Some(format) => LoadError::FormatNotBuilt {
                    file: path.to_path_buf(),
                    format: format.name(),
                    feature: format.feature(),
                },
                None => LoadError::UnknownFormat {
                    file: path.to_path_buf(),
                    extension: ext.clone(),
                    known: self.known_extensions(),
                },
            }
        })?;
        let io = |source| LoadError::Io {
            file: path.to_path_buf(),
            source,
        };
        // Only regular files: a device (`/dev/zero`) would be read until
        // memory runs out, a FIFO would block forever.
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            return Err(LoadError::NotAFile {
                file: path.to_path_buf(),
            });
        }
        if meta.len() > self.max_bytes {
            return Err(LoadError::TooLarge {
                file: path.to_path_buf(),
                size: meta.len(),
                limit: self.max_bytes,
            });
        }
        // Read at most the limit (plus one byte to notice a file that grew).
        let mut bytes = Vec::with_capacity(meta.len() as usize);
        std::io::Read::read_to_end(
            &mut std::io::Read::take(std::fs::File::open(path).map_err(io)?, self.max_bytes + 1),
            &mut bytes,
        )
        .map_err(io)?;
        if bytes.len() as u64 > self.max_bytes {
            return Err(LoadError::TooLarge {
                file: path.to_path_buf(),
                size: bytes.len() as u64,
                limit: self.max_bytes,
            });
        }
        load_with(loader, &bytes, &name, self.max_unpacked_bytes)
    }
}

/// Loads and cleans a mesh file with the built-in loaders ([`Loaders::default`]);
/// the format comes from the extension (for STL, ASCII or binary is detected
/// from the content). Exact duplicates are welded.
pub fn load_mesh(path: &Path) -> Result<LoadedMesh, LoadError> {
    Loaders::default().load(path)
}

/// Loads and cleans a mesh held in memory (for instance embedded in a binary
/// with `include_bytes!`); `name` is used in errors.
pub fn load_mesh_bytes(
    bytes: &[u8],
    format: MeshFormat,
    name: &str,
) -> Result<LoadedMesh, LoadError> {
    match format {
        MeshFormat::Obj => load_with(&ObjLoader, bytes, name, MAX_UNPACKED_BYTES),
        MeshFormat::Stl => load_with(&StlLoader, bytes, name, MAX_UNPACKED_BYTES),
        #[cfg(feature = "ply")]
        MeshFormat::Ply => load_with(&crate::ply::PlyLoader, bytes, name, MAX_UNPACKED_BYTES),
        #[cfg(feature = "vtk")]
        MeshFormat::Vtk => load_with(&crate::vtk::VtkLoader, bytes, name, MAX_UNPACKED_BYTES),
        #[cfg(not(all(feature = "ply", feature = "vtk")))]
        other => Err(LoadError::FormatNotBuilt {
            file: file(name),
            format: other.name(),
            feature: other.feature(),
        }),
    }
}

fn load_with(
    loader: &dyn MeshLoader,
    bytes: &[u8],
    name: &str,
    budget: u64,
) -> Result<LoadedMesh, LoadError> {
    if bytes.is_empty() {
        return Err(LoadError::Empty { file: file(name) });
    }
    let raw = loader.load_within(bytes, name, budget)?;
    clean_mesh(raw, 0.0, name)
}

/// Validates and cleans a raw mesh: rejects non-finite coordinates and
/// out-of-range indices; welds vertices closer than `weld_tolerance` (0 =
/// exact duplicates only; a tolerance snaps each vertex to the first vertex
/// found within it on a hash grid); drops triangles with a repeated index or
/// zero area; rejects a mesh without triangles or with a flat bounding box.
pub fn clean_mesh(raw: TriMesh, weld_tolerance: f64, name: &str) -> Result<LoadedMesh, LoadError> {
    let mut report = LoadReport {
        vertices_read: raw.vertices.len(),
        triangles_read: raw.triangles.len(),
        ..Default::default()
    };
    for (i, v) in raw.vertices.iter().enumerate() {
        if v.iter().any(|c| !c.is_finite()) {
            return Err(LoadError::NonFinite {
                file: file(name),
                vertex: i,
                value: *v,
            });
        }
    }
    for (t, tri) in raw.triangles.iter().enumerate() {
        if let Some(&bad) = tri.iter().find(|&&i| i as usize >= raw.vertices.len()) {
            return Err(LoadError::IndexOutOfRange {
                file: file(name),
                triangle: t,
                index: bad as u64,
                vertices: raw.vertices.len(),
            });
        }
    }
    // Weld: map every vertex to a representative.
    let mut remap = vec![0u32; raw.vertices.len()];
    let mut vertices: Vec<[f64; 3]> = Vec::with_capacity(raw.vertices.len());
    if weld_tolerance > 0.0 && weld_tolerance.is_finite() {
        let cell = |p: [f64; 3]| p.map(|c| (c / weld_tolerance).floor() as i64);
        let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for (i, &p) in raw.vertices.iter().enumerate() {
            let c = cell(p);
            let mut found = None;
            'search: for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            for &j in list {
                                let q = vertices[j as usize];
                                let d2: f64 = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum();
                                if d2 <= weld_tolerance * weld_tolerance {
                                    found = Some(j);
                                    break 'search;
                                }
                            }
                        }
                    }
                }
            }
            remap[i] = found.unwrap_or_else(|| {
                vertices.push(p);
                let j = (vertices.len() - 1) as u32;
                grid.entry(c).or_default().push(j);
                j
            });
        }
    } else {
        // -0.0 and 0.0 are the same point: normalize before hashing bits.
        let key = |p: [f64; 3]| p.map(|c| (c + 0.0).to_bits());
        let mut seen: HashMap<[u64; 3], u32> = HashMap::with_capacity(raw.vertices.len());
        for (i, &p) in raw.vertices.iter().enumerate() {
            remap[i] = *seen.entry(key(p)).or_insert_with(|| {
                vertices.push(p);
                (vertices.len() - 1) as u32
            });
        }
    }
    report.vertices_welded = raw.vertices.len() - vertices.len();
    let mut triangles = Vec::with_capacity(raw.triangles.len());
    for tri in &raw.triangles {
        let t = tri.map(|i| remap[i as usize]);
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            report.degenerate_repeated += 1;
            continue;
        }
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let w = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ];
        if n == [0.0; 3] {
            report.degenerate_zero_area += 1;
            continue;
        }
        triangles.push(t);
    }
    if triangles.is_empty() {
        return Err(LoadError::NoTriangles {
            file: file(name),
            dropped: report.degenerate_repeated + report.degenerate_zero_area,
        });
    }
    let mut used = vec![false; vertices.len()];
    for t in &triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    report.unused_vertices = used.iter().filter(|u| !**u).count();
    let mesh = TriMesh {
        vertices,
        triangles,
    };
    // Extent of the vertices used by triangles only.
    let used = mesh
        .triangles
        .iter()
        .flatten()
        .map(|&i| mesh.vertices[i as usize]);
    let crate::Aabb { min: lo, max: hi } = crate::Aabb::of_points(used).unwrap_or(crate::Aabb {
        min: [0.0; 3],
        max: [0.0; 3],
    });
    // Beyond this, volumes and cell counts overflow or lose all precision:
    // not a body in metres (the mesh needs scaling).
    if lo.iter().chain(&hi).any(|c| c.abs() > MAX_COORDINATE) {
        return Err(LoadError::HugeCoordinates {
            file: file(name),
            min: lo,
            max: hi,
            limit: MAX_COORDINATE,
        });
    }
    if let Some(k) = (0..3).find(|&k| hi[k] <= lo[k]) {
        return Err(LoadError::ZeroExtent {
            file: file(name),
            axis: ["x", "y", "z"][k],
            min: lo,
            max: hi,
        });
    }
    if report.vertices_welded + report.degenerate_repeated + report.degenerate_zero_area > 0 {
        log::info!(
            "{name}: welded {} vertices, dropped {} + {} degenerate triangles",
            report.vertices_welded,
            report.degenerate_repeated,
            report.degenerate_zero_area
        );
    }
    Ok(LoadedMesh { mesh, report })
}
