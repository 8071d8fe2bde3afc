//! Boundary conditions: which nodes are selected, which of their degrees of
//! freedom (dofs) are held, and how the held dofs move over time.
//!
//! A [`ConstraintSpec`] is the user-facing description (serde-friendly, for
//! scene files); [`Constraints::resolve`] turns a list of them into per-node
//! dof masks the solvers use.
//!
//! Semantics of a held dof:
//! - [`Motion::Fixed`]: the dof keeps the value it has in the solver's state
//!   (normally the rest position; a state that starts rotated keeps the rotated
//!   position) and its velocity is zero.
//! - [`Motion::Velocity`] and [`Motion::Keyframes`]: the dof follows
//!   `rest + u(t)`, with `u(t)` the prescribed displacement (this is how users
//!   drag a part of the body, paper Fig. 7).
//!
//! When two constraints hold the same dof of the same node, the later one in
//! the list wins (so "fix the base, then drag a corner of it" works).

use serde::{Deserialize, Serialize};
use thiserror::Error;

use hexmesh::Aabb;

use crate::Vec3;

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// x
    X,
    /// y
    Y,
    /// z
    Z,
}

impl Axis {
    /// 0, 1 or 2.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
}

/// Which side of a plane a [`NodeSelector::Plane`] keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// Coordinate <= value (with tolerance).
    Below,
    /// Coordinate >= value (with tolerance).
    Above,
}

/// A face of the rest bounding box of the nodes; in scene files `"x-"`,
/// `"x+"`, `"y-"`, `"y+"`, `"z-"` or `"z+"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Face {
    /// x = min x
    #[serde(rename = "x-")]
    XMin,
    /// x = max x
    #[serde(rename = "x+")]
    XMax,
    /// y = min y
    #[serde(rename = "y-")]
    YMin,
    /// y = max y
    #[serde(rename = "y+")]
    YMax,
    /// z = min z
    #[serde(rename = "z-")]
    ZMin,
    /// z = max z
    #[serde(rename = "z+")]
    ZMax,
}

impl Face {
    /// Axis index (0 = x, 1 = y, 2 = z) and whether it is the maximum side.
    pub fn axis_and_max(self) -> (usize, bool) {
        match self {
            Face::XMin => (0, false),
            Face::XMax => (0, true),
            Face::YMin => (1, false),
            Face::YMax => (1, true),
            Face::ZMin => (2, false),
            Face::ZMax => (2, true),
        }
    }
}

/// Selects nodes by their rest position. All geometric tests are inclusive
/// with a tolerance of `1e-9 h` (h the cell edge), so a plane through a layer
/// of nodes selects that layer.
///
/// In scene files a selector is a table with a `kind` key, for example
/// `{ kind = "face", face = "x-" }` or `{ kind = "box", min = [0, 0, 0],
/// max = [0.1, 1, 1], relative = true }`; unknown keys are refused.
///
/// ```
/// use mss_core::constraints::{Face, NodeSelector};
/// use mss_core::Vec3;
/// let s: NodeSelector = toml::from_str("kind = \"face\"\nface = \"x+\"").unwrap();
/// assert_eq!(s, NodeSelector::Face { face: Face::XMax });
/// let rest = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0)];
/// assert_eq!(s.select(&rest, 1.0), vec![1]);
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", from = "SelectorTable")]
pub enum NodeSelector {
    /// Nodes inside an axis-aligned box (bounds included).
    Box {
        /// Minimum corner (m, or a fraction of the rest bounding box if `relative`).
        min: [f64; 3],
        /// Maximum corner (m, or a fraction of the rest bounding box if `relative`).
        max: [f64; 3],
        /// Corners given as fractions (0..1) of the nodes' rest bounding box
        /// instead of metres (default false).
        #[serde(default)]
        relative: bool,
    },
    /// Nodes on one side of the plane `coordinate(axis) = value` (nodes on
    /// the plane included).
    Plane {
        /// Axis normal to the plane: `"x"`, `"y"` or `"z"`.
        axis: Axis,
        /// Position of the plane (m).
        value: f64,
        /// Which side is kept: `"below"` or `"above"`.
        side: Side,
    },
    /// Nodes on a face of the rest bounding box.
    Face {
        /// The face.
        face: Face,
    },
    /// Explicit node indices.
    Indices {
        /// Node indices.
        nodes: Vec<u32>,
    },
    /// Nodes with the minimum z (the layer a body stands on).
    LowestLayer,
}

