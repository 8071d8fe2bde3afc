//! ParaView `.pvd` collections (time series of XML VTK files).
//!
//! vtkio cannot write `.pvd`, and the format is a few lines of XML, so it is
//! written here.

use crate::IoError;
use crate::atomic::write_atomic;

use std::path::{Path, PathBuf};

/// One file of a `.pvd` collection: a frame, or one part of a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PvdEntry {
    /// Simulated time of the frame.
    pub time: f64,
    /// Which part of the frame the file is (0 for a frame of one part):
    /// ParaView opens a collection whose frames have several parts as one
    /// multiblock data set, a block per part.
    pub part: u32,
    /// The part's name (ParaView names its block so), if any.
    pub name: Option<String>,
    /// File name relative to the folder of the `.pvd`.
    pub file: String,
}

impl PvdEntry {
    /// A frame of one part.
    pub fn frame(time: f64, file: impl Into<String>) -> Self {
        Self {
            time,
            part: 0,
            name: None,
            file: file.into(),
        }
    }
}

/// Records the frames of a time series and keeps a `.pvd` file listing them.
///
/// The `.pvd` is rewritten atomically after every added frame, so a run that
/// is interrupted still leaves a valid collection of the frames written so far.
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let mut pvd = mss_io::vtk::PvdWriter::new(dir.path().join("run.pvd"));
/// pvd.add_frame(0.0, "run_0000.vtu").unwrap();
/// pvd.add_frame(0.5, "run_0001.vtu").unwrap();
/// let text = std::fs::read_to_string(dir.path().join("run.pvd")).unwrap();
/// assert!(text.contains(r#"timestep="0.5" group="" part="0" file="run_0001.vtu""#));
/// ```
#[derive(Debug, Clone)]
pub struct PvdWriter {
    path: PathBuf,
    entries: Vec<PvdEntry>,
    /// Decimals of the times written (`None`: the shortest text that parses
    /// back exactly).
    time_decimals: Option<usize>,
}

/// Decimals that show frame times scheduled at multiples of `every` until
/// `end` without the rounding of the steps' sums (`0.019999999999999987`
/// is `0.02`): the decimals of `every` and of `end` as written, and two
/// more, so that a frame off the schedule (an interrupted run's last)
/// keeps its own time. `None` (times written exactly) when either has more
/// than 9 decimals: then they are not round numbers.
///
/// ```
/// use mss_io::vtk::time_decimals;
/// assert_eq!(time_decimals(0.025, 1.0), Some(5));
/// assert_eq!(time_decimals(0.01, 1.5), Some(4));
/// assert_eq!(time_decimals(1.0 / 3.0, 1.0), None);
/// ```
pub fn time_decimals(every: f64, end: f64) -> Option<usize> {
    let decimals = |x: f64| {
        let text = x.to_string();
        (x.is_finite() && !text.contains('e'))
            .then(|| text.split_once('.').map_or(0, |(_, d)| d.len()))
            .filter(|&d| d <= 9)
    };
    Some(decimals(every)?.max(decimals(end)?) + 2)
}

