//! Checkpoints: the whole state of a run in one file, `checkpoint.mss` in
//! its output folder, so that `mss run --resume FOLDER` (or
//! [`Job::resume`](crate::Job::resume)) continues it. A resumed run is
//! bitwise the run that was not interrupted: same frames, same summary
//! figures (apart from timings).
//!
//! What is kept: the step reached, the [`State`] (positions, velocities,
//! time, friction anchors), the integrator's memory between steps
//! ([`IntegratorMemory`]: its step control and cached forces), the times of
//! the frames written (so that `.pvd` collections and point caches resume
//! at the right frame), the files and bytes written so far, and a
//! fingerprint of the scene: resuming with a changed scene is refused.
//!
//! The file is binary, little-endian, written atomically (a temporary file,
//! then a rename): the magic `MSSCKPT\0`, a format version, the fields in
//! the order of [`Checkpoint`], and a 64-bit FNV-1a checksum of everything
//! before it. Every count is checked against the bytes left before anything
//! is allocated, so a damaged or hostile file is an error naming the file,
//! never a panic or a huge allocation.

use std::path::Path;

use mss_core::Vec3;
use mss_core::solver::{IntegratorMemory, State};
use thiserror::Error;

use crate::scene::Scene;

/// Name of the checkpoint file in a run's output folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.mss";

const MAGIC: &[u8; 8] = b"MSSCKPT\0";
/// Version 2 added the peak displacement; version 1 files are read with
/// none recorded. Version 3 added the Newton iterations, version 4 the load
/// check's verdict (earlier files are read with none).
const VERSION: u32 = 4;

/// Everything a resumed run needs.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// [`fingerprint`] of the scene that wrote it.
    pub fingerprint: u64,
    /// Steps done.
    pub step: u64,
    /// The state after them.
    pub state: State,
    /// The integrator's memory after them.
    pub memory: IntegratorMemory,
    /// Times of the frames written so far (s), in order.
    pub frame_times: Vec<f64>,
    /// Files written so far.
    pub files: usize,
    /// Bytes written so far.
    pub bytes: u64,
    /// Largest node displacement so far (m).
    pub peak_displacement: f64,
    /// Its simulated time (s).
    pub peak_time: f64,
    /// Newton iterations so far (0 for explicit runs).
    pub newton_iterations: u64,
    /// The verdict of the load check before the run, if it ran
    /// ([`RunSummary::load_check`](crate::RunSummary::load_check)).
    pub load_check: Option<String>,
}

/// Why a checkpoint cannot be used.
#[derive(Debug, Error)]
pub enum CheckpointError {
    /// It cannot be read.
    #[error("checkpoint {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        source: std::io::Error,
    },
    /// It is not a checkpoint of this program, or it is damaged.
    #[error("checkpoint {path} is damaged or not a checkpoint: {why}")]
    Corrupt {
        /// The file.
        path: String,
        /// What does not fit.
        why: String,
    },
    /// It was written by another scene or another lattice.
    #[error(
        "checkpoint {path} was written by another scene ({what}); resume with the scene that wrote it, or start again without --resume"
    )]
    Mismatch {
        /// The file.
        path: String,
        /// What differs.
        what: String,
    },
}

/// A fingerprint of everything in a scene that changes the run's numbers or
/// frames (the output folder aside): a checkpoint resumes only the scene
/// that wrote it.
pub fn fingerprint(scene: &Scene) -> u64 {
    let mut s = scene.clone();
    s.output.folder = std::path::PathBuf::new();
    s.output.checkpoint_every = None;
    fnv1a(format!("{s:?}").as_bytes())
}

fn fnv1a(bytes: &[u8]) -> u64 {
    mss_core::fnv1a(bytes.iter().copied())
}

struct Out(Vec<u8>);

