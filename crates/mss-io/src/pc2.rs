//! PC2 point caches: every frame's vertex positions of one surface in one
//! file, the format Blender's Mesh Cache modifier (and 3ds Max, Maya through
//! plug-ins) reads.
//!
//! Layout (little-endian): the 12 bytes `POINTCACHE2\0`, `i32` version 1,
//! `i32` number of points, `f32` start frame, `f32` sample rate, `i32`
//! number of samples; then per sample, per point, `x y z` as `f32`. The
//! points are in the order of the mesh the cache belongs to, so it is
//! always written beside that mesh's rest shape (an OBJ with the same
//! vertices in the same order).
//!
//! [`Pc2Writer`] appends frames to a temporary file in the destination
//! folder and renames it to the final name in [`Pc2Writer::finish`]: the
//! final name never holds a half-written cache. The header's sample count is
//! updated after each frame's data, so even the temporary file is a valid
//! cache of the frames written so far.
//!
//! ```
//! use mss_io::pc2::{Pc2Writer, read_pc2};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("skin.pc2");
//! let mut w = Pc2Writer::create(&path, 2, 0.0, 1.0).unwrap();
//! w.append(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]).unwrap();
//! w.append(&[[0.0, 0.0, -0.5], [1.0, 0.0, -0.25]]).unwrap();
//! assert!(!path.exists()); // not before finish
//! w.finish().unwrap();
//! let cache = read_pc2(&path).unwrap();
//! assert_eq!((cache.num_points, cache.frames.len()), (2, 2));
//! assert_eq!(cache.frames[1][1], [1.0, 0.0, -0.25]);
//! ```

use std::fs::{self, File};
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::IoError;
use crate::atomic::create_temporary;

/// The PC2 signature.
const MAGIC: &[u8; 12] = b"POINTCACHE2\0";
/// Bytes of the header.
const HEADER_BYTES: u64 = 32;
/// Offset of the sample count in the header.
const SAMPLES_OFFSET: u64 = 28;

/// A point cache being written (see the module documentation).
#[derive(Debug)]
pub struct Pc2Writer {
    path: PathBuf,
    temp: PathBuf,
    file: Option<BufWriter<File>>,
    num_points: usize,
    samples: u32,
}

impl Pc2Writer {
    /// Starts a cache of `num_points` points at `path` (written to a
    /// temporary file until [`finish`](Self::finish)); `start_frame` and
    /// `sample_rate` go into the header (frame of the first sample, frames
    /// per sample).
    pub fn create(
        path: &Path,
        num_points: usize,
        start_frame: f32,
        sample_rate: f32,
    ) -> Result<Self, IoError> {
        let points = i32::try_from(num_points).map_err(|_| {
            IoError::invalid(path, format!("{num_points} points exceed the PC2 limit"))
        })?;
        let mut writer = Self::start(path, num_points, 0)?;
        let mut header = Vec::with_capacity(HEADER_BYTES as usize);
        header.extend_from_slice(MAGIC);
        header.extend_from_slice(&1i32.to_le_bytes());
        header.extend_from_slice(&points.to_le_bytes());
        header.extend_from_slice(&start_frame.to_le_bytes());
        header.extend_from_slice(&sample_rate.to_le_bytes());
        header.extend_from_slice(&0i32.to_le_bytes());
        writer.with_file(|f| f.write_all(&header))?;
        Ok(writer)
    }

    /// Continues the cache at `path` (a finished file of a run resumed from
    /// a checkpoint) after its first `samples` frames: they are copied into
    /// a new temporary file, the rest is dropped, and later frames are
    /// appended as by [`create`](Self::create)'s writer. The file must hold
    /// `num_points` points and at least `samples` frames.
    pub fn resume(path: &Path, num_points: usize, samples: u32) -> Result<Self, IoError> {
        let bad = |why: String| IoError::invalid(path, why);
        let mut old = File::open(path).map_err(|e| IoError::io(path, e))?;
        let mut header = [0u8; HEADER_BYTES as usize];
        old.read_exact(&mut header)
            .map_err(|_| bad("too short for a PC2 header".into()))?;
        if &header[..12] != MAGIC {
            return Err(bad("not a PC2 point cache".into()));
        }
        let field = |at: usize| i32::from_le_bytes(header[at..at + 4].try_into().unwrap_or([0; 4]));
        let (points, have) = (field(16), field(SAMPLES_OFFSET as usize));
        if usize::try_from(points).ok() != Some(num_points) {
            return Err(bad(format!(
                "holds {points} points per frame, the run {num_points}"
            )));
        }
        if u32::try_from(have).map_or(true, |h| h < samples) {
            return Err(bad(format!(
                "holds {have} frames, the checkpoint needs {samples}"
            )));
        }
        let frame_bytes = 12 * num_points as u64;
        let mut writer = Self::start(path, num_points, samples)?;
        header[SAMPLES_OFFSET as usize..].copy_from_slice(&(samples as i32).to_le_bytes());
        writer.with_file(|f| {
            f.write_all(&header)?;
            let copied = std::io::copy(&mut (&mut old).take(frame_bytes * u64::from(samples)), f)?;
            if copied != frame_bytes * u64::from(samples) {
                return Err(std::io::Error::other("the file ends inside a frame"));
            }
            f.flush()
        })?;
        Ok(writer)
    }