/// `t` with `decimals` decimals, trailing zeros dropped (`0.0200` -> `0.02`).
fn time_text(t: f64, decimals: usize) -> String {
    let text = format!("{t:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    }
}

impl PvdWriter {
    /// A collection to be written at `path` (nothing is written until the
    /// first [`add_frame`](Self::add_frame)).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        PvdWriter {
            path: path.into(),
            entries: Vec::new(),
            time_decimals: None,
        }
    }

    /// Writes times with `decimals` decimals ([`time_decimals`] of the
    /// frame schedule gives frames at its multiples as ParaView users expect
    /// them), or, with `None`, exactly (the default).
    pub fn set_time_decimals(&mut self, decimals: Option<usize>) {
        self.time_decimals = decimals;
    }

    /// Path of the `.pvd` file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames recorded so far, in the order added.
    pub fn entries(&self) -> &[PvdEntry] {
        &self.entries
    }

    /// Records a frame (its file name relative to the `.pvd`'s folder, `/` as
    /// separator) and rewrites the `.pvd`. A non-finite time is refused.
    pub fn add_frame(&mut self, time: f64, file: &str) -> Result<(), IoError> {
        if !time.is_finite() {
            return Err(IoError::invalid(
                &self.path,
                format!("frame time {time} is not finite"),
            ));
        }
        self.entries.push(PvdEntry::frame(time, file));
        if let Err(e) = self.write() {
            // Keep the in-memory list equal to what is on disk.
            self.entries.pop();
            return Err(e);
        }
        Ok(())
    }

    /// Records a frame of several parts, `(name, file)` each, the parts
    /// numbered in order, and rewrites the `.pvd`. A non-finite time is
    /// refused.
    ///
    /// ```
    /// let dir = tempfile::tempdir().unwrap();
    /// let mut pvd = mss_io::vtk::PvdWriter::new(dir.path().join("all.pvd"));
    /// pvd.add_parts(0.5, &[("a", "a_0001.vtu"), ("b", "b_0001.vtu")]).unwrap();
    /// let text = std::fs::read_to_string(dir.path().join("all.pvd")).unwrap();
    /// assert!(text.contains(r#"timestep="0.5" group="" part="1" name="b" file="b_0001.vtu""#));
    /// ```
    pub fn add_parts(&mut self, time: f64, parts: &[(&str, &str)]) -> Result<(), IoError> {
        if !time.is_finite() {
            return Err(IoError::invalid(
                &self.path,
                format!("frame time {time} is not finite"),
            ));
        }
        let before = self.entries.len();
        self.entries
            .extend(parts.iter().enumerate().map(|(k, (name, file))| PvdEntry {
                time,
                part: k as u32,
                name: Some(name.to_string()),
                file: file.to_string(),
            }));
        if let Err(e) = self.write() {
            self.entries.truncate(before);
            return Err(e);
        }
        Ok(())
    }

    /// Replaces the frames recorded by `frames` (time, file) and rewrites the
    /// `.pvd` (a series resumed from a checkpoint). A non-finite time is
    /// refused.
    pub fn set_frames(&mut self, frames: Vec<(f64, String)>) -> Result<(), IoError> {
        if let Some((t, _)) = frames.iter().find(|(t, _)| !t.is_finite()) {
            return Err(IoError::invalid(
                &self.path,
                format!("frame time {t} is not finite"),
            ));
        }
        self.set_entries(
            frames
                .into_iter()
                .map(|(time, file)| PvdEntry::frame(time, file))
                .collect(),
        )
    }

    /// Replaces the files recorded by `entries` and rewrites the `.pvd` (a
    /// collection of parts resumed from a checkpoint). A non-finite time is
    /// refused.
    pub fn set_entries(&mut self, entries: Vec<PvdEntry>) -> Result<(), IoError> {
        if let Some(e) = entries.iter().find(|e| !e.time.is_finite()) {
            return Err(IoError::invalid(
                &self.path,
                format!("frame time {} is not finite", e.time),
            ));
        }
        self.entries = entries;
        self.write()
    }

    /// Rewrites the `.pvd` with the frames recorded so far.
    pub fn write(&self) -> Result<(), IoError> {
        write_atomic(&self.path, |w| {
            w.write_all(
                b"<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" \
                  byte_order=\"LittleEndian\">\n  <Collection>\n",
            )?;
            for e in &self.entries {
                // Display of f64 is the shortest text that parses back exactly.
                let time = match self.time_decimals {
                    Some(d) => time_text(e.time, d),
                    None => e.time.to_string(),
                };
                let name = e
                    .name
                    .as_deref()
                    .map_or(String::new(), |n| format!(" name=\"{}\"", xml_escape(n)));
                writeln!(
                    w,
                    "    <DataSet timestep=\"{time}\" group=\"\" part=\"{}\"{name} file=\"{}\"/>",
                    e.part,
                    xml_escape(&e.file)
                )?;
            }
            w.write_all(b"  </Collection>\n</VTKFile>\n")
        })
    }
}

/// Escapes the characters that cannot appear in a double-quoted XML attribute.
fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_file_names_and_refuses_nan() {
        let dir = tempfile::tempdir().unwrap();
        let mut pvd = PvdWriter::new(dir.path().join("a.pvd"));
        pvd.add_frame(1.0, "a&b\"<c>.vtu").unwrap();
        let text = std::fs::read_to_string(pvd.path()).unwrap();
        assert!(
            text.contains("file=\"a&amp;b&quot;&lt;c&gt;.vtu\""),
            "{text}"
        );
        assert!(pvd.add_frame(f64::NAN, "x.vtu").is_err());
        assert_eq!(pvd.entries().len(), 1);
    }

    #[test]
    fn parts_read_back_with_their_numbers_and_names() {
        let dir = tempfile::tempdir().unwrap();
        let mut pvd = PvdWriter::new(dir.path().join("all.pvd"));
        pvd.add_parts(0.0, &[("a", "a_0000.vtu"), ("b&c", "b_0000.vtu")])
            .unwrap();
        pvd.add_parts(0.5, &[("a", "a_0001.vtu"), ("b&c", "b_0001.vtu")])
            .unwrap();
        assert!(pvd.add_parts(f64::INFINITY, &[("a", "x.vtu")]).is_err());
        let back = crate::vtk::read::read_pvd(pvd.path()).unwrap();
        assert_eq!(back, pvd.entries());
        assert_eq!(back.len(), 4);
        assert_eq!((back[3].part, back[3].name.as_deref()), (1, Some("b&c")));
        // A plain frame is part 0 without a name, and reads back so.
        pvd.set_frames(vec![(1.0, "x.vtu".into())]).unwrap();
        let back = crate::vtk::read::read_pvd(pvd.path()).unwrap();
        assert_eq!(back, vec![PvdEntry::frame(1.0, "x.vtu")]);
    }
}
