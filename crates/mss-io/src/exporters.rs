//! The exporters a program knows, by name: lattice frame series
//! ([`FrameExporter`]) and skin series ([`SkinExporter`]).
//!
//! [`Exporters`] is a value (no global state): a program starts from
//! [`Exporters::default`] (the built-ins), registers its own, and passes it
//! to whatever writes output (`mss-scene` keeps it in its `Registry`).
//!
//! ```
//! use std::sync::Arc;
//! use mss_io::exporters::Exporters;
//! use mss_io::vtk::{FrameExporter, LatticeFrame};
//! use mss_io::IoError;
//!
//! /// Counts frames instead of writing them (a custom exporter).
//! struct Counter(usize);
//! impl FrameExporter for Counter {
//!     fn name(&self) -> &'static str {
//!         "counter"
//!     }
//!     fn write_frame(&mut self, _index: usize, _time: f64, _frame: &LatticeFrame) -> Result<(), IoError> {
//!         self.0 += 1;
//!         Ok(())
//!     }
//!     fn finish(&mut self) -> Result<(), IoError> {
//!         Ok(())
//!     }
//! }
//!
//! let mut exporters = Exporters::default();
//! exporters.register_frames("counter", Arc::new(|_dir, _prefix| Ok(Box::new(Counter(0)))));
//! let dir = tempfile::tempdir().unwrap();
//! let mut e = exporters.frames("counter", dir.path(), "lattice").unwrap();
//! assert_eq!(e.name(), "counter");
//! let points = [[0.0; 3]; 8];
//! e.write_frame(0, 0.0, &LatticeFrame::new(&points, &[[0, 1, 2, 3, 4, 5, 6, 7]])).unwrap();
//! e.finish().unwrap();
//! let err = exporters.frames("vtp", dir.path(), "lattice").err().unwrap().to_string();
//! assert!(err.contains("vtu") && err.contains("counter"), "{err}");
//! ```

use std::path::Path;
use std::sync::Arc;

use crate::IoError;
use crate::skin::{SkinExporter, SkinFormat, SkinFrames, SkinSeries};
use crate::vtk::{FrameExporter, SurfaceVtuSeries, VtuEncoding, VtuSeries};
#[cfg(feature = "legacy-vtk")]
use crate::vtk::{LegacyFormat, LegacyVtkSeries};
use mss_registry::Named;

/// Creates a frame exporter writing `PREFIX_NNNN.*` files into a folder.
pub type FrameExporterFactory =
    Arc<dyn Fn(&Path, &str) -> Result<Box<dyn FrameExporter>, IoError> + Send + Sync>;

/// Creates a skin exporter writing `PREFIX_NNNN.*` (or `PREFIX.*`) files into a folder.
pub type SkinExporterFactory =
    Arc<dyn Fn(&Path, &str, SkinFrames) -> Result<Box<dyn SkinExporter>, IoError> + Send + Sync>;

/// What a registered exporter writes, known without building it: the
/// extension of its numbered files (`PREFIX_NNNN.EXT`), the index file it
/// keeps beside them, and an estimate of one file's size. A program's
/// output folder is recognised from these (a new run there removes the
/// files an earlier one left), and disk space is estimated from them
/// before a run starts.
#[derive(Debug, Clone, Copy)]
pub struct SeriesFacts {
    /// Extension of the numbered files, without the dot.
    pub extension: &'static str,
    /// Extension of the index file `PREFIX.EXT` listing them (`"pvd"`), if any.
    pub index_extension: Option<&'static str>,
    /// Estimated bytes of one file: for a lattice frame from its nodes and
    /// cells, for a skin from its vertices and triangles.
    pub bytes: fn(usize, usize) -> u64,
}

/// Bytes of a lattice frame's arrays, uncompressed: per node the points
/// and four more vectors, a flag and a vector of f64; per cell its 8
/// connectivity ids, an offset, a type and three f64 fields.
fn lattice_bytes(nodes: usize, cells: usize) -> u64 {
    (nodes * (5 * 24 + 1 + 24) + cells * (32 + 8 + 1 + 3 * 8)) as u64
}

/// An uncompressed `.vtu`: the raw arrays in base64.
fn vtu_base64_bytes(nodes: usize, cells: usize) -> u64 {
    lattice_bytes(nodes, cells) * 4 / 3
}

/// A ZLib-compressed `.vtu` in base64 takes about the raw arrays' size
/// (0.92 of it measured on the default job's frames: the positions and
/// forces compress little, the flags and the connectivity much).
fn vtu_zlib_bytes(nodes: usize, cells: usize) -> u64 {
    lattice_bytes(nodes, cells)
}

