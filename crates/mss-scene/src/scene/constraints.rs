//! `[[motions]]`: node sets moved by a prescribed displacement (`[[fixed]]` is
//! a list of the library's node selectors).

use mss_core::constraints::{ConstraintSpec, Dofs, Keyframe, Motion, NodeSelector};
use serde::Deserialize;

/// A node set moved rigidly by a prescribed displacement.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionSpec {
    /// The nodes.
    pub select: NodeSelector,
    /// Final displacement (m), reached linearly from t = 0 to `ramp`, then held.
    pub displacement: [f64; 3],
    /// Ramp time (s), > 0; default: the whole duration.
    pub ramp: Option<f64>,
}

impl MotionSpec {
    /// The library's constraint: all three dofs follow a linear ramp from
    /// rest to `displacement` over `ramp` seconds (or `duration`), then hold.
    pub fn constraint(&self, duration: f64) -> ConstraintSpec {
        ConstraintSpec {
            select: self.select.clone(),
            dofs: Dofs::ALL,
            motion: Motion::Keyframes(vec![
                Keyframe {
                    time: 0.0,
                    displacement: [0.0; 3],
                },
                Keyframe {
                    time: self.ramp.unwrap_or(duration),
                    displacement: self.displacement,
                },
            ]),
        }
    }
}
