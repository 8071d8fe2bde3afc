//! Frame exporters: plugins that write a time series of lattice frames.

use super::{LatticeFrame, PvdWriter, VtuEncoding, write_vtu};
#[cfg(feature = "legacy-vtk")]
use super::{LegacyFormat, write_legacy_vtk};
use crate::IoError;
use crate::atomic::{check_prefix, ensure_dir};
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
fn check_index(last: Option<usize>, index: usize, path: &Path) -> Result<(), IoError> {
    match last {
        Some(l) if index <= l => Err(IoError::invalid(
            path,
            format!("frame index {index} does not follow the previous frame index {l}"),
        )),
        _ => Ok(()),
    }
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
        check_index(self.last_index, frame_index, &path)?;
        if !time.is_finite() {
            return Err(IoError::invalid(
                &path,
                format!("frame time {time} is not finite"),
            ));
        }
        write_vtu(&path, frame, self.encoding)?;
        if self.write_pvd {
            self.pvd.add_frame(time, &file)?;
        }
        self.last_index = Some(frame_index);
        Ok(())
    }

    fn resume(&mut self, frame_times: &[f64]) -> Result<(), IoError> {
        let entries = frame_times
            .iter()
            .enumerate()
            .map(|(i, &time)| (time, self.frame_file_name(i)))
            .collect::<Vec<_>>();
        if self.write_pvd {
            // The collection lists every frame: each must still be there,
            // or the resumed run would end with a .pvd naming a lost file.
            if let Some((_, missing)) = entries
                .iter()
                .find(|(_, name)| !self.dir.join(name).is_file())
            {
                return Err(IoError::invalid(
                    &self.dir.join(missing),
                    "this frame, written before the checkpoint, is missing: the folder \
                     changed since; run the scene again without --resume",
                ));
            }
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