/// Text numbers take about three times their binary bytes.
fn text_bytes(nodes: usize, cells: usize) -> u64 {
    lattice_bytes(nodes, cells) * 3
}

/// A surface `.vtu`: per vertex a Float64 position and displacement, per
/// triangle three Int64 nodes, an offset and a type, ZLib-compressed to
/// about 0.6 of that (smooth surfaces; measured on the default job's
/// frames), base64 adding a third.
fn surface_vtu_bytes(vertices: usize, triangles: usize) -> u64 {
    ((vertices * 48 + triangles * 33) as u64) * 4 / 5 + 1200
}

/// A `v` or `vn` line of shortest-round-trip coordinates is about 60
/// bytes, an `f` line with vertex normals (`f a//a b//b c//c`) about 36:
/// per vertex a `v` and a `vn`, per triangle an `f` (measured on the
/// default job's surface: within 1 %).
fn obj_smooth_bytes(vertices: usize, triangles: usize) -> u64 {
    (vertices * 120 + triangles * 36) as u64
}

/// One `v` line per vertex; per triangle a `vn` line and an `f` line.
fn obj_flat_bytes(vertices: usize, triangles: usize) -> u64 {
    (vertices * 60 + triangles * 96) as u64
}

/// Binary STL: an 84-byte header, 50 bytes per triangle.
fn stl_bytes(_vertices: usize, triangles: usize) -> u64 {
    (84 + triangles * 50) as u64
}

/// Frame and skin exporters by name. The built-ins:
///
/// | frames | what |
/// |---|---|
/// | `vtu` | XML `.vtu`, ZLib-compressed, and a `.pvd` listing the frames with their times |
/// | `vtu-no-pvd` | the same frames without the `.pvd` |
/// | `vtu-base64` | uncompressed `.vtu` and `.pvd` |
/// | `vtu-base64-no-pvd` | uncompressed `.vtu` frames only |
/// | `vtu-ascii` | text `.vtu` and `.pvd` |
/// | `vtk` | legacy binary `.vtk` |
/// | `vtk-ascii` | legacy text `.vtk` |
///
/// Skins: `obj` (smooth: vertex normals), `obj-flat` (one normal per
/// triangle), `stl` (binary) and `vtu` (ZLib-compressed triangles with
/// their displacement, and a `.pvd` listing the frames; ParaView opens the
/// series as one, like the lattice's).
#[derive(Clone)]
pub struct Exporters {
    frames: Named<(FrameExporterFactory, Option<SeriesFacts>)>,
    skins: Named<(SkinExporterFactory, Option<SeriesFacts>)>,
}

fn vtu(encoding: VtuEncoding, pvd: bool) -> FrameExporterFactory {
    Arc::new(move |dir: &Path, prefix: &str| {
        let series = VtuSeries::new(dir, prefix, encoding)?;
        Ok(Box::new(if pvd { series } else { series.without_pvd() }) as Box<dyn FrameExporter>)
    })
}

#[cfg(feature = "legacy-vtk")]
fn legacy(format: LegacyFormat) -> FrameExporterFactory {
    Arc::new(move |dir: &Path, prefix: &str| {
        Ok(Box::new(LegacyVtkSeries::new(dir, prefix, format)?) as Box<dyn FrameExporter>)
    })
}

fn skin(format: SkinFormat) -> SkinExporterFactory {
    Arc::new(move |dir: &Path, prefix: &str, frames: SkinFrames| {
        Ok(Box::new(SkinSeries::new(dir, prefix, format, frames)?) as Box<dyn SkinExporter>)
    })
}

impl Default for Exporters {
    fn default() -> Self {
        let mut e = Self {
            frames: Named::new(),
            skins: Named::new(),
        };
        let facts = |extension, index_extension, bytes| SeriesFacts {
            extension,
            index_extension,
            bytes,
        };
        let pvd = Some("pvd");
        // Each encoding with and without its .pvd: `vtu`, `vtu-no-pvd`, ...
        for (stem, encoding, bytes) in [
            (
                "vtu",
                VtuEncoding::Base64Zlib,
                vtu_zlib_bytes as fn(usize, usize) -> u64,
            ),
            ("vtu-base64", VtuEncoding::Base64, vtu_base64_bytes),
        ] {
            e.register_frames_with(stem, facts("vtu", pvd, bytes), vtu(encoding, true));
            e.register_frames_with(
                &format!("{stem}-no-pvd"),
                facts("vtu", None, bytes),
                vtu(encoding, false),
            );
        }
        e.register_frames_with(
            "vtu-ascii",
            facts("vtu", pvd, text_bytes),
            vtu(VtuEncoding::Ascii, true),
        );
        #[cfg(feature = "legacy-vtk")]
        {
            e.register_frames_with(
                "vtk",
                facts("vtk", None, lattice_bytes),
                legacy(LegacyFormat::Binary),
            );
            e.register_frames_with(
                "vtk-ascii",
                facts("vtk", None, text_bytes),
                legacy(LegacyFormat::Ascii),
            );
        }
        e.register_skins_with(
            "obj",
            facts("obj", None, obj_smooth_bytes),
            skin(SkinFormat::Obj),
        );
        e.register_skins_with(
            "obj-flat",
            facts("obj", None, obj_flat_bytes),
            skin(SkinFormat::ObjFlat),
        );
        e.register_skins_with("stl", facts("stl", None, stl_bytes), skin(SkinFormat::Stl));
        e.register_skins_with(
            "vtu",
            facts("vtu", pvd, surface_vtu_bytes),
            Arc::new(|dir: &Path, prefix: &str, _frames: SkinFrames| {
                Ok(Box::new(SurfaceVtuSeries::new(dir, prefix)?) as Box<dyn SkinExporter>)
            }),
        );
        e
    }
}