/// How a [`NodeSelector`] is read: the same tables, with `lowest_layer` as an
/// empty struct variant, because serde lets unknown keys pass beside a unit
/// variant of an internally tagged enum and a typo must not be ignored.
#[derive(Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
enum SelectorTable {
    Box {
        min: [f64; 3],
        max: [f64; 3],
        #[serde(default)]
        relative: bool,
    },
    Plane {
        axis: Axis,
        value: f64,
        side: Side,
    },
    Face {
        face: Face,
    },
    Indices {
        nodes: Vec<u32>,
    },
    LowestLayer {},
}

impl From<SelectorTable> for NodeSelector {
    fn from(t: SelectorTable) -> Self {
        match t {
            SelectorTable::Box { min, max, relative } => NodeSelector::Box { min, max, relative },
            SelectorTable::Plane { axis, value, side } => NodeSelector::Plane { axis, value, side },
            SelectorTable::Face { face } => NodeSelector::Face { face },
            SelectorTable::Indices { nodes } => NodeSelector::Indices { nodes },
            SelectorTable::LowestLayer {} => NodeSelector::LowestLayer,
        }
    }
}

impl NodeSelector {
    /// A box in metres.
    pub fn boxed(min: [f64; 3], max: [f64; 3]) -> Self {
        NodeSelector::Box {
            min,
            max,
            relative: false,
        }
    }

    /// The nodes on a face of the rest bounding box.
    pub fn face(face: Face) -> Self {
        NodeSelector::Face { face }
    }

    /// Nodes by index.
    pub fn indices(nodes: Vec<u32>) -> Self {
        NodeSelector::Indices { nodes }
    }
}

impl std::fmt::Display for NodeSelector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NodeSelector::Box {
                min,
                max,
                relative: false,
            } => write!(f, "box {min:?}..{max:?}"),
            NodeSelector::Box { min, max, .. } => {
                write!(f, "box {min:?}..{max:?} (fractions of the bounding box)")
            }
            NodeSelector::Plane { axis, value, side } => {
                write!(f, "plane {axis:?} {side:?} {value}")
            }
            NodeSelector::Face { face } => write!(f, "bounding face {face:?}"),
            NodeSelector::Indices { nodes } => write!(f, "{} node indices", nodes.len()),
            NodeSelector::LowestLayer => write!(f, "lowest layer"),
        }
    }
}

/// Why a boundary condition or selection was refused.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ConstraintError {
    /// A selector used by a constraint or load selects no node.
    #[error(
        "the node selector `{selector}` selects no node (the lattice spans {min:?}..{max:?} m at rest); widen it or check its coordinates"
    )]
    EmptySelection {
        /// The selector, as text.
        selector: String,
        /// Rest bounding box minimum.
        min: [f64; 3],
        /// Rest bounding box maximum.
        max: [f64; 3],
    },
    /// A node index is out of range.
    #[error("node index {index} is out of range: the model has {count} nodes")]
    NodeIndex {
        /// The index given.
        index: u32,
        /// Number of nodes.
        count: usize,
    },
    /// Keyframes are malformed.
    #[error("keyframes: {0}")]
    Keyframes(String),
    /// A number is NaN or infinite.
    #[error("{what} = {value} is not a finite number")]
    NotFinite {
        /// Which quantity.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// The selector names what a 2D body does not have (its z faces).
    #[error(
        "the node selector `{0}` selects nothing of a 2D body: it has no z faces; use x-, x+, y- or y+"
    )]
    NotInPlane(String),
    /// A dof mask string is not made of the letters x, y, z.
    #[error(
        "dofs \"{0}\": use a non-empty combination of the letters x, y, z (e.g. \"xyz\" or \"z\")"
    )]
    Dofs(String),
}

/// Axis-aligned bounding box of node positions (an empty one, min = +inf and
/// max = -inf, without nodes).
pub fn node_bounds(rest: &[Vec3]) -> Aabb {
    Aabb::of_points(rest.iter().map(|p| [p.x, p.y, p.z])).unwrap_or(Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    })
}

