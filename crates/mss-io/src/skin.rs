//! Skin (triangle surface) output: Wavefront OBJ with smooth (per-vertex) or
//! flat (per-triangle) normals and binary STL, plus exporter plugins for
//! writing skins per frame.
//!
//! Inputs are plain slices: `positions` (current vertex positions, e.g. a skin
//! deformed with the lattice) and `triangles` indexing them, counter-clockwise
//! seen from outside.
//!
//! ```
//! let positions = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
//! let triangles = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
//! let dir = tempfile::tempdir().unwrap();
//! mss_io::skin::write_obj(&dir.path().join("tet.obj"), &positions, &triangles).unwrap();
//! mss_io::skin::write_stl(&dir.path().join("tet.stl"), &positions, &triangles).unwrap();
//! ```

use crate::IoError;
use crate::atomic::{check_prefix, ensure_dir, write_atomic};
use crate::numfmt::write_f64;

use std::path::{Path, PathBuf};

/// Area-weighted vertex normals: each vertex gets the normalised sum of the
/// (area-scaled) normals of the triangles around it. Vertices without a
/// triangle of non-zero area get `[0, 0, 0]`.
///
/// Indices must be in range (the writers check this first).
pub fn vertex_normals(positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Vec<[f64; 3]> {
    let mut normals = vec![[0.0f64; 3]; positions.len()];
    for t in triangles {
        // The cross product's length is twice the area: exactly the weighting.
        let n = triangle_cross(positions, t);
        for &i in t {
            let acc = &mut normals[i as usize];
            for k in 0..3 {
                acc[k] += n[k];
            }
        }
    }
    for n in &mut normals {
        *n = normalized(*n);
    }
    normals
}

fn triangle_cross(positions: &[[f64; 3]], t: &[u32; 3]) -> [f64; 3] {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ]
}

fn normalized(n: [f64; 3]) -> [f64; 3] {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        n.map(|x| x / len)
    } else {
        [0.0; 3]
    }
}

fn validate(path: &Path, positions: &[[f64; 3]], triangles: &[[u32; 3]]) -> Result<(), IoError> {
    if triangles.is_empty() {
        return Err(IoError::invalid(path, "the skin has no triangles"));
    }
    let n = positions.len();
    if let Some((t, i)) = triangles
        .iter()
        .enumerate()
        .find_map(|(t, tri)| tri.iter().find(|&&i| i as usize >= n).map(|&i| (t, i)))
    {
        return Err(IoError::invalid(
            path,
            format!("triangle {t} refers to vertex {i} but there are only {n} vertices"),
        ));
    }
    Ok(())
}

/// How an OBJ skin is shaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize),
    serde(rename_all = "lowercase")
)]
pub enum Normals {
    /// One normal per vertex, area-weighted over its triangles
    /// ([`vertex_normals`]): smooth shading, right for a smooth input surface.
    #[default]
    Smooth,
    /// One normal per triangle: flat shading, right for the voxel skin, whose
    /// cube corners a smooth normal rounds into blobs.
    Flat,
}

/// Writes a Wavefront OBJ file with smooth normals ([`write_obj_with`]).
pub fn write_obj(
    path: &Path,
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
) -> Result<(), IoError> {
    write_obj_with(path, positions, triangles, Normals::Smooth)
}

/// Writes a Wavefront OBJ file, atomically: `v` lines with the positions
/// (shortest digits that parse back to exactly the same `f64`), in the
/// order given (so a point cache of the same vertices applies to it); then
/// for [`Normals::Smooth`] one `vn` per vertex and faces `f a//a b//b c//c`,
/// for [`Normals::Flat`] one `vn` per triangle, `s off` and faces
/// `f a//t b//t c//t` (1-based).
pub fn write_obj_with(
    path: &Path,
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
    normals: Normals,
) -> Result<(), IoError> {
    validate(path, positions, triangles)?;
    let normal_rows = match normals {
        Normals::Smooth => vertex_normals(positions, triangles),
        Normals::Flat => triangles
            .iter()
            .map(|t| normalized(triangle_cross(positions, t)))
            .collect(),
    };
    write_atomic(path, |w| {
        writeln!(
            w,
            "# hexahedral MSS skin: {} vertices, {} triangles",
            positions.len(),
            triangles.len()
        )?;
        for (tag, rows) in [(&b"v "[..], positions), (&b"vn "[..], &normal_rows[..])] {
            for p in rows {
                w.write_all(tag)?;
                write_f64(w, p[0])?;
                w.write_all(b" ")?;
                write_f64(w, p[1])?;
                w.write_all(b" ")?;
                write_f64(w, p[2])?;
                w.write_all(b"\n")?;
            }
        }
        match normals {
            Normals::Smooth => {
                for t in triangles {
                    let [a, b, c] = t.map(|i| u64::from(i) + 1);
                    writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
                }
            }
            Normals::Flat => {
                w.write_all(b"s off\n")?;
                for (k, t) in triangles.iter().enumerate() {
                    let [a, b, c] = t.map(|i| u64::from(i) + 1);
                    let n = k + 1;
                    writeln!(w, "f {a}//{n} {b}//{n} {c}//{n}")?;
                }
            }
        }
        Ok(())
    })
}

