//! Frame exporters: plugins that write a time series of lattice frames.

use super::{Field, LatticeFrame, PvdWriter, VtuEncoding, write_triangles_vtu, write_vtu};
#[cfg(feature = "legacy-vtk")]
use super::{LegacyFormat, write_legacy_vtk};
use crate::IoError;
use crate::atomic::{check_prefix, ensure_dir};
use crate::skin::SkinExporter;
use std::path::{Path, PathBuf};

/// A writer of lattice frame series, the plug point for frame formats,
/// registered by name in [`Exporters`](crate::exporters::Exporters).
///
/// The caller calls [`write_frame`](Self::write_frame) with strictly
/// increasing frame indices, then [`finish`](Self::finish) once. Every file is
/// complete and valid as soon as `write_frame` returns, so an interrupted run
/// keeps all frames written so far.
pub trait FrameExporter: Send {
    /// The name this exporter is registered under.
    fn name(&self) -> &'static str;
    /// Writes frame number `frame_index` at simulated time `time`.
    fn write_frame(
        &mut self,
        frame_index: usize,
        time: f64,
        frame: &LatticeFrame,
    ) -> Result<(), IoError>;
    /// Completes the series (e.g. final index files). Idempotent.
    fn finish(&mut self) -> Result<(), IoError>;
    /// Continues a series of which frames `0..frame_times.len()`, at those
    /// times, are on disk already (a run resumed from a checkpoint): the
    /// next [`write_frame`](Self::write_frame) has index
    /// `frame_times.len()`, and index files list the earlier frames. The
    /// default does nothing, right for a series that keeps no index.
    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        let _ = frame_times;
        Ok(())
    }
    /// Frame times are round numbers to `decimals` decimals
    /// ([`super::time_decimals`]): an index file may print them so. The
    /// default ignores it.
    fn set_time_decimals(&mut self, decimals: usize) {
        let _ = decimals;
    }
}

/// Refuses frame indices that do not increase, which would list a frame twice
/// in a `.pvd` or silently overwrite an earlier file.
pub(crate) fn check_index(last: Option<usize>, index: usize, path: &Path) -> Result<(), IoError> {
    match last {
        Some(l) if index <= l => Err(IoError::invalid(
            path,
            format!("frame index {index} does not follow the previous frame index {l}"),
        )),
        _ => Ok(()),
    }
}

/// [`check_index`], and a finite `time`.
fn check_next(last: Option<usize>, index: usize, time: f64, path: &Path) -> Result<(), IoError> {
    check_index(last, index, path)?;
    if time.is_finite() {
        Ok(())
    } else {
        Err(IoError::invalid(
            path,
            format!("frame time {time} is not finite"),
        ))
    }
}

/// The frames a resumed series' index lists, `(time, file name)`, each
/// checked to be in `dir` still: a resumed run would otherwise end with an
/// index naming a lost file.
fn frames_on_disk(
    dir: &Path,
    frame_times: &[f64],
    file_name: impl Fn(usize) -> String,
) -> Result<Vec<(f64, String)>, IoError> {
    let entries: Vec<(f64, String)> = frame_times
        .iter()
        .enumerate()
        .map(|(i, &time)| (time, file_name(i)))
        .collect();
    if let Some((_, missing)) = entries.iter().find(|(_, name)| !dir.join(name).is_file()) {
        return Err(IoError::invalid(
            &dir.join(missing),
            "this frame, written before the checkpoint, is missing: the folder \
             changed since; run the scene again without --resume",
        ));
    }
    Ok(entries)
}

/// XML `.vtu` series: `DIR/PREFIX_NNNN.vtu` per frame and `DIR/PREFIX.pvd`
/// listing them with their times (rewritten after every frame; see
/// [`VtuSeries::without_pvd`]).
#[derive(Debug)]
pub struct VtuSeries {
    dir: PathBuf,
    prefix: String,
    encoding: VtuEncoding,
    pvd: PvdWriter,
    write_pvd: bool,
    last_index: Option<usize>,
}

