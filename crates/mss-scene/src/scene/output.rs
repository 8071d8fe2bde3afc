//! `[output]`: what is written and when.

use std::path::PathBuf;

pub use mss_io::skin::Normals;
use serde::Deserialize;

use super::key::KeyError;

/// `[output]`: what is written and when.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Output folder, relative to the working directory (default `"out"`;
    /// the CLI's `--out` overrides it).
    #[serde(default = "default_folder")]
    pub folder: PathBuf,
    /// Lattice frames as XML `.vtu` (default true).
    #[serde(default = "yes")]
    pub vtu: bool,
    /// A `.pvd` collection listing the `.vtu` frames with their times (default true).
    #[serde(default = "yes")]
    pub pvd: bool,
    /// How `.vtu` arrays are stored: `"zlib"` (compressed, default: files
    /// about 4 times smaller) or `"none"` (base64 only: no compression work,
    /// a frame takes about a third less time where the disk keeps up).
    #[serde(default)]
    pub compression: CompressionKey,
    /// Lattice frames as legacy `.vtk` (default false).
    #[serde(default)]
    pub vtk: bool,
    /// Deformed lattice boundary skin as OBJ per frame (default false: the
    /// `.vtu` frames hold the lattice, whose boundary it is).
    #[serde(default)]
    pub skin_obj: bool,
    /// Deformed lattice boundary skin as binary STL per frame (default false).
    #[serde(default)]
    pub skin_stl: bool,
    /// The input surface carried by the lattice, per frame, in
    /// `surface_format` (default true).
    #[serde(default = "yes")]
    pub embedded: bool,
    /// How the embedded surface's frames are written: `"vtu"` (default:
    /// ZLib-compressed triangles with their `displacement`, listed with
    /// their times in `surface.pvd`, so that ParaView opens them as one
    /// series) or `"obj"` (a text OBJ per frame shaded by
    /// `surface_normals`, for tools that import OBJ; Blender plays the
    /// point cache of `pc2` instead).
    #[serde(default)]
    pub surface_format: SurfaceFormat,
    /// Shading of the skin OBJ files: `"flat"` (one normal per triangle,
    /// default: the skin is made of cube faces) or `"smooth"`.
    #[serde(default = "flat")]
    pub skin_normals: Normals,
    /// Shading of the embedded surface's OBJ files: `"smooth"` (default) or `"flat"`.
    #[serde(default)]
    pub surface_normals: Normals,
    /// Point caches for Blender's Mesh Cache modifier (default false):
    /// `skin.pc2` with its rest shape `skin_rest.obj`, and, with `embedded`,
    /// `surface.pc2` with `surface_rest.obj`; one sample per frame.
    #[serde(default)]
    pub pc2: bool,
    /// The springs as lines per frame, `springs_NNNN.vtu`, with cell data
    /// `strain` ((l - L0) / L0), `stiffness` (N/m), `rest_length` (m) and
    /// `diagonal`, plus `springs.pvd` when frames form a series (default false).
    #[serde(default)]
    pub springs: bool,
    /// Write a frame every this many steps (give this or `every_time`).
    pub every_steps: Option<u64>,
    /// Write a frame every this many simulated seconds (default: duration / 20).
    pub every_time: Option<f64>,
    /// Write only the final state (default false).
    #[serde(default)]
    pub last_only: bool,
    /// Write `checkpoint.mss`, the whole state of the run, every this many
    /// simulated seconds (default: never, but at an interruption), so that
    /// `mss run --resume FOLDER` continues it (time-stepping solvers only).
    pub checkpoint_every: Option<f64>,
    /// More lattice frame exporters, by the names a program registered in its
    /// [`Registry`](crate::Registry) (default none).
    #[serde(default)]
    pub exporters: Vec<String>,
}

/// `[output] compression`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum CompressionKey {
    /// ZLib-compressed blocks (VTK's `vtkZLibDataCompressor`).
    #[default]
    Zlib,
    /// Uncompressed.
    None,
}

/// `[output] surface_format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum SurfaceFormat {
    /// Compressed `.vtu` triangles and a `.pvd` (the skin exporter `vtu`).
    #[default]
    Vtu,
    /// Text OBJ per frame (the skin exporters `obj` and `obj-flat`).
    Obj,
}