impl NodeSelector {
    /// Indices (ascending) of the nodes selected among rest positions `rest`
    /// of a lattice of cell edge `h`. Out-of-range indices of
    /// [`NodeSelector::Indices`] are dropped: use [`NodeSelector::select_checked`]
    /// to have them reported.
    pub fn select(&self, rest: &[Vec3], h: f64) -> Vec<u32> {
        let tol = 1e-9 * h;
        let keep = |pred: &dyn Fn(&Vec3) -> bool| -> Vec<u32> {
            rest.iter()
                .enumerate()
                .filter(|(_, p)| pred(p))
                .map(|(i, _)| i as u32)
                .collect()
        };
        match self {
            NodeSelector::Box { min, max, relative } => {
                let (min, max) = if *relative {
                    let b = node_bounds(rest);
                    (b.at_fraction(*min), b.at_fraction(*max))
                } else {
                    (*min, *max)
                };
                keep(&|p| (0..3).all(|k| p[k] >= min[k] - tol && p[k] <= max[k] + tol))
            }
            NodeSelector::Plane { axis, value, side } => {
                let a = axis.index();
                match side {
                    Side::Below => keep(&|p| p[a] <= value + tol),
                    Side::Above => keep(&|p| p[a] >= value - tol),
                }
            }
            NodeSelector::Face { face } => {
                let Aabb { min: lo, max: hi } = node_bounds(rest);
                let (a, is_max) = face.axis_and_max();
                if is_max {
                    keep(&|p| p[a] >= hi[a] - tol)
                } else {
                    keep(&|p| p[a] <= lo[a] + tol)
                }
            }
            NodeSelector::Indices { nodes } => {
                let mut out: Vec<u32> = nodes
                    .iter()
                    .copied()
                    .filter(|&i| (i as usize) < rest.len())
                    .collect();
                out.sort_unstable();
                out.dedup();
                out
            }
            NodeSelector::LowestLayer => {
                let lo = node_bounds(rest).min;
                keep(&|p| p[2] <= lo[2] + tol)
            }
        }
    }

    /// Like [`NodeSelector::select`], but an empty selection or an index out of
    /// range is an error naming the selector.
    pub fn select_checked(&self, rest: &[Vec3], h: f64) -> Result<Vec<u32>, ConstraintError> {
        match self {
            NodeSelector::Indices { nodes } => {
                if let Some(&index) = nodes.iter().find(|&&i| i as usize >= rest.len()) {
                    return Err(ConstraintError::NodeIndex {
                        index,
                        count: rest.len(),
                    });
                }
            }
            NodeSelector::Box { min, max, .. } => {
                check_finite3("box min", min).and_then(|_| check_finite3("box max", max))?
            }
            NodeSelector::Plane { value, .. } => check_finite("plane value", *value)?,
            _ => {}
        }
        let sel = self.select(rest, h);
        if sel.is_empty() {
            let Aabb { min, max } = node_bounds(rest);
            return Err(ConstraintError::EmptySelection {
                selector: self.to_string(),
                min,
                max,
            });
        }
        Ok(sel)
    }
}

pub(crate) fn check_finite(what: &'static str, value: f64) -> Result<(), ConstraintError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ConstraintError::NotFinite { what, value })
    }
}

pub(crate) fn check_finite3(what: &'static str, v: &[f64; 3]) -> Result<(), ConstraintError> {
    v.iter().try_for_each(|&x| check_finite(what, x))
}

/// Which components of a node are held: a mask over x, y, z. In scene files
/// it is a string of the letters held, e.g. `"xyz"` (all) or `"z"` (a roller
/// that only stops motion along z).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Dofs(pub [bool; 3]);

impl Dofs {
    /// All three components.
    pub const ALL: Dofs = Dofs([true; 3]);
    /// Only the component along `axis`.
    pub fn only(axis: Axis) -> Self {
        let mut m = [false; 3];
        m[axis.index()] = true;
        Dofs(m)
    }
}

impl Default for Dofs {
    fn default() -> Self {
        Dofs::ALL
    }
}

impl TryFrom<String> for Dofs {
    type Error = ConstraintError;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        let mut m = [false; 3];
        for ch in s.chars() {
            match ch.to_ascii_lowercase() {
                'x' => m[0] = true,
                'y' => m[1] = true,
                'z' => m[2] = true,
                _ => return Err(ConstraintError::Dofs(s)),
            }
        }
        if m == [false; 3] {
            return Err(ConstraintError::Dofs(s));
        }
        Ok(Dofs(m))
    }
}

impl From<Dofs> for String {
    fn from(d: Dofs) -> String {
        ["x", "y", "z"]
            .iter()
            .zip(d.0)
            .filter(|(_, on)| *on)
            .map(|(c, _)| *c)
            .collect()
    }
}