impl Out {
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn vecs(&mut self, v: &[Vec3]) {
        self.u64(v.len() as u64);
        for p in v {
            self.f64(p.x);
            self.f64(p.y);
            self.f64(p.z);
        }
    }
    fn state(&mut self, s: &State) {
        self.f64(s.time);
        self.vecs(&s.x);
        self.vecs(&s.v);
        self.u64(s.contact.len() as u64);
        for a in &s.contact {
            match a {
                None => self.0.push(0),
                Some(p) => {
                    self.0.push(1);
                    self.f64(p.x);
                    self.f64(p.y);
                    self.f64(p.z);
                }
            }
        }
    }
}

struct In<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a str,
}

impl In<'_> {
    fn corrupt(&self, why: impl Into<String>) -> CheckpointError {
        CheckpointError::Corrupt {
            path: self.path.to_owned(),
            why: why.into(),
        }
    }
    fn take(&mut self, n: usize) -> Result<&[u8], CheckpointError> {
        if self.bytes.len() - self.at < n {
            return Err(self.corrupt(format!(
                "it ends at byte {} inside a field",
                self.bytes.len()
            )));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u64(&mut self) -> Result<u64, CheckpointError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or([0; 8]),
        ))
    }
    fn f64(&mut self) -> Result<f64, CheckpointError> {
        Ok(f64::from_bits(self.u64()?))
    }
    /// A count of items of at least `item_bytes` each, checked against the
    /// bytes left.
    fn count(&mut self, item_bytes: usize, what: &str) -> Result<usize, CheckpointError> {
        let n = self.u64()?;
        let left = (self.bytes.len() - self.at) as u64;
        if n.saturating_mul(item_bytes as u64) > left {
            return Err(self.corrupt(format!(
                "{what}: {n} entries cannot fit in the {left} bytes left"
            )));
        }
        Ok(n as usize)
    }
    fn vecs(&mut self, what: &str) -> Result<Vec<Vec3>, CheckpointError> {
        let n = self.count(24, what)?;
        let mut v = Vec::with_capacity(n);
        for _ in 0..n {
            v.push(Vec3::new(self.f64()?, self.f64()?, self.f64()?));
        }
        Ok(v)
    }
    fn state(&mut self) -> Result<State, CheckpointError> {
        let time = self.f64()?;
        let x = self.vecs("positions")?;
        let v = self.vecs("velocities")?;
        let n = self.count(1, "friction anchors")?;
        let mut contact = Vec::with_capacity(n);
        for _ in 0..n {
            contact.push(match self.take(1)?[0] {
                0 => None,
                1 => Some(Vec3::new(self.f64()?, self.f64()?, self.f64()?)),
                b => return Err(self.corrupt(format!("friction anchor flag {b}"))),
            });
        }
        if v.len() != x.len() {
            return Err(self.corrupt("positions and velocities differ in number"));
        }
        Ok(State {
            x,
            v,
            time,
            contact,
        })
    }
}

impl Checkpoint {
    fn encode(&self) -> Vec<u8> {
        let mut o = Out(Vec::with_capacity(64 + 56 * self.state.x.len()));
        o.0.extend_from_slice(MAGIC);
        o.0.extend_from_slice(&VERSION.to_le_bytes());
        o.u64(self.fingerprint);
        o.u64(self.step);
        o.state(&self.state);
        let m = &self.memory;
        o.u64(m.counters.len() as u64);
        m.counters.iter().for_each(|&c| o.u64(c));
        o.u64(m.values.len() as u64);
        m.values.iter().for_each(|&v| o.f64(v));
        o.u64(m.states.len() as u64);
        m.states.iter().for_each(|s| o.state(s));
        o.u64(self.frame_times.len() as u64);
        self.frame_times.iter().for_each(|&t| o.f64(t));
        o.u64(self.files as u64);
        o.u64(self.bytes);
        o.f64(self.peak_displacement);
        o.f64(self.peak_time);
        o.u64(self.newton_iterations);
        match &self.load_check {
            None => o.0.push(0),
            Some(text) => {
                o.0.push(1);
                o.u64(text.len() as u64);
                o.0.extend_from_slice(text.as_bytes());
            }
        }
        let sum = fnv1a(&o.0);
        o.u64(sum);
        o.0
    }

