//! Resource guards: the memory a job may use and the disk space its output
//! needs, estimated before the large allocations and before any file is
//! written.
//!
//! A job is refused, with a message that names the figures, when
//! - the voxelizer's bounding grid, or the run (model, state, solver) it
//!   would build, is estimated to need more than [`Limits::memory_bytes`]
//!   (default: [`DEFAULT_MEMORY_FRACTION`] of the machine's physical memory);
//! - the frames it would write are estimated to need more than the free
//!   space of the output folder's file system.
//!
//! The estimates ([`run_memory_estimate`], and the frame size of
//! [`crate::output::frame_size_estimate`]) are measured figures per cell
//! and per node; they err on the high side.
//!
//! ```
//! use mss_scene::limits::{Limits, parse_size};
//! assert_eq!(parse_size("512MiB").unwrap(), 512 << 20);
//! assert_eq!(parse_size("2 GB").unwrap(), 2_000_000_000);
//! assert!(parse_size("lots").is_err());
//! assert!(Limits::default().memory_bytes > 0);
//! ```

use std::path::Path;

/// Fraction of the physical memory a job may use by default.
pub const DEFAULT_MEMORY_FRACTION: f64 = 0.75;

/// Memory assumed when the physical memory cannot be read (bytes).
pub const FALLBACK_MEMORY_BYTES: u64 = 8 << 30;

/// [`Limits::load_check_seconds`] unless a front end says otherwise: the
/// bundled scenes' checks take well under a second.
pub const DEFAULT_LOAD_CHECK_SECONDS: f64 = 3.0;

/// What a job may use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest estimated memory (bytes).
    pub memory_bytes: u64,
    /// Whether the output's estimated size is compared with the disk space.
    pub check_disk: bool,
    /// Largest output a run may write (bytes); `None`: the free space of the
    /// output folder's file system.
    pub output_bytes: Option<u64>,
    /// Longest a dynamic run of the default kind of model waits for its
    /// load check (s). For that model the check only warns (the body
    /// buckles, or has an unstable equilibrium), and a soft body that
    /// collapses under its load makes the static solve search its load
    /// limit through many failing increments (a 6,500-cell bunny: 29 s and
    /// 1 GiB before its first step); past this time the run starts without
    /// the verdict and says so. `mss check` runs the check in full. Models
    /// that the check may refuse are always checked in full.
    pub load_check_seconds: f64,
}

impl Limits {
    /// `loaders` whose compressed files may unpack to at most the memory
    /// limit (or their own bound, if lower): a hostile file is refused
    /// from what it declares before it is unpacked.
    pub fn bound_loaders(&self, loaders: &mut hexmesh::load::Loaders) {
        loaders.max_unpacked_bytes = loaders.max_unpacked_bytes.min(self.memory_bytes);
    }
}

impl Default for Limits {
    fn default() -> Self {
        let physical = physical_memory_bytes().unwrap_or(FALLBACK_MEMORY_BYTES);
        Self {
            memory_bytes: (physical as f64 * DEFAULT_MEMORY_FRACTION) as u64,
            check_disk: true,
            output_bytes: None,
            load_check_seconds: DEFAULT_LOAD_CHECK_SECONDS,
        }
    }
}

impl Limits {
    /// Where [`Limits::memory_bytes`] comes from, in messages.
    pub fn memory_origin(&self) -> &'static str {
        if self.memory_bytes == Limits::default().memory_bytes {
            "three quarters of this machine's memory; --max-memory sets it"
        } else {
            "as set"
        }
    }
}

/// The machine's physical memory (bytes), from `/proc/meminfo` (Linux).
pub fn physical_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// Free space (bytes) for an unprivileged user on the file system holding
/// `dir` (or its nearest existing ancestor).
pub fn free_disk_bytes(dir: &Path) -> Option<u64> {
    // A relative folder ("out", the template's) has no parent to climb to
    // once its own name is gone: resolve it against the working directory.
    let absolute = std::path::absolute(dir).ok()?;
    let mut p = absolute.as_path();
    loop {
        if p.exists() {
            break;
        }
        p = p.parent().filter(|q| !q.as_os_str().is_empty())?;
    }
    let s = rustix::fs::statvfs(p).ok()?;
    s.f_bavail.checked_mul(s.f_frsize)
}

