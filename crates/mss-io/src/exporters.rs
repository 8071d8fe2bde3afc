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
use crate::vtk::{FrameExporter, VtuEncoding, VtuSeries};
#[cfg(feature = "legacy-vtk")]
use crate::vtk::{LegacyFormat, LegacyVtkSeries};
use mss_registry::Named;

/// Creates a frame exporter writing `PREFIX_NNNN.*` files into a folder.
pub type FrameExporterFactory =
    Arc<dyn Fn(&Path, &str) -> Result<Box<dyn FrameExporter>, IoError> + Send + Sync>;

/// Creates a skin exporter writing `PREFIX_NNNN.*` (or `PREFIX.*`) files into a folder.
pub type SkinExporterFactory =
    Arc<dyn Fn(&Path, &str, SkinFrames) -> Result<Box<dyn SkinExporter>, IoError> + Send + Sync>;

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
/// triangle) and `stl` (binary).
#[derive(Clone)]
pub struct Exporters {
    frames: Named<FrameExporterFactory>,
    skins: Named<SkinExporterFactory>,
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
        e.register_frames("vtu", vtu(VtuEncoding::Base64Zlib, true));
        e.register_frames("vtu-no-pvd", vtu(VtuEncoding::Base64Zlib, false));
        e.register_frames("vtu-base64", vtu(VtuEncoding::Base64, true));
        e.register_frames("vtu-base64-no-pvd", vtu(VtuEncoding::Base64, false));
        e.register_frames("vtu-ascii", vtu(VtuEncoding::Ascii, true));
        #[cfg(feature = "legacy-vtk")]
        {
            e.register_frames("vtk", legacy(LegacyFormat::Binary));
            e.register_frames("vtk-ascii", legacy(LegacyFormat::Ascii));
        }
        e.register_skins("obj", skin(SkinFormat::Obj));
        e.register_skins("obj-flat", skin(SkinFormat::ObjFlat));
        e.register_skins("stl", skin(SkinFormat::Stl));
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
    /// Registers (or replaces) the frame exporter called `name`.
    pub fn register_frames(&mut self, name: &str, factory: FrameExporterFactory) {
        self.frames.register(name, factory);
    }

    /// Registers (or replaces) the skin exporter called `name`.
    pub fn register_skins(&mut self, name: &str, factory: SkinExporterFactory) {
        self.skins.register(name, factory);
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
        let factory = self
            .frames
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
        let factory = self
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