impl VtuSeries {
    /// A series in `dir` (created if missing) named after `prefix`.
    pub fn new(dir: &Path, prefix: &str, encoding: VtuEncoding) -> Result<Self, IoError> {
        check_prefix(dir, prefix)?;
        ensure_dir(dir)?;
        Ok(VtuSeries {
            dir: dir.to_path_buf(),
            prefix: prefix.to_string(),
            encoding,
            pvd: PvdWriter::new(dir.join(format!("{prefix}.pvd"))),
            write_pvd: true,
            last_index: None,
        })
    }

    /// The same series without the `.pvd` file (`[output] pvd = false`): only
    /// the numbered `.vtu` frames are written, and [`VtuSeries::pvd`] stays
    /// empty.
    pub fn without_pvd(mut self) -> Self {
        self.write_pvd = false;
        self
    }

    /// File name of frame `frame_index` (relative to the folder).
    pub fn frame_file_name(&self, frame_index: usize) -> String {
        format!("{}_{frame_index:04}.vtu", self.prefix)
    }

    /// The `.pvd` collection of the frames written so far.
    pub fn pvd(&self) -> &PvdWriter {
        &self.pvd
    }
}

impl FrameExporter for VtuSeries {
    fn set_time_decimals(&mut self, decimals: usize) {
        self.pvd.set_time_decimals(Some(decimals));
    }

    fn name(&self) -> &'static str {
        match self.encoding {
            VtuEncoding::Base64Zlib => "vtu",
            VtuEncoding::Base64 => "vtu-base64",
            VtuEncoding::Ascii => "vtu-ascii",
        }
    }

    fn write_frame(
        &mut self,
        frame_index: usize,
        time: f64,
        frame: &LatticeFrame,
    ) -> Result<(), IoError> {
        let file = self.frame_file_name(frame_index);
        let path = self.dir.join(&file);
        check_next(self.last_index, frame_index, time, &path)?;
        write_vtu(&path, frame, self.encoding)?;
        if self.write_pvd {
            self.pvd.add_frame(time, &file)?;
        }
        self.last_index = Some(frame_index);
        Ok(())
    }

    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        if self.write_pvd {
            let entries = frames_on_disk(&self.dir, frame_times, |i| self.frame_file_name(i))?;
            self.pvd.set_frames(entries)?;
        }
        self.last_index = frame_times.len().checked_sub(1);
        Ok(())
    }

    fn finish(&mut self) -> Result<(), IoError> {
        if self.write_pvd && self.pvd.entries().is_empty() {
            log::warn!(
                "no frame written; {} not created",
                self.pvd.path().display()
            );
        }
        Ok(())
    }
}

/// Legacy `.vtk` series: `DIR/PREFIX_NNNN.vtk` per frame (ParaView groups
/// numbered files into a series; the legacy format cannot be listed in a
/// `.pvd`). The simulated time is written in each file's title line.
#[cfg(feature = "legacy-vtk")]
#[derive(Debug)]
pub struct LegacyVtkSeries {
    dir: PathBuf,
    prefix: String,
    format: LegacyFormat,
    last_index: Option<usize>,
}

#[cfg(feature = "legacy-vtk")]
impl LegacyVtkSeries {
    /// A series in `dir` (created if missing) named after `prefix`.
    pub fn new(dir: &Path, prefix: &str, format: LegacyFormat) -> Result<Self, IoError> {
        check_prefix(dir, prefix)?;
        ensure_dir(dir)?;
        Ok(LegacyVtkSeries {
            dir: dir.to_path_buf(),
            prefix: prefix.to_string(),
            format,
            last_index: None,
        })
    }

    /// File name of frame `frame_index` (relative to the folder).
    pub fn frame_file_name(&self, frame_index: usize) -> String {
        format!("{}_{frame_index:04}.vtk", self.prefix)
    }
}

#[cfg(feature = "legacy-vtk")]
impl FrameExporter for LegacyVtkSeries {
    fn name(&self) -> &'static str {
        match self.format {
            LegacyFormat::Binary => "vtk",
            LegacyFormat::Ascii => "vtk-ascii",
        }
    }

    fn write_frame(
        &mut self,
        frame_index: usize,
        time: f64,
        frame: &LatticeFrame,
    ) -> Result<(), IoError> {
        let path = self.dir.join(self.frame_file_name(frame_index));
        check_index(self.last_index, frame_index, &path)?;
        let title = format!("hexahedral MSS frame {frame_index} time {time}");
        write_legacy_vtk(&path, frame, self.format, &title)?;
        self.last_index = Some(frame_index);
        Ok(())
    }

    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        self.last_index = frame_times.len().checked_sub(1);
        Ok(())
    }

    fn finish(&mut self) -> Result<(), IoError> {
        Ok(())
    }
}

