//! Loads on a 2D body beyond its gravity and dead nodal forces (which
//! [`PlaneProblem`](super::PlaneProblem) holds as numbers): drag springs,
//! dead forces a scene's `[[loads.custom]]` names, and any load a program
//! brings, through one trait, [`PlaneLoad`] (the plane's counterpart of
//! [`crate::loads::Load`]).

use std::fmt::Debug;

use super::PlaneModel;
use crate::loads::LoadError;
use crate::{BlockCsr, Vec3};

/// A load on a 2D body: forces in the plane that may depend on time and
/// on the positions.
///
/// Contract: `add_forces` adds `scale` times the load's forces (N) at time
/// `t` (s) and positions `x` (m, z = 0) to the x and y of `f` and leaves z
/// alone; `add_jacobian` adds `scale` times their derivative in the x and
/// y of each 3x3 block of `jac` (the lattice's pattern, the diagonal always
/// present). Loads that do not depend on the positions keep the default,
/// which adds nothing. Both must be deterministic (no order of sums that
/// depends on threads). `scale` is the static solve's load factor (1 in
/// time steps).
pub trait PlaneLoad: Send + Sync + Debug {
    /// A short description for logs and errors.
    fn name(&self) -> String;
    /// Adds `scale` times the forces at `(t, x)` to `f`.
    fn add_forces(&self, model: &PlaneModel, t: f64, x: &[Vec3], scale: f64, f: &mut [Vec3]);
    /// Adds `scale` times the forces' derivative at `(t, x)` to `jac`.
    fn add_jacobian(&self, model: &PlaneModel, t: f64, x: &[Vec3], scale: f64, jac: &mut BlockCsr) {
        let _ = (model, t, x, scale, jac);
    }
}

/// Dead forces on nodes (N): what a scene's gravity, forces and tractions
/// become when `[[loads.custom]]` names them in 2D.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneNodalForces {
    name: String,
    forces: Vec<(u32, [f64; 2])>,
}

impl PlaneNodalForces {
    /// `forces` (node, force) on `model`'s nodes; a node may appear more
    /// than once (the forces add). Checks the indices and that the forces
    /// are finite.
    pub fn new(
        name: &str,
        model: &PlaneModel,
        forces: Vec<(u32, [f64; 2])>,
    ) -> Result<Self, LoadError> {
        let invalid = |message: String| LoadError::Invalid {
            load: name.to_owned(),
            message,
        };
        if let Some((n, _)) = forces
            .iter()
            .find(|(n, _)| *n as usize >= model.num_nodes())
        {
            return Err(invalid(format!(
                "node {n} is out of range: the model has {} nodes",
                model.num_nodes()
            )));
        }
        if let Some((n, f)) = forces
            .iter()
            .find(|(_, f)| !f.iter().all(|c| c.is_finite()))
        {
            return Err(invalid(format!(
                "the force {f:?} on node {n} is not finite"
            )));
        }
        Ok(Self {
            name: name.to_owned(),
            forces,
        })
    }

    /// The sum of the forces (N).
    pub fn total(&self) -> [f64; 2] {
        self.forces
            .iter()
            .fold([0.0; 2], |s, (_, f)| [s[0] + f[0], s[1] + f[1]])
    }
}

impl PlaneLoad for PlaneNodalForces {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn add_forces(&self, _: &PlaneModel, _: f64, _: &[Vec3], scale: f64, f: &mut [Vec3]) {
        for &(n, force) in &self.forces {
            f[n as usize].x += scale * force[0];
            f[n as usize].y += scale * force[1];
        }
    }
}

/// A drag spring: zero-length springs, one per node of a set, pull each
/// node toward its rest position shifted by `target - centroid` (the
/// set's centroid goes to `target` and the set keeps its shape), sharing
/// the stiffness `stiffness` (N/m) equally. As in 3D.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneDrag {
    nodes: Vec<u32>,
    offset: [f64; 2],
    per_node: f64,
}

impl PlaneDrag {
    /// The drag of `nodes` (not empty, in range) toward `target` (m) with
    /// total stiffness `stiffness` (N/m, finite, >= 0).
    pub fn new(
        model: &PlaneModel,
        nodes: Vec<u32>,
        target: [f64; 2],
        stiffness: f64,
    ) -> Result<Self, LoadError> {
        let invalid = |message: String| LoadError::Invalid {
            load: "drag".into(),
            message,
        };
        if !(stiffness.is_finite() && stiffness >= 0.0) {
            return Err(invalid(format!(
                "stiffness {stiffness} N/m must be a finite number >= 0"
            )));
        }
        if !target.iter().all(|c| c.is_finite()) {
            return Err(invalid(format!("target {target:?} is not a finite point")));
        }
        if nodes.is_empty() {
            return Err(invalid("no node to drag".into()));
        }
        let rest = model.rest_positions();
        if let Some(n) = nodes.iter().find(|&&n| n as usize >= rest.len()) {
            return Err(invalid(format!(
                "node {n} is out of range: the model has {} nodes",
                rest.len()
            )));
        }
        let centroid = nodes.iter().map(|&n| rest[n as usize]).sum::<Vec3>() / nodes.len() as f64;
        Ok(Self {
            per_node: stiffness / nodes.len() as f64,
            offset: [target[0] - centroid.x, target[1] - centroid.y],
            nodes,
        })
    }

    /// Moves the target to `target` (m): a mouse drag.
    pub fn set_target(&mut self, model: &PlaneModel, target: [f64; 2]) {
        let rest = model.rest_positions();
        let centroid =
            self.nodes.iter().map(|&n| rest[n as usize]).sum::<Vec3>() / self.nodes.len() as f64;
        self.offset = [target[0] - centroid.x, target[1] - centroid.y];
    }

    /// The dragged nodes.
    pub fn nodes(&self) -> &[u32] {
        &self.nodes
    }
}

impl PlaneLoad for PlaneDrag {
    fn name(&self) -> String {
        format!("drag of {} nodes", self.nodes.len())
    }

    fn add_forces(&self, model: &PlaneModel, _: f64, x: &[Vec3], scale: f64, f: &mut [Vec3]) {
        let rest = model.rest_positions();
        let k = scale * self.per_node;
        for &n in &self.nodes {
            let n = n as usize;
            f[n].x += k * (rest[n].x + self.offset[0] - x[n].x);
            f[n].y += k * (rest[n].y + self.offset[1] - x[n].y);
        }
    }

    fn add_jacobian(&self, _: &PlaneModel, _: f64, _: &[Vec3], scale: f64, jac: &mut BlockCsr) {
        let k = scale * self.per_node;
        for &n in &self.nodes {
            let b = jac
                .find(n as usize, n as usize)
                .expect("the diagonal is in the pattern");
            jac.blocks[b][(0, 0)] -= k;
            jac.blocks[b][(1, 1)] -= k;
        }
    }
}