/// Header of the STL files written here. It must not start with `solid`, or
/// readers take the file for ASCII STL.
const STL_HEADER: &[u8] = b"binary STL: hexahedral MSS skin (mss-io)";

/// Writes a binary STL file, atomically: 80-byte header (not starting with
/// `solid`), triangle count, then per triangle its unit normal (from the `f64`
/// positions; zero for a degenerate triangle) and three vertices, all as
/// little-endian `f32`. Positions lose precision to `f32`, as the format
/// dictates.
pub fn write_stl(
    path: &Path,
    positions: &[[f64; 3]],
    triangles: &[[u32; 3]],
) -> Result<(), IoError> {
    validate(path, positions, triangles)?;
    let count = u32::try_from(triangles.len()).map_err(|_| {
        IoError::invalid(
            path,
            format!("{} triangles exceed the STL limit", triangles.len()),
        )
    })?;
    write_atomic(path, |w| {
        let mut header = [0u8; 80];
        header[..STL_HEADER.len()].copy_from_slice(STL_HEADER);
        w.write_all(&header)?;
        w.write_all(&count.to_le_bytes())?;
        let mut rec = [0u8; 50];
        for t in triangles {
            let n = normalized(triangle_cross(positions, t));
            let vecs = [
                n,
                positions[t[0] as usize],
                positions[t[1] as usize],
                positions[t[2] as usize],
            ];
            let floats = vecs.as_flattened();
            for (slot, &x) in rec[..48].chunks_exact_mut(4).zip(floats) {
                slot.copy_from_slice(&(x as f32).to_le_bytes());
            }
            // rec[48..50] is the attribute byte count: always 0.
            w.write_all(&rec)?;
        }
        Ok(())
    })
}

/// File format of a skin exporter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SkinFormat {
    /// Wavefront OBJ with vertex normals ([`write_obj`]).
    Obj,
    /// Wavefront OBJ with one normal per triangle ([`Normals::Flat`]).
    ObjFlat,
    /// Binary STL ([`write_stl`]).
    Stl,
}

impl SkinFormat {
    /// File extension without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            SkinFormat::Obj | SkinFormat::ObjFlat => "obj",
            SkinFormat::Stl => "stl",
        }
    }

    /// Writes one skin in this format.
    pub fn write(
        self,
        path: &Path,
        positions: &[[f64; 3]],
        triangles: &[[u32; 3]],
    ) -> Result<(), IoError> {
        match self {
            SkinFormat::Obj => write_obj(path, positions, triangles),
            SkinFormat::ObjFlat => write_obj_with(path, positions, triangles, Normals::Flat),
            SkinFormat::Stl => write_stl(path, positions, triangles),
        }
    }
}

/// Which frames a skin exporter keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SkinFrames {
    /// One file per frame: `PREFIX_NNNN.ext`.
    #[default]
    Every,
    /// One file `PREFIX.ext`, atomically replaced at every frame, so it always
    /// holds the latest complete skin (also after an interruption).
    LastOnly,
}