/// A surface series as compressed XML `.vtu` of triangles, the skin
/// exporter `vtu`: `DIR/PREFIX_NNNN.vtu` per frame, with the point field
/// `displacement` from the first frame (the rest shape), and `DIR/PREFIX.pvd`
/// listing them with their times (rewritten after every frame), so that
/// ParaView opens the surface as one series, like the lattice's.
#[derive(Debug)]
pub struct SurfaceVtuSeries {
    dir: PathBuf,
    prefix: String,
    pvd: PvdWriter,
    /// The first frame's positions, which displacements are measured from.
    rest: Option<Vec<[f64; 3]>>,
    displacement: Vec<[f64; 3]>,
    last_index: Option<usize>,
}

impl SurfaceVtuSeries {
    /// A series in `dir` (created if missing) named after `prefix`.
    pub fn new(dir: &Path, prefix: &str) -> Result<Self, IoError> {
        check_prefix(dir, prefix)?;
        ensure_dir(dir)?;
        Ok(SurfaceVtuSeries {
            dir: dir.to_path_buf(),
            prefix: prefix.to_string(),
            pvd: PvdWriter::new(dir.join(format!("{prefix}.pvd"))),
            rest: None,
            displacement: Vec::new(),
            last_index: None,
        })
    }

    /// File name of frame `frame_index` (relative to the folder).
    pub fn frame_file_name(&self, frame_index: usize) -> String {
        format!("{}_{frame_index:04}.vtu", self.prefix)
    }
}

/// Largest surface frame read back when a run resumes (bytes).
#[cfg(feature = "read")]
const MAX_SURFACE_FRAME_BYTES: u64 = 4 << 30;

impl SkinExporter for SurfaceVtuSeries {
    fn name(&self) -> &'static str {
        "vtu"
    }

    fn write_skin(
        &mut self,
        frame_index: usize,
        time: f64,
        positions: &[[f64; 3]],
        triangles: &[[u32; 3]],
    ) -> Result<(), IoError> {
        let file = self.frame_file_name(frame_index);
        let path = self.dir.join(&file);
        check_next(self.last_index, frame_index, time, &path)?;
        let rest = self.rest.get_or_insert_with(|| positions.to_vec());
        if rest.len() != positions.len() {
            return Err(IoError::invalid(
                &path,
                format!(
                    "{} vertices, where the first frame had {}",
                    positions.len(),
                    rest.len()
                ),
            ));
        }
        self.displacement.clear();
        self.displacement.extend(
            positions
                .iter()
                .zip(rest.iter())
                .map(|(p, r)| [p[0] - r[0], p[1] - r[1], p[2] - r[2]]),
        );
        write_triangles_vtu(
            &path,
            positions,
            triangles,
            &[Field::vectors("displacement", &self.displacement)],
            VtuEncoding::Base64Zlib,
        )?;
        self.pvd.add_frame(time, &file)?;
        self.last_index = Some(frame_index);
        Ok(())
    }

    fn finish(&mut self) -> Result<(), IoError> {
        Ok(())
    }

    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        let entries = frames_on_disk(&self.dir, frame_times, |i| self.frame_file_name(i))?;
        if let Some((_, first)) = entries.first() {
            // Displacements go on from the first frame's positions.
            let path = self.dir.join(first);
            #[cfg(feature = "read")]
            {
                let frame = super::read::read_surface_vtu(&path, MAX_SURFACE_FRAME_BYTES)
                    .map_err(|e| IoError::invalid(&path, format!("cannot resume from it: {e}")))?;
                self.rest = Some(frame.points);
            }
            #[cfg(not(feature = "read"))]
            return Err(IoError::invalid(
                &path,
                "resuming a surface series reads its first frame: mss-io needs its `read` feature",
            ));
        }
        self.pvd.set_frames(entries)?;
        self.last_index = frame_times.len().checked_sub(1);
        Ok(())
    }

    fn set_time_decimals(&mut self, decimals: usize) {
        self.pvd.set_time_decimals(Some(decimals));
    }
}
