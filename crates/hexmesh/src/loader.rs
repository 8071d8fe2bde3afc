//! What every mesh loader shares: the [`MeshLoader`] plug point, the
//! [`LoadError`] all of them return, and the [`LoadedMesh`] that cleaning
//! produces. The built-in formats ([`load`](crate::load), [`ply`](crate::ply),
//! [`vtk`](crate::vtk)) depend on this module and it on none of them, so a
//! format can be compiled out (the `ply` and `vtk` features) without touching
//! the others.

use std::path::PathBuf;

use thiserror::Error;

use crate::TriMesh;

/// Why a mesh could not be loaded. Every variant names the file (or the name
/// given to [`load_mesh_bytes`](crate::load::load_mesh_bytes)).
#[derive(Debug, Error)]
pub enum LoadError {
    /// The file could not be read (missing, permissions, ...).
    #[error("cannot read mesh file {file}: {source}")]
    Io {
        /// The file.
        file: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file has no bytes.
    #[error("mesh file {file} is empty")]
    Empty {
        /// The file.
        file: PathBuf,
    },
    /// Coordinates so large that the body's volume and cell counts overflow.
    #[error(
        "mesh {file} spans {} .. {}: coordinates beyond {limit:e} (m) are not a physical body; scale the mesh",
        fmt3(min),
        fmt3(max)
    )]
    HugeCoordinates {
        /// The file.
        file: PathBuf,
        /// Bounding box minimum.
        min: [f64; 3],
        /// Bounding box maximum.
        max: [f64; 3],
        /// The largest coordinate accepted.
        limit: f64,
    },
    /// The path is not a regular file (a folder, a device, a FIFO, ...).
    #[error("mesh path {file} is not a regular file (a folder, device or pipe); give a mesh file")]
    NotAFile {
        /// The path.
        file: PathBuf,
    },
    /// The file is larger than the loaders' limit.
    #[error("mesh file {file} is {size} bytes, more than the limit of {limit} bytes")]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// Its size (bytes).
        size: u64,
        /// The limit (bytes).
        limit: u64,
    },
    /// No loader is registered for the file's extension.
    #[error("mesh file {file}: unknown format (extension {extension:?}); known: {known}")]
    UnknownFormat {
        /// The file.
        file: PathBuf,
        /// Its extension (lower case, possibly empty).
        extension: String,
        /// The registered extensions, comma separated.
        known: String,
    },
    /// The file's format is known but its reader was compiled out (hexmesh
    /// built without the format's feature).
    #[error(
        "mesh file {file}: {format} support is not built in (hexmesh's `{}` feature is off)",
        feature.unwrap_or("default")
    )]
    FormatNotBuilt {
        /// The file.
        file: PathBuf,
        /// The format's name.
        format: &'static str,
        /// The hexmesh feature that builds it in.
        feature: Option<&'static str>,
    },
    /// A binary STL file is shorter than its triangle count says.
    #[error(
        "binary STL {file} is truncated: header announces {triangles} triangles \
         ({expected} bytes) but the file has {actual} bytes"
    )]
    TruncatedStl {
        /// The file.
        file: PathBuf,
        /// Triangle count in the header.
        triangles: u32,
        /// Expected file length.
        expected: u64,
        /// Actual file length.
        actual: u64,
    },
    /// Text that could not be parsed.
    #[error("cannot parse {file}{}: {message}", line.map(|l| format!(" (line {l})")).unwrap_or_default())]
    Parse {
        /// The file.
        file: PathBuf,
        /// 1-based line number, where known.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("mesh {file}: vertex {vertex} has a non-finite coordinate {value:?}")]
    NonFinite {
        /// The file.
        file: PathBuf,
        /// 0-based vertex index.
        vertex: usize,
        /// The vertex.
        value: [f64; 3],
    },
    /// A triangle refers to a vertex that does not exist.
    #[error(
        "mesh {file}: triangle {triangle} refers to vertex {index}, but there are {vertices} vertices"
    )]
    IndexOutOfRange {
        /// The file.
        file: PathBuf,
        /// 0-based triangle index.
        triangle: usize,
        /// The offending 0-based index.
        index: u64,
        /// Number of vertices.
        vertices: usize,
    },
    /// No (non-degenerate) triangle is left.
    #[error("mesh {file} has no triangles ({dropped} degenerate triangles dropped)")]
    NoTriangles {
        /// The file.
        file: PathBuf,
        /// Degenerate triangles dropped.
        dropped: usize,
    },
    /// The bounding box is flat along some axis: the surface encloses no volume.
    #[error(
        "mesh {file} has zero extent along {axis} (bounding box {min:?} .. {max:?}): it encloses no volume"
    )]
    ZeroExtent {
        /// The file.
        file: PathBuf,
        /// "x", "y" or "z".
        axis: &'static str,
        /// Bounding box minimum.
        min: [f64; 3],
        /// Bounding box maximum.
        max: [f64; 3],
    },
}

/// What cleaning did to a loaded mesh.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadReport {
    /// Vertices as read.
    pub vertices_read: usize,
    /// Triangles as read (after polygon triangulation).
    pub triangles_read: usize,
    /// Vertices removed by welding.
    pub vertices_welded: usize,
    /// Triangles dropped for a repeated vertex index.
    pub degenerate_repeated: usize,
    /// Triangles dropped for zero area.
    pub degenerate_zero_area: usize,
    /// Vertices not used by any triangle (kept, but ignored by everything else).
    pub unused_vertices: usize,
}

/// A loaded, cleaned mesh and what cleaning did.
#[derive(Debug, Clone)]
pub struct LoadedMesh {
    /// The cleaned mesh.
    pub mesh: TriMesh,
    /// Counts of what was read, welded and dropped.
    pub report: LoadReport,
}

/// A mesh file format, the plug point for new formats: implement it and
/// [`Loaders::register`](crate::load::Loaders::register) it.
///
/// Contract: [`load`](Self::load) parses the whole file's bytes into a raw
/// [`TriMesh`] and never panics; malformed input is a [`LoadError`] naming
/// `name` (and the line, where the format has lines). It does not need to
/// weld, drop degenerate triangles or check finiteness: [`clean_mesh`](crate::load::clean_mesh) does
/// that for every loader. See [`Loaders`](crate::load::Loaders) for an example.
pub trait MeshLoader: Send + Sync {
    /// File extensions served, lower case, without the dot.
    fn extensions(&self) -> &[&str];
    /// Parses `bytes` (the whole file) into a raw mesh; `name` is used in
    /// errors. Cleaning and checks are done by the caller.
    fn load(&self, bytes: &[u8], name: &str) -> Result<TriMesh, LoadError>;
    /// [`MeshLoader::load`] where what the file unpacks to may take at most
    /// `budget` bytes: a compressed format checks what its content declares
    /// before unpacking it, and refuses more. The default ignores the
    /// budget, right for a format that takes about its file's size.
    fn load_within(&self, bytes: &[u8], name: &str, budget: u64) -> Result<TriMesh, LoadError> {
        let _ = budget;
        self.load(bytes, name)
    }
}

/// A message on one line (a parser's text may span several).
#[cfg(any(feature = "ply", feature = "vtk"))]
pub(crate) fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A point as `[x, y, z]` with 4 significant digits.
fn fmt3(p: &[f64; 3]) -> String {
    format!("[{:.3e}, {:.3e}, {:.3e}]", p[0], p[1], p[2])
}