impl OutputSection {
    /// The skin exporter that writes the embedded surface's frames.
    pub fn surface_exporter(&self) -> &'static str {
        match self.surface_format {
            SurfaceFormat::Vtu => "vtu",
            SurfaceFormat::Obj => obj_exporter(self.surface_normals),
        }
    }
}

impl CompressionKey {
    /// The `.vtu` encoding.
    pub fn encoding(self) -> mss_io::vtk::VtuEncoding {
        match self {
            CompressionKey::Zlib => mss_io::vtk::VtuEncoding::Base64Zlib,
            CompressionKey::None => mss_io::vtk::VtuEncoding::Base64,
        }
    }

    /// The lattice frame exporter for this compression, with or without
    /// the `.pvd` collection.
    pub fn vtu_exporter(self, pvd: bool) -> &'static str {
        match (self, pvd) {
            (CompressionKey::Zlib, true) => "vtu",
            (CompressionKey::Zlib, false) => "vtu-no-pvd",
            (CompressionKey::None, true) => "vtu-base64",
            (CompressionKey::None, false) => "vtu-base64-no-pvd",
        }
    }
}

/// The skin exporter that writes OBJ files shaded with `normals`.
pub fn obj_exporter(normals: Normals) -> &'static str {
    match normals {
        Normals::Smooth => "obj",
        Normals::Flat => "obj-flat",
    }
}

fn flat() -> Normals {
    Normals::Flat
}

fn default_folder() -> PathBuf {
    PathBuf::from("out")
}
fn yes() -> bool {
    true
}

impl Default for OutputSection {
    fn default() -> Self {
        Self {
            folder: default_folder(),
            vtu: true,
            pvd: true,
            compression: CompressionKey::Zlib,
            vtk: false,
            skin_obj: false,
            skin_stl: false,
            embedded: true,
            surface_format: SurfaceFormat::Vtu,
            skin_normals: Normals::Flat,
            surface_normals: Normals::Smooth,
            pc2: false,
            springs: false,
            every_steps: None,
            every_time: None,
            last_only: false,
            checkpoint_every: None,
            exporters: Vec::new(),
        }
    }
}

impl OutputSection {
    /// Checks the keys: a folder name, `.pvd` only with `.vtu`, named
    /// exporters non-empty, at least one kind of output, one frame
    /// schedule with positive values, a positive checkpoint interval.
    /// Whether `checkpoint_every` suits the solver is the scene's
    /// cross-table check.
    pub fn check(&self) -> Result<(), KeyError> {
        let bad = |key: &str, message: &str| Err(KeyError::new(key, message));
        if self.folder.as_os_str().is_empty() {
            return bad("folder", "is empty; give a folder name");
        }
        if self.pvd && !self.vtu {
            return bad(
                "pvd",
                "a .pvd collection lists .vtu frames: set vtu = true too, or pvd = false",
            );
        }
        if let Some(i) = self.exporters.iter().position(|n| n.trim().is_empty()) {
            return bad(
                "exporters",
                &format!("entry #{} is empty; give an exporter name", i + 1),
            );
        }
        if !(self.vtu
            || self.vtk
            || self.skin_obj
            || self.skin_stl
            || self.embedded
            || self.springs
            || !self.exporters.is_empty())
        {
            return bad(
                "",
                "every output kind is off; enable at least one of vtu, vtk, skin_obj, \
                 skin_stl, embedded, springs",
            );
        }
        match (self.every_steps, self.every_time) {
            (Some(_), Some(_)) => {
                return bad("", "give either every_steps or every_time, not both");
            }
            (Some(0), _) => return bad("every_steps", "= 0; must be at least 1"),
            (_, Some(t)) if !(t.is_finite() && t > 0.0) => {
                return bad("every_time", &format!("= {t}; must be a positive time (s)"));
            }
            _ => {}
        }
        if let Some(t) = self.checkpoint_every
            && !(t.is_finite() && t > 0.0)
        {
            return bad(
                "checkpoint_every",
                &format!("= {t}; must be a positive time (s)"),
            );
        }
        Ok(())
    }
}