/// How held dofs move.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Motion {
    /// Held where they are (velocity zero).
    #[default]
    Fixed,
    /// Displacement `u(t) = velocity * t` from rest (m/s).
    Velocity([f64; 3]),
    /// Displacement from rest, piecewise linear between keyframes and constant
    /// before the first and after the last one.
    Keyframes(Vec<Keyframe>),
}

/// One keyframe of a prescribed displacement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Keyframe {
    /// Time (s).
    pub time: f64,
    /// Displacement from rest at that time (m).
    pub displacement: [f64; 3],
}

impl Motion {
    fn validate(&self) -> Result<(), ConstraintError> {
        match self {
            Motion::Fixed => Ok(()),
            Motion::Velocity(v) => check_finite3("prescribed velocity", v),
            Motion::Keyframes(k) => {
                if k.is_empty() {
                    return Err(ConstraintError::Keyframes("no keyframe given".into()));
                }
                for f in k {
                    check_finite("keyframe time", f.time)?;
                    check_finite3("keyframe displacement", &f.displacement)?;
                }
                if let Some(w) = k.windows(2).find(|w| w[1].time <= w[0].time) {
                    return Err(ConstraintError::Keyframes(format!(
                        "times must increase strictly, but {} follows {}",
                        w[1].time, w[0].time
                    )));
                }
                Ok(())
            }
        }
    }

    /// Prescribed displacement from rest at time `t` (zero for `Fixed`).
    pub fn displacement(&self, t: f64) -> Vec3 {
        match self {
            Motion::Fixed => Vec3::zeros(),
            Motion::Velocity(v) => Vec3::from(*v) * t,
            Motion::Keyframes(k) => {
                let first = &k[0];
                let last = &k[k.len() - 1];
                if t <= first.time {
                    return Vec3::from(first.displacement);
                }
                if t >= last.time {
                    return Vec3::from(last.displacement);
                }
                // The first keyframe after t; it exists and is not the first.
                let j = k.partition_point(|f| f.time <= t);
                let (a, b) = (&k[j - 1], &k[j]);
                let s = (t - a.time) / (b.time - a.time);
                Vec3::from(a.displacement) * (1.0 - s) + Vec3::from(b.displacement) * s
            }
        }
    }
}

/// A user-facing boundary condition: hold the `dofs` of the selected nodes and
/// move them by `motion`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConstraintSpec {
    /// Which nodes.
    pub select: NodeSelector,
    /// Which components (default: all three).
    #[serde(default)]
    pub dofs: Dofs,
    /// How they move (default: fixed).
    #[serde(default)]
    pub motion: Motion,
}

impl ConstraintSpec {
    /// All dofs of the selected nodes fixed.
    pub fn fixed(select: NodeSelector) -> Self {
        Self {
            select,
            dofs: Dofs::ALL,
            motion: Motion::Fixed,
        }
    }
    /// A roller: only the component along `axis` fixed.
    pub fn roller(select: NodeSelector, axis: Axis) -> Self {
        Self {
            select,
            dofs: Dofs::only(axis),
            motion: Motion::Fixed,
        }
    }
}

/// Resolved constraints: for every node and component, whether it is held and
/// by which motion.
///
/// Stored as one byte per node (the explicit step reads every node's mask
/// twice per sub-step, and most nodes are free) and a list of the held nodes
/// with their motions, instead of a motion slot per component of every node
/// (24 bytes per node).
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints {
    /// Per node: bit `d` set when component `d` is held.
    held_bits: Vec<u8>,
    /// The nodes with a held component, in increasing order.
    held_nodes: Vec<u32>,
    /// For each of `held_nodes`, per component: `None` free, `Some(k)` held
    /// by `motions[k]`.
    held_by: Vec<[Option<u32>; 3]>,
    motions: Vec<Motion>,
    num_held: usize,
}

impl Constraints {
    /// No constraint on any of `num_nodes` nodes.
    pub fn none(num_nodes: usize) -> Self {
        Self {
            held_bits: vec![0; num_nodes],
            held_nodes: Vec::new(),
            held_by: Vec::new(),
            motions: Vec::new(),
            num_held: 0,
        }
    }