    /// Writes the checkpoint into `dir` atomically.
    pub fn write(&self, dir: &Path) -> Result<(), mss_io::IoError> {
        let bytes = self.encode();
        mss_io::atomic::write_atomic(&dir.join(CHECKPOINT_FILE), |w| w.write_all(&bytes))
    }

    /// Reads the checkpoint of `dir`, refusing one that is damaged or was not
    /// written for `fingerprint` and a model of `nodes` nodes.
    pub fn read(dir: &Path, fingerprint: u64, nodes: usize) -> Result<Self, CheckpointError> {
        let path = dir.join(CHECKPOINT_FILE);
        let name = path.display().to_string();
        let bytes = std::fs::read(&path).map_err(|source| CheckpointError::Io {
            path: name.clone(),
            source,
        })?;
        let c = Self::decode(&bytes, &name)?;
        if c.fingerprint != fingerprint {
            return Err(CheckpointError::Mismatch {
                path: name,
                what: "its scene fingerprint differs from this scene's".into(),
            });
        }
        let sizes_fit = c.state.x.len() == nodes
            && c.memory
                .states
                .iter()
                .all(|s| s.x.len() == nodes && s.contact.len() == c.state.contact.len());
        if !sizes_fit {
            return Err(CheckpointError::Mismatch {
                path: name,
                what: format!("it holds {} nodes, this lattice {nodes}", c.state.x.len()),
            });
        }
        Ok(c)
    }