    /// A writer on a new temporary file beside `path`, counting `samples`
    /// frames already in it.
    fn start(path: &Path, num_points: usize, samples: u32) -> Result<Self, IoError> {
        let file_name = path
            .file_name()
            .ok_or_else(|| IoError::invalid(path, "the output path has no file name"))?;
        let (temp, file) = create_temporary(path, file_name)?;
        Ok(Pc2Writer {
            path: path.to_path_buf(),
            temp,
            file: Some(BufWriter::with_capacity(1 << 20, file)),
            num_points,
            samples,
        })
    }

    fn with_file(
        &mut self,
        op: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
    ) -> Result<(), IoError> {
        let Some(file) = self.file.as_mut() else {
            return Err(IoError::invalid(
                &self.path,
                "the point cache is already finished",
            ));
        };
        op(file).map_err(|e| IoError::io(&self.path, e))
    }

    /// Appends one frame: exactly the cache's number of points, stored as `f32`.
    pub fn append(&mut self, positions: &[[f64; 3]]) -> Result<(), IoError> {
        if positions.len() != self.num_points {
            return Err(IoError::invalid(
                &self.path,
                format!(
                    "frame {} has {} points, the cache {}",
                    self.samples,
                    positions.len(),
                    self.num_points
                ),
            ));
        }
        let samples = self
            .samples
            .checked_add(1)
            .filter(|&s| i32::try_from(s).is_ok())
            .ok_or_else(|| IoError::invalid(&self.path, "too many frames for a PC2 file"))?;
        self.with_file(|f| {
            let mut bytes = Vec::with_capacity(12 * positions.len());
            for p in positions {
                for c in p {
                    bytes.extend_from_slice(&(*c as f32).to_le_bytes());
                }
            }
            f.write_all(&bytes)?;
            // Count the frame only once its data is written.
            f.flush()?;
            let file = f.get_mut();
            file.seek(SeekFrom::Start(SAMPLES_OFFSET))?;
            file.write_all(&(samples as i32).to_le_bytes())?;
            file.seek(SeekFrom::End(0))?;
            Ok(())
        })?;
        self.samples = samples;
        Ok(())
    }

    /// Frames written so far.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Whether [`finish`](Self::finish) was called.
    pub fn is_finished(&self) -> bool {
        self.file.is_none()
    }

    /// The final path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes the cache and renames it to its final name. Idempotent.
    pub fn finish(&mut self) -> Result<(), IoError> {
        let Some(file) = self.file.take() else {
            return Ok(());
        };
        let result = file
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_data().or(Ok(())))
            .map_err(|e| IoError::io(&self.path, e))
            .and_then(|()| {
                fs::rename(&self.temp, &self.path).map_err(|e| IoError::io(&self.path, e))
            });
        if result.is_err() {
            let _ = fs::remove_file(&self.temp);
        }
        result
    }
}

impl Drop for Pc2Writer {
    fn drop(&mut self) {
        // Never finished (an error unwound the writer): no stray temporary.
        if self.file.take().is_some() {
            let _ = fs::remove_file(&self.temp);
        }
    }
}

/// A point cache read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Pc2 {
    /// Points per frame.
    pub num_points: usize,
    /// Start frame from the header.
    pub start_frame: f32,
    /// Sample rate from the header.
    pub sample_rate: f32,
    /// Positions per frame (from `f32`).
    pub frames: Vec<Vec<[f64; 3]>>,
}