    /// Resolves specs against rest positions `rest` of a lattice of edge `h`.
    /// Later specs override earlier ones on the same dof.
    pub fn resolve(
        specs: &[ConstraintSpec],
        rest: &[Vec3],
        h: f64,
    ) -> Result<Self, ConstraintError> {
        let mut c = Self::none(rest.len());
        for spec in specs {
            let nodes = spec.select.select_checked(rest, h)?;
            c.hold(&nodes, spec.dofs, spec.motion.clone())?;
        }
        Ok(c)
    }

    /// Holds the `dofs` of `nodes` with `motion` (overriding earlier holds).
    pub fn hold(
        &mut self,
        nodes: &[u32],
        dofs: Dofs,
        motion: Motion,
    ) -> Result<(), ConstraintError> {
        motion.validate()?;
        if let Some(&index) = nodes.iter().find(|&&i| i as usize >= self.held_bits.len()) {
            return Err(ConstraintError::NodeIndex {
                index,
                count: self.held_bits.len(),
            });
        }
        let k = self.motions.len() as u32;
        self.motions.push(motion);
        let mut by_node: std::collections::BTreeMap<u32, [Option<u32>; 3]> = self
            .held_nodes
            .iter()
            .copied()
            .zip(self.held_by.iter().copied())
            .collect();
        for &n in nodes {
            let entry = by_node.entry(n).or_insert([None; 3]);
            for (d, (by, &held)) in entry.iter_mut().zip(&dofs.0).enumerate() {
                if held {
                    *by = Some(k);
                    self.held_bits[n as usize] |= 1 << d;
                }
            }
        }
        by_node.retain(|_, by| by.iter().any(Option::is_some));
        (self.held_nodes, self.held_by) = by_node.into_iter().unzip();
        self.num_held = self
            .held_by
            .iter()
            .flatten()
            .filter(|h| h.is_some())
            .count();
        Ok(())
    }

    /// The constraints of several bodies side by side: `parts[b]` holds the
    /// nodes of body `b`, which follow those of the bodies before it (as in
    /// [`crate::Model::union`]).
    pub fn union(parts: &[Constraints]) -> Self {
        let mut out = Self::none(0);
        for part in parts {
            let motion_shift = out.motions.len() as u32;
            let node_shift = out.held_bits.len() as u32;
            out.held_bits.extend_from_slice(&part.held_bits);
            out.held_nodes
                .extend(part.held_nodes.iter().map(|n| n + node_shift));
            out.held_by.extend(
                part.held_by
                    .iter()
                    .map(|h| h.map(|k| k.map(|k| k + motion_shift))),
            );
            out.motions.extend_from_slice(&part.motions);
            out.num_held += part.num_held;
        }
        out
    }

    /// Fixes all dofs of `nodes`.
    pub fn fix(&mut self, nodes: &[u32]) -> Result<(), ConstraintError> {
        self.hold(nodes, Dofs::ALL, Motion::Fixed)
    }

    /// Number of nodes this applies to.
    pub fn num_nodes(&self) -> usize {
        self.held_bits.len()
    }

    /// Number of held dofs (components).
    pub fn num_held_dofs(&self) -> usize {
        self.num_held
    }

    /// Whether component `d` of node `n` is held.
    #[inline]
    pub fn is_held(&self, n: usize, d: usize) -> bool {
        self.held_bits[n] & (1 << d) != 0
    }

    /// The per-component held mask of node `n`.
    #[inline]
    pub fn mask(&self, n: usize) -> [bool; 3] {
        let bits = self.held_bits[n];
        [bits & 1 != 0, bits & 2 != 0, bits & 4 != 0]
    }

    /// Every node's held components as bits (bit `d` for component `d`),
    /// for loops over all nodes.
    pub fn mask_bits(&self) -> &[u8] {
        &self.held_bits
    }

    /// The nodes with at least one held component, in increasing order.
    pub fn held_nodes(&self) -> &[u32] {
        &self.held_nodes
    }

    /// Nodes with every component held.
    pub fn fully_fixed_nodes(&self) -> Vec<u32> {
        self.held_nodes
            .iter()
            .copied()
            .filter(|&n| self.held_bits[n as usize] == 0b111)
            .collect()
    }

    /// Whether any held dof moves (i.e. is not [`Motion::Fixed`]).
    pub fn has_moving(&self) -> bool {
        self.motions.iter().any(|m| !matches!(m, Motion::Fixed))
    }