    fn decode(bytes: &[u8], path: &str) -> Result<Self, CheckpointError> {
        let corrupt = |why: &str| CheckpointError::Corrupt {
            path: path.to_owned(),
            why: why.to_owned(),
        };
        if bytes.len() < MAGIC.len() + 4 + 8 || &bytes[..MAGIC.len()] != MAGIC {
            return Err(corrupt("it does not start with the checkpoint signature"));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap_or([0; 4]));
        if !(1..=VERSION).contains(&version) {
            return Err(corrupt(&format!(
                "format version {version}, this program reads {VERSION}"
            )));
        }
        let (body, sum) = bytes.split_at(bytes.len() - 8);
        if fnv1a(body).to_le_bytes() != sum {
            return Err(corrupt(
                "its checksum does not match (a partial or altered file)",
            ));
        }
        let mut r = In {
            bytes: body,
            at: 12,
            path,
        };
        let fingerprint = r.u64()?;
        let step = r.u64()?;
        let state = r.state()?;
        let n = r.count(8, "integrator counters")?;
        let counters = (0..n).map(|_| r.u64()).collect::<Result<_, _>>()?;
        let n = r.count(8, "integrator values")?;
        let values = (0..n).map(|_| r.f64()).collect::<Result<_, _>>()?;
        let n = r.count(8 + 24 + 8, "integrator states")?;
        let states = (0..n).map(|_| r.state()).collect::<Result<_, _>>()?;
        let n = r.count(8, "frame times")?;
        let frame_times: Vec<f64> = (0..n).map(|_| r.f64()).collect::<Result<_, _>>()?;
        let files = r.u64()? as usize;
        let bytes_written = r.u64()?;
        let (peak_displacement, peak_time) = if version >= 2 {
            (r.f64()?, r.f64()?)
        } else {
            (0.0, 0.0)
        };
        let newton_iterations = if version >= 3 { r.u64()? } else { 0 };
        let load_check = if version >= 4 && r.take(1)?[0] == 1 {
            let n = r.count(1, "load check verdict")?;
            let text = r.take(n)?.to_vec();
            Some(
                String::from_utf8(text)
                    .map_err(|_| r.corrupt("its load check verdict is not UTF-8"))?,
            )
        } else {
            None
        };
        if !(peak_displacement.is_finite() && peak_displacement >= 0.0 && peak_time.is_finite()) {
            return Err(r.corrupt("its peak displacement is not a finite length"));
        }
        if r.at != body.len() {
            return Err(r.corrupt(format!("{} bytes left over", body.len() - r.at)));
        }
        if !frame_times.windows(2).all(|w| w[0] < w[1])
            || frame_times.iter().any(|t| !t.is_finite())
        {
            return Err(r.corrupt("frame times are not increasing finite times"));
        }
        Ok(Checkpoint {
            fingerprint,
            step,
            state,
            memory: IntegratorMemory {
                counters,
                values,
                states,
            },
            frame_times,
            files,
            bytes: bytes_written,
            peak_displacement,
            peak_time,
            newton_iterations,
            load_check,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Checkpoint {
        let x = vec![
            Vec3::new(0.1, -2.0, 3.5),
            Vec3::new(f64::MIN_POSITIVE, 0.0, -0.0),
        ];
        let state = State {
            v: vec![Vec3::new(1e-300, 2.0, 3.0); 2],
            x: x.clone(),
            time: 0.123456789,
            contact: vec![None, Some(Vec3::new(1.0, 2.0, 3.0))],
        };
        Checkpoint {
            fingerprint: 42,
            step: 17,
            memory: IntegratorMemory {
                counters: vec![1, u64::MAX, 0],
                values: vec![std::f64::consts::PI, -0.0],
                states: vec![state.clone()],
            },
            state,
            frame_times: vec![0.0, 0.05, 0.1],
            files: 9,
            bytes: 123_456,
            peak_displacement: 0.25,
            peak_time: 0.5,
            newton_iterations: 77,
            load_check: Some("stable static equilibrium: 1 % µ".to_owned()),
        }
    }

    #[test]
    fn round_trips_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let c = sample();
        c.write(dir.path()).unwrap();
        let back = Checkpoint::read(dir.path(), 42, 2).unwrap();
        assert_eq!(back, c);
        assert_eq!(back.state.x[1].z.to_bits(), (-0.0f64).to_bits());
    }

    #[test]
    fn damaged_or_foreign_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let c = sample();
        c.write(dir.path()).unwrap();
        assert!(matches!(
            Checkpoint::read(dir.path(), 43, 2),
            Err(CheckpointError::Mismatch { .. })
        ));
        assert!(matches!(
            Checkpoint::read(dir.path(), 42, 3),
            Err(CheckpointError::Mismatch { .. })
        ));
        let path = dir.path().join(CHECKPOINT_FILE);
        let good = std::fs::read(&path).unwrap();
        // Every truncation and a flipped byte anywhere: an error, never a panic.
        for cut in [0, 5, 12, 30, good.len() / 2, good.len() - 1] {
            std::fs::write(&path, &good[..cut]).unwrap();
            let e = Checkpoint::read(dir.path(), 42, 2).unwrap_err();
            assert!(matches!(e, CheckpointError::Corrupt { .. }), "{cut}: {e}");
        }
        for at in (0..good.len()).step_by(7) {
            let mut bad = good.clone();
            bad[at] ^= 0x40;
            std::fs::write(&path, &bad).unwrap();
            assert!(Checkpoint::read(dir.path(), 42, 2).is_err(), "byte {at}");
        }
        // A count that claims more than the file holds, with a valid
        // checksum: refused before allocating.
        let mut o = Out(Vec::new());
        o.0.extend_from_slice(MAGIC);
        o.0.extend_from_slice(&VERSION.to_le_bytes());
        o.u64(42);
        o.u64(1);
        o.f64(0.0);
        o.u64(u64::MAX / 2);
        let sum = fnv1a(&o.0);
        o.u64(sum);
        std::fs::write(&path, &o.0).unwrap();
        let e = Checkpoint::read(dir.path(), 42, 2).unwrap_err().to_string();
        assert!(e.contains("cannot fit"), "{e}");
        std::fs::remove_file(&path).unwrap();
        assert!(matches!(
            Checkpoint::read(dir.path(), 42, 2),
            Err(CheckpointError::Io { .. })
        ));
    }
}
