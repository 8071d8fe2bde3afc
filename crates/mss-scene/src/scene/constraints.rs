//! `[[motions]]`: node sets moved by a prescribed displacement (`[[fixed]]` is
//! a list of the library's node selectors).

use mss_core::constraints::{ConstraintSpec, Dofs, Keyframe, Motion, NodeSelector};
use serde::Deserialize;

use super::key::KeyError;

/// Checks a box's corners: finite, with `min <= max` on every axis.
pub fn check_box(min: &[f64; 3], max: &[f64; 3]) -> Result<(), KeyError> {
    if !(min.iter().chain(max).all(|v| v.is_finite())) || (0..3).any(|k| min[k] > max[k]) {
        return Err(KeyError::new(
            "",
            format!("box min = {min:?}, max = {max:?}: coordinates must be finite with min <= max"),
        ));
    }
    Ok(())
}

/// Checks what a node selector's own values can say (a finite plane, a
/// box with `min <= max`, a non-empty index list); whether it selects a
/// node is known only on the lattice.
pub fn check_selector(s: &NodeSelector) -> Result<(), KeyError> {
    match s {
        NodeSelector::LowestLayer | NodeSelector::Face { .. } => Ok(()),
        NodeSelector::Box { min, max, .. } => check_box(min, max),
        NodeSelector::Plane { value, .. } if !value.is_finite() => Err(KeyError::new(
            "",
            format!("plane value = {value}; must be a finite position (m)"),
        )),
        NodeSelector::Plane { .. } => Ok(()),
        NodeSelector::Indices { nodes } if nodes.is_empty() => Err(KeyError::new(
            "",
            "`nodes` is empty; list at least one node index",
        )),
        NodeSelector::Indices { .. } => Ok(()),
    }
}

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
    /// Checks the table: its selector, a finite displacement and a
    /// positive ramp time.
    pub fn check(&self) -> Result<(), KeyError> {
        check_selector(&self.select)?;
        if !self.displacement.iter().all(|v| v.is_finite()) {
            return Err(KeyError::new(
                "",
                format!("displacement = {:?}; must be finite", self.displacement),
            ));
        }
        if let Some(r) = self.ramp
            && !(r.is_finite() && r > 0.0)
        {
            return Err(KeyError::new(
                "",
                format!("ramp = {r}; must be a positive time (s)"),
            ));
        }
        Ok(())
    }

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