impl std::fmt::Debug for Exporters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Exporters")
            .field("frames", &self.frame_names())
            .field("skins", &self.skin_names())
            .finish()
    }
}

impl Exporters {
    /// Registers (or replaces) the frame exporter called `name`, whose
    /// files are not known by name (a run does not count or remove them)
    /// and whose size is not estimated.
    pub fn register_frames(&mut self, name: &str, factory: FrameExporterFactory) {
        self.frames.register(name, (factory, None));
    }

    /// Registers (or replaces) the frame exporter called `name`, writing
    /// the files `facts` describe.
    pub fn register_frames_with(
        &mut self,
        name: &str,
        facts: SeriesFacts,
        factory: FrameExporterFactory,
    ) {
        self.frames.register(name, (factory, Some(facts)));
    }

    /// Registers (or replaces) the skin exporter called `name` (files not
    /// known by name, size not estimated).
    pub fn register_skins(&mut self, name: &str, factory: SkinExporterFactory) {
        self.skins.register(name, (factory, None));
    }

    /// Registers (or replaces) the skin exporter called `name`, writing the
    /// files `facts` describe.
    pub fn register_skins_with(
        &mut self,
        name: &str,
        facts: SeriesFacts,
        factory: SkinExporterFactory,
    ) {
        self.skins.register(name, (factory, Some(facts)));
    }

    /// What the frame exporter `name` writes, if it is registered with facts.
    pub fn frame_facts(&self, name: &str) -> Option<SeriesFacts> {
        self.frames.get(name).and_then(|(_, facts)| *facts)
    }

    /// What the skin exporter `name` writes, if it is registered with facts.
    pub fn skin_facts(&self, name: &str) -> Option<SeriesFacts> {
        self.skins.get(name).and_then(|(_, facts)| *facts)
    }

    /// The facts of every frame exporter registered with them.
    pub fn all_frame_facts(&self) -> Vec<SeriesFacts> {
        self.frames.iter().filter_map(|(_, (_, f))| *f).collect()
    }

    /// The facts of every skin exporter registered with them.
    pub fn all_skin_facts(&self) -> Vec<SeriesFacts> {
        self.skins.iter().filter_map(|(_, (_, f))| *f).collect()
    }

    /// Names of the frame exporters, in registration order.
    pub fn frame_names(&self) -> Vec<String> {
        self.frames.names()
    }

    /// Names of the skin exporters, in registration order.
    pub fn skin_names(&self) -> Vec<String> {
        self.skins.names()
    }

    /// Creates the frame exporter `name` writing into `dir` (created if
    /// missing) with file names `PREFIX_NNNN.ext`.
    pub fn frames(
        &self,
        name: &str,
        dir: &Path,
        prefix: &str,
    ) -> Result<Box<dyn FrameExporter>, IoError> {
        let (factory, _) =
            self.frames
                .lookup(name)
                .map_err(|unknown| IoError::UnknownExporter {
                    kind: "frame",
                    name: unknown.name,
                    known: unknown.known,
                })?;
        factory(dir, prefix)
    }

    /// Creates the skin exporter `name` writing into `dir` (created if missing).
    pub fn skins(
        &self,
        name: &str,
        dir: &Path,
        prefix: &str,
        frames: SkinFrames,
    ) -> Result<Box<dyn SkinExporter>, IoError> {
        let (factory, _) = self
            .skins
            .lookup(name)
            .map_err(|unknown| IoError::UnknownExporter {
                kind: "skin",
                name: unknown.name,
                known: unknown.known,
            })?;
        factory(dir, prefix, frames)
    }
}