/// Parses a size: a number of bytes with an optional unit `K`, `M`, `G`, `T`
/// (powers of 1000; `KB`, `MB`, ... the same) or `KiB`, `MiB`, `GiB`, `TiB`
/// (powers of 1024).
pub fn parse_size(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let value: f64 = number
        .parse()
        .map_err(|_| format!("{text:?} is not a size (like 8GiB, 512MB or 1000000)"))?;
    let factor: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "m" | "mb" => 1e6,
        "g" | "gb" => 1e9,
        "t" | "tb" => 1e12,
        "kib" => 1024.0,
        "mib" => 1024f64.powi(2),
        "gib" => 1024f64.powi(3),
        "tib" => 1024f64.powi(4),
        other => {
            return Err(format!(
                "unknown size unit {other:?} in {text:?} (use KB, MB, GB, KiB, MiB, GiB)"
            ));
        }
    };
    let bytes = value * factor;
    if !(1.0..1.8e19).contains(&bytes) {
        return Err(format!("{text:?} is not a usable size"));
    }
    Ok(bytes as u64)
}

/// Bytes of a process before any lattice (program, runtime, thread stacks).
const BASE_BYTES: u64 = 13 << 20;
/// Bytes per cell of an explicit run at its peak, output included, beyond
/// [`BASE_BYTES`] (measured: the slope over voxelized cubes of 48^3 to
/// 128^3 cells is 296, the bundled scenes 12-13 MiB in all; the lattice's
/// positions and cells, the model, the state, the integrator, whose retry
/// positions the frame being written borrows; docs/solvers.md). The mode check that `mss run`
/// makes on lattices of at most 20,000 nodes is not counted (it is bounded
/// by that size); `benches/estimates.rs` of mss-cli compares the estimate
/// with runs.
const EXPLICIT_BYTES_PER_CELL: u64 = 300;
/// Bytes per node that Newton solves add (tangent, multigrid hierarchy,
/// Krylov vectors; measured: 28,000 implicit and 30,000 static with the
/// stability test on 8,800 nodes).
const MATRIX_BYTES_PER_NODE: u64 = 32_000;

/// Cells a run may have within `memory_bytes` (the lattice and the run; for
/// Newton solves a node per cell is assumed, as on a large lattice).
pub fn cell_budget(memory_bytes: u64, needs_matrix: bool) -> u64 {
    let per_cell = hexmesh::voxelize::LATTICE_BYTES_PER_CELL
        + EXPLICIT_BYTES_PER_CELL
        + if needs_matrix {
            MATRIX_BYTES_PER_NODE
        } else {
            0
        };
    memory_bytes.saturating_sub(BASE_BYTES) / per_cell
}

/// Estimated peak memory (bytes) of a run on a lattice of `cells` cells and
/// `nodes` nodes; `needs_matrix` for implicit and static solves.
pub fn run_memory_estimate(cells: usize, nodes: usize, needs_matrix: bool) -> u64 {
    let matrix = if needs_matrix {
        MATRIX_BYTES_PER_NODE * nodes as u64
    } else {
        0
    };
    BASE_BYTES + EXPLICIT_BYTES_PER_CELL * cells as u64 + matrix
}

/// Bytes per vertex of the input surface that a run keeps (the mesh, its
/// embedding in the lattice, the deformed surface of a frame; measured: the
/// 36,000-vertex Stanford bunny on a 3,000-cell lattice adds 12 MiB).
const MESH_BYTES_PER_VERTEX: u64 = 350;

/// Estimated memory (bytes) for the input surface of `vertices` vertices,
/// beyond [`run_memory_estimate`].
pub fn mesh_memory_estimate(vertices: usize) -> u64 {
    MESH_BYTES_PER_VERTEX * vertices as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_units_and_refuse_nonsense() {
        assert_eq!(parse_size("1000").unwrap(), 1000);
        assert_eq!(parse_size("1.5K").unwrap(), 1500);
        assert_eq!(parse_size("8GiB").unwrap(), 8 << 30);
        for bad in ["", "-1", "0", "1e3", "5 parsecs", "inf", "99999999999TB"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_machine_reports_memory_and_disk() {
        assert!(physical_memory_bytes().is_some_and(|b| b > 1 << 28));
        let dir = tempfile::tempdir().unwrap();
        assert!(free_disk_bytes(&dir.path().join("not/yet/there")).is_some_and(|b| b > 0));
        // Relative folders, existing or not (the template's "out").
        for relative in ["out", "not/yet/there", ".", "./out"] {
            assert!(
                free_disk_bytes(Path::new(relative)).is_some_and(|b| b > 0),
                "{relative}"
            );
        }
    }
}