    /// Position and velocity that the held components of node `n` must have
    /// at time `t`, given its rest position and its current position `x` (a
    /// fixed component keeps its current value). Free components are returned
    /// unchanged from `x` and `v`. The velocity of a moving component is the
    /// mean velocity over `[t - dt, t]` (exact for piecewise linear motion
    /// whose kinks fall on step boundaries).
    #[inline]
    pub fn prescribe(&self, n: usize, t: f64, dt: f64, rest: &Vec3, x: &mut Vec3, v: &mut Vec3) {
        if self.held_bits[n] == 0 {
            return;
        }
        let Ok(slot) = self.held_nodes.binary_search(&(n as u32)) else {
            return;
        };
        self.prescribe_slot(slot, t, dt, rest, x, v);
    }

    /// [`Constraints::prescribe`] for every held node of `x` and `v` (one
    /// entry per node), visiting only the held ones.
    pub fn prescribe_all(&self, t: f64, dt: f64, rest: &[Vec3], x: &mut [Vec3], v: &mut [Vec3]) {
        for (slot, &n) in self.held_nodes.iter().enumerate() {
            let n = n as usize;
            self.prescribe_slot(slot, t, dt, &rest[n], &mut x[n], &mut v[n]);
        }
    }

    #[inline]
    fn prescribe_slot(
        &self,
        slot: usize,
        t: f64,
        dt: f64,
        rest: &Vec3,
        x: &mut Vec3,
        v: &mut Vec3,
    ) {
        for d in 0..3 {
            if let Some(k) = self.held_by[slot][d] {
                match &self.motions[k as usize] {
                    Motion::Fixed => v[d] = 0.0,
                    m => {
                        let u1 = m.displacement(t)[d];
                        x[d] = rest[d] + u1;
                        v[d] = if dt > 0.0 {
                            (u1 - m.displacement(t - dt)[d]) / dt
                        } else {
                            0.0
                        };
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> Vec<Vec3> {
        let mut v = Vec::new();
        for z in 0..=n {
            for y in 0..=n {
                for x in 0..=n {
                    v.push(Vec3::new(x as f64, y as f64, z as f64) * 0.5);
                }
            }
        }
        v
    }

    #[test]
    fn selectors_pick_layers() {
        let p = grid(2);
        assert_eq!(NodeSelector::LowestLayer.select(&p, 0.5).len(), 9);
        assert_eq!(
            NodeSelector::face(Face::XMax).select(&p, 0.5),
            NodeSelector::Plane {
                axis: Axis::X,
                value: 1.0,
                side: Side::Above
            }
            .select(&p, 0.5)
        );
        let b = NodeSelector::boxed([0.0, 0.0, 0.0], [0.5, 0.5, 0.5]);
        assert_eq!(b.select(&p, 0.5).len(), 8);
        // The same box as fractions of the grid's bounding box (0..1 m).
        let relative = NodeSelector::Box {
            min: [0.0; 3],
            max: [0.5; 3],
            relative: true,
        };
        assert_eq!(relative.select(&p, 0.5), b.select(&p, 0.5));
        let empty = NodeSelector::boxed([5.0; 3], [6.0; 3]);
        let err = empty.select_checked(&p, 0.5).unwrap_err();
        assert!(err.to_string().contains("box"), "{err}");
        assert!(matches!(
            NodeSelector::indices(vec![1, 999]).select_checked(&p, 0.5),
            Err(ConstraintError::NodeIndex { index: 999, .. })
        ));
    }

    #[test]
    fn selectors_read_from_scene_tables() {
        let read = |t: &str| toml::from_str::<NodeSelector>(t).map_err(|e| e.to_string());
        assert_eq!(
            read("kind = \"lowest_layer\"").unwrap(),
            NodeSelector::LowestLayer
        );
        assert_eq!(
            read("kind = \"box\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]").unwrap(),
            NodeSelector::boxed([0.0; 3], [1.0; 3])
        );
        assert_eq!(
            read("kind = \"indices\"\nnodes = [3, 1]").unwrap(),
            NodeSelector::indices(vec![3, 1])
        );
        for bad in [
            "kind = \"lowest_layer\"\nheight = 2",
            "kind = \"box\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nsize = 2",
            "kind = \"face\"\nface = \"x\"",
            "kind = \"blob\"",
        ] {
            assert!(read(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn keyframes_interpolate_and_validate() {
        let m = Motion::Keyframes(vec![
            Keyframe {
                time: 0.0,
                displacement: [0.0; 3],
            },
            Keyframe {
                time: 2.0,
                displacement: [2.0, 0.0, -4.0],
            },
        ]);
        assert_eq!(m.displacement(1.0), Vec3::new(1.0, 0.0, -2.0));
        assert_eq!(m.displacement(5.0), Vec3::new(2.0, 0.0, -4.0));
        assert_eq!(m.displacement(-1.0), Vec3::zeros());
        let bad = Motion::Keyframes(vec![
            Keyframe {
                time: 1.0,
                displacement: [0.0; 3],
            },
            Keyframe {
                time: 1.0,
                displacement: [0.0; 3],
            },
        ]);
        assert!(bad.validate().is_err());
    }

    #[test]
    fn later_constraint_wins_and_rollers_hold_one_component() {
        let p = grid(1);
        let specs = vec![
            ConstraintSpec::roller(NodeSelector::LowestLayer, Axis::Z),
            ConstraintSpec {
                select: NodeSelector::indices(vec![0]),
                dofs: Dofs::ALL,
                motion: Motion::Velocity([1.0, 0.0, 0.0]),
            },
        ];
        let c = Constraints::resolve(&specs, &p, 0.5).unwrap();
        assert_eq!(c.num_held_dofs(), 4 + 2);
        assert_eq!(c.mask(1), [false, false, true]);
        let (mut x, mut v) = (p[0], Vec3::zeros());
        c.prescribe(0, 2.0, 0.5, &p[0], &mut x, &mut v);
        assert_eq!(x, Vec3::new(2.0, 0.0, 0.0));
        assert_eq!(v, Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(c.fully_fixed_nodes(), vec![0]);
    }

    #[test]
    fn union_keeps_each_bodys_holds_and_prescribe_all_matches_each_node() {
        let p = grid(1);
        let mut a = Constraints::none(p.len());
        a.hold(
            &[3, 1],
            Dofs([false, true, false]),
            Motion::Velocity([0.0, 2.0, 0.0]),
        )
        .unwrap();
        a.fix(&[1]).unwrap();
        let mut b = Constraints::none(p.len());
        b.hold(&[0], Dofs::ALL, Motion::Velocity([1.0, 0.0, 0.0]))
            .unwrap();
        // Holding nothing new leaves the lists as they were.
        b.hold(&[], Dofs::ALL, Motion::Fixed).unwrap();
        let u = Constraints::union(&[a.clone(), b]);
        assert_eq!(u.num_nodes(), 2 * p.len());
        assert_eq!(u.held_nodes(), &[1, 3, p.len() as u32]);
        assert_eq!(u.num_held_dofs(), 3 + 1 + 3);
        assert_eq!(u.mask(3), [false, true, false]);
        assert_eq!(u.mask(1), [true, true, true]);
        assert_eq!(u.mask(p.len()), [true, true, true]);
        assert_eq!(u.mask(p.len() + 3), [false; 3]);
        assert_eq!(u.fully_fixed_nodes(), vec![1, p.len() as u32]);

        let rest: Vec<Vec3> = p.iter().chain(&p).copied().collect();
        let x0: Vec<Vec3> = rest.iter().map(|r| r + Vec3::new(0.1, 0.2, 0.3)).collect();
        let v0 = vec![Vec3::new(7.0, 8.0, 9.0); rest.len()];
        let (mut x_all, mut v_all) = (x0.clone(), v0.clone());
        u.prescribe_all(1.5, 0.5, &rest, &mut x_all, &mut v_all);
        for n in 0..rest.len() {
            let (mut x, mut v) = (x0[n], v0[n]);
            u.prescribe(n, 1.5, 0.5, &rest[n], &mut x, &mut v);
            assert_eq!((x, v), (x_all[n], v_all[n]), "node {n}");
        }
        // The second body's node 0 follows its own motion, not the first's.
        assert_eq!(x_all[p.len()], rest[p.len()] + Vec3::new(1.5, 0.0, 0.0));
        assert_eq!(x_all[3].y, rest[3].y + 3.0);
        assert_eq!(v_all[1], Vec3::zeros());
        assert_eq!(x_all[2], x0[2]);
    }

    #[test]
    fn dofs_parse() {
        assert_eq!(
            Dofs::try_from("xz".to_string()).unwrap(),
            Dofs([true, false, true])
        );
        assert!(Dofs::try_from("w".to_string()).is_err());
        assert!(Dofs::try_from(String::new()).is_err());
        assert_eq!(String::from(Dofs::ALL), "xyz");
    }
}
