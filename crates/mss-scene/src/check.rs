//! What `mss check` reports about a prepared job without running it: sizes,
//! the time plan, memory and output estimates, and the mechanisms the held
//! nodes leave free.

use serde::Serialize;

use crate::job::Job;
use std::path::Path;

use crate::limits::run_memory_estimate;

/// Largest model (nodes) on which a run counts zero-energy modes before
/// starting; [`CheckReport::new`] always counts them.
pub const RUN_MODE_CHECK_MAX_NODES: usize = 20_000;

/// The figures of a prepared job that `mss check` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckReport {
    /// Fully or partly held nodes.
    pub held_nodes: usize,
    /// Estimated peak memory of the run (bytes).
    pub memory_bytes: u64,
    /// Frames the run writes.
    pub frames: u64,
    /// Estimated bytes of one frame.
    pub frame_bytes: u64,
    /// Hourglass stiffness per cell (N/m; 0 without hourglass control).
    pub hourglass_stiffness: f64,
    /// A warning about mechanisms the held nodes leave free, if any.
    pub mechanism_warning: Option<String>,
}

impl CheckReport {
    /// Estimates and checks for `job` (counts zero-energy modes: seconds on
    /// large lattices).
    pub fn new(job: &Job) -> Self {
        let model = job.problem.model();
        let (frame_bytes, frames) = job.output_estimate();
        let held_nodes = (0..model.num_nodes())
            .filter(|&n| job.problem.constraints().mask(n).iter().any(|&h| h))
            .count();
        let needs_matrix = !job.input.scene.solver.is_explicit();
        CheckReport {
            held_nodes,
            memory_bytes: run_memory_estimate(model.num_cells(), model.num_nodes(), needs_matrix),
            frames,
            frame_bytes,
            hourglass_stiffness: model.cell_coefficients(0).hourglass,
            mechanism_warning: mechanism_warning(job),
        }
    }

    /// Free bytes on the disk of `out_dir` and a warning when the output
    /// would take more than half of it (the run refuses more than all of it).
    pub fn disk(&self, out_dir: &Path) -> (Option<u64>, Option<String>) {
        let free = crate::limits::free_disk_bytes(out_dir);
        let needed = self.frames.saturating_mul(self.frame_bytes);
        let warning = free.and_then(|f| {
            (needed > f / 2).then(|| {
                format!(
                    "the output (about {}) {} the {} free in {}",
                    crate::error::human(needed),
                    if needed > f {
                        "exceeds"
                    } else {
                        "takes more than half of"
                    },
                    crate::error::human(f),
                    out_dir.display()
                )
            })
        });
        (free, warning)
    }
}

/// A warning if the boundary conditions leave zero-energy motions (rigid
/// motions or hourglass mechanisms) that the loads can excite: counted on the
/// rest stiffness restricted to the free dofs (`mss_core::modes`).
pub fn mechanism_warning(job: &Job) -> Option<String> {
    let c = job.problem.constraints();
    let model = job.problem.model();
    let restrained = !job.input.scene.loads.drags.is_empty();
    let mask: Vec<[bool; 3]> = (0..model.num_nodes()).map(|n| c.mask(n)).collect();
    match mss_core::modes::zero_energy_modes(model, &mask) {
        Ok(z) if z.count == 0 => None,
        Ok(z) => Some(format!(
            "the held nodes leave {}{} zero-energy mode(s) (rigid motions or hourglass \
             mechanisms){}: a static solve will fail and dynamics may drift; hold a larger \
             region (e.g. a whole face){}",
            z.count,
            if z.exact { "" } else { " or more" },
            if restrained {
                "; drag springs restrain some of them"
            } else {
                ""
            },
            if model.cell_coefficients(0).hourglass > 0.0 {
                ""
            } else {
                // Parts one cell thick leave hourglass mechanisms however they are held.
                ", or add hourglass control ([model] parameterization \"...+hg\" or hourglass = 0.05)"
            },
        )),
        Err(e) => {
            log::debug!("zero-energy modes not counted: {e}");
            let held = c.num_held_dofs();
            if held < 6 && !restrained {
                Some(format!(
                    "only {held} displacement components are held: rigid motions remain free"
                ))
            } else {
                None
            }
        }
    }
}