/// A writer of skins over a run, the plug point for skin formats, registered
/// by name in [`Exporters`](crate::exporters::Exporters).
///
/// Contract: the caller calls [`write_skin`](Self::write_skin) with strictly
/// increasing frame indices, then [`finish`](Self::finish) once. Every file is
/// complete when `write_skin` returns (write through
/// [`write_atomic`]), errors name the file, and
/// nothing panics on any input.
///
/// ```
/// use std::io::Write;
/// use std::path::PathBuf;
/// use mss_io::IoError;
/// use mss_io::skin::SkinExporter;
///
/// /// Writes each frame's vertices as `x y z` lines.
/// struct Xyz(PathBuf);
/// impl SkinExporter for Xyz {
///     fn name(&self) -> &'static str {
///         "xyz"
///     }
///     fn write_skin(&mut self, index: usize, _time: f64, positions: &[[f64; 3]], _triangles: &[[u32; 3]]) -> Result<(), IoError> {
///         let path = self.0.join(format!("skin_{index:04}.xyz"));
///         mss_io::atomic::write_atomic(&path, |w| {
///             positions.iter().try_for_each(|p| writeln!(w, "{} {} {}", p[0], p[1], p[2]))
///         })
///     }
///     fn finish(&mut self) -> Result<(), IoError> {
///         Ok(())
///     }
/// }
///
/// let dir = tempfile::tempdir().unwrap();
/// let mut e = Xyz(dir.path().to_path_buf());
/// e.write_skin(0, 0.0, &[[0.0, 1.0, 2.0]], &[]).unwrap();
/// e.finish().unwrap();
/// let text = std::fs::read_to_string(dir.path().join("skin_0000.xyz")).unwrap();
/// assert_eq!(text, "0 1 2\n");
/// ```
pub trait SkinExporter: Send {
    /// The name this exporter is registered under.
    fn name(&self) -> &'static str;
    /// Writes the skin of frame `frame_index` at simulated time `time`.
    fn write_skin(
        &mut self,
        frame_index: usize,
        time: f64,
        positions: &[[f64; 3]],
        triangles: &[[u32; 3]],
    ) -> Result<(), IoError>;
    /// Completes the series. Idempotent.
    fn finish(&mut self) -> Result<(), IoError>;
    /// Continues a series of which frames `0..frame_times.len()` are on disk
    /// already (a run resumed from a checkpoint): the next
    /// [`write_skin`](Self::write_skin) has index `frame_times.len()`. The
    /// default does nothing.
    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        let _ = frame_times;
        Ok(())
    }
    /// Frame times are round numbers to `decimals` decimals
    /// ([`crate::vtk::time_decimals`]): an index file may print them so. The
    /// default ignores it.
    fn set_time_decimals(&mut self, decimals: usize) {
        let _ = decimals;
    }
}

/// The built-in skin exporter: OBJ or STL files, every frame or the last one.
#[derive(Debug)]
pub struct SkinSeries {
    dir: PathBuf,
    prefix: String,
    format: SkinFormat,
    frames: SkinFrames,
    last_index: Option<usize>,
}

impl SkinSeries {
    /// A skin series in `dir` (created if missing) named after `prefix`.
    pub fn new(
        dir: &Path,
        prefix: &str,
        format: SkinFormat,
        frames: SkinFrames,
    ) -> Result<Self, IoError> {
        check_prefix(dir, prefix)?;
        ensure_dir(dir)?;
        Ok(SkinSeries {
            dir: dir.to_path_buf(),
            prefix: prefix.to_string(),
            format,
            frames,
            last_index: None,
        })
    }

    /// Path of the file for frame `frame_index`.
    pub fn frame_path(&self, frame_index: usize) -> PathBuf {
        let ext = self.format.extension();
        match self.frames {
            SkinFrames::Every => self
                .dir
                .join(format!("{}_{frame_index:04}.{ext}", self.prefix)),
            SkinFrames::LastOnly => self.dir.join(format!("{}.{ext}", self.prefix)),
        }
    }
}

impl SkinExporter for SkinSeries {
    fn name(&self) -> &'static str {
        match self.format {
            SkinFormat::ObjFlat => "obj-flat",
            other => other.extension(),
        }
    }

    fn write_skin(
        &mut self,
        frame_index: usize,
        time: f64,
        positions: &[[f64; 3]],
        triangles: &[[u32; 3]],
    ) -> Result<(), IoError> {
        let path = self.frame_path(frame_index);
        crate::vtk::check_index(self.last_index, frame_index, &path)?;
        log::debug!(
            "skin frame {frame_index} (t = {time}) -> {}",
            path.display()
        );
        self.format.write(&path, positions, triangles)?;
        self.last_index = Some(frame_index);
        Ok(())
    }

    fn finish(&mut self) -> Result<(), IoError> {
        Ok(())
    }

    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        self.last_index = frame_times.len().checked_sub(1);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_of_a_closed_tetrahedron_point_outwards() {
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let t = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let n = vertex_normals(&p, &t);
        // Vertex 3 = (0,0,1): area-weighted face normals (0,-1,0) + (-1,0,0)
        // + (1,1,1) (cross products, twice the areas) sum to (0,0,1).
        let expect = [0.0, 0.0, 1.0];
        for k in 0..3 {
            assert!((n[3][k] - expect[k]).abs() < 1e-15, "{:?}", n[3]);
        }
        // Vertex 0 at the origin: the three axis faces, equal areas.
        let s = -1.0 / 3f64.sqrt();
        for k in 0..3 {
            assert!((n[0][k] - s).abs() < 1e-15, "{:?}", n[0]);
        }
    }

    #[test]
    fn refuses_bad_indices_and_empty_skins() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.obj");
        let err = write_obj(&path, &[[0.0; 3]; 3], &[[0, 1, 3]]).unwrap_err();
        assert!(err.to_string().contains("vertex 3"), "{err}");
        assert!(write_stl(&path, &[[0.0; 3]; 3], &[]).is_err());
        assert!(!path.exists());
        assert!(
            crate::exporters::Exporters::default()
                .skins("ply", dir.path(), "s", SkinFrames::Every)
                .is_err()
        );
    }
}