/// Reads a PC2 file (for checks and tests); a file shorter than its header
/// says is an error naming it.
pub fn read_pc2(path: &Path) -> Result<Pc2, IoError> {
    let bytes = fs::read(path).map_err(|e| IoError::io(path, e))?;
    if bytes.len() < HEADER_BYTES as usize || &bytes[..12] != MAGIC {
        return Err(IoError::invalid(
            path,
            "not a PC2 file (no POINTCACHE2 header)",
        ));
    }
    let i32_at =
        |o: usize| i32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let f32_at =
        |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]);
    let (points, samples) = (i32_at(16), i32_at(28));
    if points < 0 || samples < 0 {
        return Err(IoError::invalid(path, "negative counts in the PC2 header"));
    }
    let (points, samples) = (points as usize, samples as usize);
    let need = HEADER_BYTES as usize + 12 * points * samples;
    if bytes.len() < need {
        return Err(IoError::invalid(
            path,
            format!(
                "{} bytes, but {samples} frames of {points} points need {need}",
                bytes.len()
            ),
        ));
    }
    let frames = (0..samples)
        .map(|s| {
            (0..points)
                .map(|p| {
                    let o = HEADER_BYTES as usize + 12 * (s * points + p);
                    [f32_at(o) as f64, f32_at(o + 4) as f64, f32_at(o + 8) as f64]
                })
                .collect()
        })
        .collect();
    Ok(Pc2 {
        num_points: points,
        start_frame: f32_at(20),
        sample_rate: f32_at(24),
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_temporary_file_is_a_valid_cache_of_the_frames_so_far() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.pc2");
        let mut w = Pc2Writer::create(&path, 1, 0.0, 1.0).unwrap();
        w.append(&[[1.0, 2.0, 3.0]]).unwrap();
        let temp = w.temp.clone();
        let partial = read_pc2(&temp).unwrap();
        assert_eq!(partial.frames, vec![vec![[1.0, 2.0, 3.0]]]);
        assert!(w.append(&[[0.0; 3]; 2]).is_err());
        assert_eq!(w.samples(), 1);
        drop(w);
        assert!(!temp.exists() && !path.exists());
    }

    #[test]
    fn a_resumed_cache_keeps_its_first_frames_and_appends() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.pc2");
        let mut w = Pc2Writer::create(&path, 2, 0.0, 1.0).unwrap();
        for k in 0..3 {
            w.append(&[[k as f64, 0.0, 0.0], [0.0, k as f64, 1.0]])
                .unwrap();
        }
        w.finish().unwrap();
        let mut r = Pc2Writer::resume(&path, 2, 2).unwrap();
        assert_eq!(r.samples(), 2);
        r.append(&[[9.0, 9.0, 9.0], [8.0, 8.0, 8.0]]).unwrap();
        r.finish().unwrap();
        let back = read_pc2(&path).unwrap();
        assert_eq!(back.frames.len(), 3);
        assert_eq!(back.frames[1], vec![[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]);
        assert_eq!(back.frames[2], vec![[9.0, 9.0, 9.0], [8.0, 8.0, 8.0]]);
        // Too few frames, another point count, or no cache: refused.
        assert!(Pc2Writer::resume(&path, 2, 4).is_err());
        assert!(Pc2Writer::resume(&path, 3, 1).is_err());
        assert!(Pc2Writer::resume(&dir.path().join("none.pc2"), 2, 1).is_err());
        std::fs::write(&path, b"POINTCACHE2\0 short").unwrap();
        assert!(Pc2Writer::resume(&path, 2, 1).is_err());
        let leftovers = std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(leftovers, 1, "no temporary file is left");
    }

    #[test]
    fn header_is_the_published_layout() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.pc2");
        let mut w = Pc2Writer::create(&path, 3, 5.0, 0.5).unwrap();
        w.append(&[[0.0; 3]; 3]).unwrap();
        w.finish().unwrap();
        w.finish().unwrap();
        let b = std::fs::read(&path).unwrap();
        assert_eq!(b.len(), 32 + 36);
        assert_eq!(&b[..12], b"POINTCACHE2\0");
        assert_eq!(b[12..16], 1i32.to_le_bytes());
        assert_eq!(b[16..20], 3i32.to_le_bytes());
        assert_eq!(b[20..24], 5.0f32.to_le_bytes());
        assert_eq!(b[24..28], 0.5f32.to_le_bytes());
        assert_eq!(b[28..32], 1i32.to_le_bytes());
        assert!(w.append(&[[0.0; 3]; 3]).is_err());
        std::fs::write(&path, &b[..50]).unwrap();
        assert!(read_pc2(&path).unwrap_err().to_string().contains("h.pc2"));
    }
}
