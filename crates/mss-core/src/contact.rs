//! Contact with rigid obstacles: a ground plane, spheres, boxes, capsules
//! and closed triangle meshes ([`MeshObstacle`], parry3d's queries), fixed,
//! moving along a path or steered by hand ([`Steered`]), with Coulomb
//! friction and contact damping.
//!
//! Contact is a penalty on the lattice's boundary nodes ([`Model::boundary_nodes`]),
//! or on the embedded surface's vertices, whose forces their cells' nodes
//! share by the trilinear weights ([`ContactPoints`]):
//! a node at depth `d > 0` inside an obstacle is pushed out along the
//! obstacle's outward normal `n` with the force `f_n = k d - c v_n`
//! (`k` the node's contact stiffness, proportional to its mass, `v_n` the normal velocity relative to the
//! obstacle, `c = 2 zeta sqrt(k m)` for the node's mass `m` and the damping
//! ratio `zeta`; never pulling: `f_n >= 0`).
//!
//! Friction is the stick-slip law of an anchored tangential spring: when a
//! node first touches, an anchor is set where it touched (in the obstacle's
//! moving frame). While `|k delta| <= mu_s f_n`, with `delta` the tangential
//! offset from the anchor, the node sticks with the force `-k delta`; beyond
//! it slides with the kinetic force `-mu_k f_n delta / |delta|` and the
//! anchor follows it ([`Contact::update_anchors`], after every step). So a
//! block on an incline stays put while `tan(angle) < mu_s`, and slides with
//! the acceleration `g (sin - mu_k cos)` above. The anchors are part of the
//! [`State`](crate::solver::State) (`contact`), so a step depends on nothing
//! else.
//!
//! Derivatives (for Newton) are exact for the normal force (`-k n n^T` plus
//! `f_n dn/dx` on curved obstacles), for its damping (`-(c / dt) n n^T` in
//! implicit steps, and the normal velocity's change as the normal turns)
//! and for friction, sticking or sliding, including the turning of the
//! normal.
//! The explicit integrator uses them too: it updates each touching node
//! implicitly ([`Contact::node_point_force`], [`crate::solver::Explicit`]),
//! so that contact, however stiff, does not limit its step.
//!
//! ```
//! use mss_core::contact::{Contact, ContactSettings, Plane};
//! use mss_core::{Material, Model, Vec3};
//! use mss_core::Volumetric;
//!
//! let lattice = hexmesh::Lattice::block([2, 2, 2], 0.05, [0.0, 0.0, -0.001]).unwrap();
//! let model = Model::new(&lattice, Material::new(1e5, 0.3, 1000.0).unwrap(), &Volumetric).unwrap();
//! let ground = Plane::new(Vec3::zeros(), Vec3::z()).unwrap();
//! let contact = Contact::new(&model, vec![(Box::new(ground), ContactSettings::for_model(&model))]);
//! // The bottom nodes are 1 mm deep in the ground: pushed up.
//! let mut f = vec![Vec3::zeros(); model.num_nodes()];
//! let v = vec![Vec3::zeros(); model.num_nodes()];
//! contact.add_forces(0.0, model.rest_positions(), &v, &[], &mut f);
//! assert!(f.iter().all(|fi| fi.z >= 0.0) && f.iter().any(|fi| fi.z > 0.0));
//! ```

use std::fmt::Debug;

use crate::{BlockCsr, Mat3, Model, Vec3};

mod bodies;
mod pair_tangent;
pub(crate) use bodies::StepPairs;
pub use bodies::{
    BodyContact, BodyContactError, DEFAULT_BODY_FREQUENCY_FRACTION, DEPTH_LIMIT, PERSIST_LIMIT,
    SELF_EXCLUSION, TRIANGLE_PREFERENCE,
};

/// The `velocity` and `offset` of an obstacle that follows its `path`.
macro_rules! path_motion {
    () => {
        #[inline]
        fn velocity(&self, t: f64) -> Vec3 {
            self.path.velocity(t)
        }
        #[inline]
        fn offset(&self, t: f64) -> Vec3 {
            self.path.offset(t)
        }
    };
}

/// How deep a point is inside an obstacle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Penetration {
    /// Depth (m), > 0.
    pub depth: f64,
    /// Outward unit normal of the obstacle's surface nearest to the point.
    pub normal: Vec3,
    /// Derivative of the normal with respect to the point (1/m): zero for
    /// flat faces, `(I - n n^T) / r` on a sphere of radius `r` around the point.
    pub normal_gradient: Mat3,
}

/// A rigid obstacle, the plug point for shapes.
///
/// Contract: [`penetration`](Self::penetration) is `Some` exactly for points
/// strictly inside the obstacle at time `t`, with a positive finite depth,
/// a unit normal and its derivative, and never panics;
/// [`velocity`](Self::velocity) is the velocity of the obstacle's material at
/// `t` (obstacles translate; the default is at rest).
pub trait Obstacle: Send + Sync + Debug {
    /// Short description for logs and messages.
    fn name(&self) -> String;
    /// How deep `p` is inside the obstacle at time `t`, if it is.
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration>;
    /// Whether `p` is inside the obstacle at time `t`: exactly
    /// `penetration(t, p).is_some()`, which is what the default does. The
    /// explicit step asks it of every surface node each sub-step, so
    /// obstacles whose test is cheaper than their penetration (its normal
    /// and their gradient) override it.
    fn contains(&self, t: f64, p: Vec3) -> bool {
        self.penetration(t, p).is_some()
    }
    /// Appends to `inside`, in order, the `k` for which `x[nodes[k]]` is
    /// inside the obstacle at time `t`: exactly those of which
    /// [`contains`](Self::contains) says so, which is what the default asks.
    /// The explicit step asks it of all the surface nodes each sub-step;
    /// obstacles override it to find their placement at `t` once rather than
    /// per node.
    fn nodes_inside(&self, t: f64, x: &[Vec3], nodes: &[u32], inside: &mut Vec<u32>) {
        for (k, &n) in nodes.iter().enumerate() {
            if self.contains(t, x[n as usize]) {
                inside.push(k as u32);
            }
        }
    }
    /// Velocity of the obstacle at time `t` (m/s).
    fn velocity(&self, t: f64) -> Vec3 {
        let _ = t;
        Vec3::zeros()
    }
    /// Offset of the obstacle from its initial placement at time `t` (m).
    fn offset(&self, t: f64) -> Vec3 {
        let _ = t;
        Vec3::zeros()
    }
    /// This obstacle as a [`Plane`], when it is exactly that plane (its
    /// point, normal and path): a [`Contact`] then asks the plane itself,
    /// not through the trait object, and its queries are inlined into the
    /// node contact's Newton loop. Through the trait object, each answer
    /// came back through memory and reading it stalled the store
    /// forwarding: a fifth of a frame was the ground's contact. The
    /// default, `None`, is always correct.
    fn as_plane(&self) -> Option<&Plane> {
        None
    }
}

/// A prescribed translation: offsets at keyframe times, linear in between,
/// held before the first and after the last.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Path {
    keys: Vec<(f64, Vec3)>,
}

impl Path {
    /// A path through `(time, offset)` keyframes (times strictly increasing,
    /// all finite); `None` otherwise.
    pub fn new(keys: Vec<(f64, Vec3)>) -> Option<Self> {
        let finite = keys
            .iter()
            .all(|(t, o)| t.is_finite() && o.iter().all(|c| c.is_finite()));
        let increasing = keys.windows(2).all(|w| w[1].0 > w[0].0);
        (finite && increasing).then_some(Self { keys })
    }

    /// No motion.
    pub fn fixed() -> Self {
        Self::default()
    }

    /// Offset at `t`.
    pub fn offset(&self, t: f64) -> Vec3 {
        let Some(&(t0, o0)) = self.keys.first() else {
            return Vec3::zeros();
        };
        if t <= t0 {
            return o0;
        }
        for w in self.keys.windows(2) {
            let ((ta, a), (tb, b)) = (w[0], w[1]);
            if t <= tb {
                return a + (b - a) * ((t - ta) / (tb - ta));
            }
        }
        self.keys.last().map_or(Vec3::zeros(), |k| k.1)
    }

    /// Velocity at `t` (of the segment `t` lies in; zero outside the keys).
    pub fn velocity(&self, t: f64) -> Vec3 {
        for w in self.keys.windows(2) {
            let ((ta, a), (tb, b)) = (w[0], w[1]);
            if t >= ta && t < tb {
                return (b - a) / (tb - ta);
            }
        }
        Vec3::zeros()
    }
}

/// Why an obstacle could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ObstacleError {
    /// A value is not finite or out of range.
    #[error("{0}")]
    Invalid(String),
}

fn finite(v: &Vec3) -> bool {
    v.iter().all(|c| c.is_finite())
}

/// The half-space behind a plane: `(p - point) . normal < 0` is inside.
#[derive(Debug, Clone, PartialEq)]
pub struct Plane {
    point: Vec3,
    normal: Vec3,
    path: Path,
}

impl Plane {
    /// The plane through `point` with outward `normal` (any length > 0).
    pub fn new(point: Vec3, normal: Vec3) -> Result<Self, ObstacleError> {
        let len = normal.norm();
        if !(finite(&point) && len.is_finite() && len > 0.0) {
            return Err(ObstacleError::Invalid(format!(
                "plane point {point:?} and normal {normal:?}: the point must be finite and the normal non-zero"
            )));
        }
        Ok(Self {
            point,
            normal: normal / len,
            path: Path::fixed(),
        })
    }

    /// The signed height of `p` over the plane at time `t` (negative
    /// inside).
    #[inline]
    fn height(&self, t: f64, p: Vec3) -> f64 {
        self.height_at(self.path.offset(t), p)
    }

    /// [`Plane::height`] with the path's offset at the time given.
    #[inline]
    fn height_at(&self, offset: Vec3, p: Vec3) -> f64 {
        (p - self.point - offset).dot(&self.normal)
    }
}

/// A ball.
#[derive(Debug, Clone, PartialEq)]
pub struct Sphere {
    centre: Vec3,
    radius: f64,
    path: Path,
}

impl Sphere {
    /// The ball of `radius` (m) around `centre`.
    pub fn new(centre: Vec3, radius: f64) -> Result<Self, ObstacleError> {
        if !(finite(&centre) && radius.is_finite() && radius > 0.0) {
            return Err(ObstacleError::Invalid(format!(
                "sphere centre {centre:?}, radius {radius}: the centre must be finite and the radius positive"
            )));
        }
        Ok(Self {
            centre,
            radius,
            path: Path::fixed(),
        })
    }
}

/// An axis-aligned box.
#[derive(Debug, Clone, PartialEq)]
pub struct Cuboid {
    min: Vec3,
    max: Vec3,
    path: Path,
}

impl Cuboid {
    /// The box `min ..= max` (m).
    pub fn new(min: Vec3, max: Vec3) -> Result<Self, ObstacleError> {
        if !(finite(&min) && finite(&max) && (0..3).all(|k| min[k] < max[k])) {
            return Err(ObstacleError::Invalid(format!(
                "box {min:?} .. {max:?}: corners must be finite with min < max"
            )));
        }
        Ok(Self {
            min,
            max,
            path: Path::fixed(),
        })
    }
}

/// The points within `radius` of the segment `a b`.
#[derive(Debug, Clone, PartialEq)]
pub struct Capsule {
    a: Vec3,
    b: Vec3,
    radius: f64,
    path: Path,
}

impl Capsule {
    /// The capsule around the segment `a b` (m) of `radius` (m).
    pub fn new(a: Vec3, b: Vec3, radius: f64) -> Result<Self, ObstacleError> {
        if !(finite(&a) && finite(&b) && radius.is_finite() && radius > 0.0) {
            return Err(ObstacleError::Invalid(format!(
                "capsule {a:?} .. {b:?}, radius {radius}: the ends must be finite and the radius positive"
            )));
        }
        Ok(Self {
            a,
            b,
            radius,
            path: Path::fixed(),
        })
    }
}

/// The solid bounded by a closed triangle surface (a tool, a bone, a
/// table), with parry3d's point queries: a point is inside by the mesh's
/// pseudo-normals, and is pushed toward the nearest surface point. Faces are
/// flat, so the normal's derivative is taken as zero (exact inside a face).
pub struct MeshObstacle {
    mesh: parry3d_f64::shape::TriMesh,
    triangles: usize,
    path: Path,
}

impl Debug for MeshObstacle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshObstacle")
            .field("triangles", &self.triangles)
            .finish()
    }
}

impl MeshObstacle {
    /// The solid inside `mesh`, which must be closed (its orientation is
    /// repaired to face outward).
    pub fn new(mesh: &hexmesh::TriMesh) -> Result<Self, ObstacleError> {
        let (oriented, report) = hexmesh::winding::orient(mesh);
        if !report.closed || report.nonmanifold_edges > 0 {
            return Err(ObstacleError::Invalid(format!(
                "the obstacle mesh must be a closed surface ({} patches, {} edges shared by more than two triangles)",
                report.patches, report.nonmanifold_edges
            )));
        }
        if oriented.vertices.iter().flatten().any(|c| !c.is_finite()) {
            return Err(ObstacleError::Invalid(
                "the obstacle mesh has non-finite vertices".into(),
            ));
        }
        // Outward winding: a negative volume means the repair chose inward.
        let mut triangles = oriented.triangles.clone();
        if oriented.signed_volume() < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let vertices = oriented
            .vertices
            .iter()
            .map(|p| parry3d_f64::math::Vector::new(p[0], p[1], p[2]))
            .collect();
        let count = triangles.len();
        let mesh = parry3d_f64::shape::TriMesh::with_flags(
            vertices,
            triangles,
            parry3d_f64::shape::TriMeshFlags::ORIENTED,
        )
        .map_err(|e| ObstacleError::Invalid(format!("the obstacle mesh: {e}")))?;
        Ok(Self {
            mesh,
            triangles: count,
            path: Path::fixed(),
        })
    }
}

impl Obstacle for MeshObstacle {
    fn name(&self) -> String {
        format!("mesh of {} triangles", self.triangles)
    }
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        use parry3d_f64::query::PointQuery;
        let q = p - self.path.offset(t);
        let local = parry3d_f64::math::Vector::new(q.x, q.y, q.z);
        let proj = self.mesh.project_local_point(local, false);
        if !proj.is_inside {
            return None;
        }
        let to_surface = Vec3::new(proj.point.x - q.x, proj.point.y - q.y, proj.point.z - q.z);
        let depth = to_surface.norm();
        (depth > 0.0 && depth.is_finite()).then(|| Penetration {
            depth,
            normal: to_surface / depth,
            normal_gradient: Mat3::zeros(),
        })
    }
    path_motion!();
}

macro_rules! moving {
    ($($t:ty),*) => {$(
        impl $t {
            /// The same obstacle following `path` (offsets from its placement).
            pub fn moving(mut self, path: Path) -> Self {
                self.path = path;
                self
            }
        }
    )*};
}
moving!(Plane, Sphere, Cuboid, Capsule, MeshObstacle);

/// Any obstacle carried along a [`Path`]: it is asked about the point in its
/// own frame (the point less the path's offset), and moves with the path's
/// velocity. For obstacles written outside this crate; the built-in ones
/// follow a path through their own `moving`.
#[derive(Debug)]
pub struct Moving {
    inner: Box<dyn Obstacle>,
    path: Path,
}

impl Moving {
    /// `inner` following `path`.
    pub fn new(inner: Box<dyn Obstacle>, path: Path) -> Self {
        Self { inner, path }
    }
}

impl Obstacle for Moving {
    fn name(&self) -> String {
        format!("moving {}", self.inner.name())
    }
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        self.inner.penetration(t, p - self.path.offset(t))
    }
    path_motion!();
}

/// Penetration of a ball of `radius` around `c` by `p` (also the capsule's
/// round parts); `along` is the segment direction for a capsule's side.
fn ball(c: Vec3, radius: f64, p: Vec3, along: Option<Vec3>) -> Option<Penetration> {
    let d = p - c;
    let r = d.norm();
    if r >= radius || !r.is_finite() {
        return None;
    }
    // At the very centre every direction is as near: push up.
    let normal = if r > 1e-12 * radius { d / r } else { Vec3::z() };
    let mut tangent = Mat3::identity() - normal * normal.transpose();
    if let Some(u) = along {
        tangent -= u * u.transpose();
    }
    let normal_gradient = if r > 1e-12 * radius {
        tangent / r
    } else {
        Mat3::zeros()
    };
    Some(Penetration {
        depth: radius - r,
        normal,
        normal_gradient,
    })
}

impl Obstacle for Plane {
    fn name(&self) -> String {
        format!(
            "plane through {:?} with normal {:?}",
            self.point.as_slice(),
            self.normal.as_slice()
        )
    }
    #[inline]
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        let s = self.height(t, p);
        (s < 0.0).then(|| Penetration {
            depth: -s,
            normal: self.normal,
            normal_gradient: Mat3::zeros(),
        })
    }
    fn contains(&self, t: f64, p: Vec3) -> bool {
        self.height(t, p) < 0.0
    }
    fn nodes_inside(&self, t: f64, x: &[Vec3], nodes: &[u32], inside: &mut Vec<u32>) {
        // The offset found once.
        let offset = self.path.offset(t);
        for (k, &n) in nodes.iter().enumerate() {
            if self.height_at(offset, x[n as usize]) < 0.0 {
                inside.push(k as u32);
            }
        }
    }
    path_motion!();
    fn as_plane(&self) -> Option<&Plane> {
        Some(self)
    }
}

impl Sphere {
    /// Whether `p` is inside the ball when its centre is at `centre`
    /// (`ball`'s test: a NaN distance is not inside).
    fn contains_around(&self, centre: Vec3, p: Vec3) -> bool {
        (p - centre).norm() < self.radius
    }
}

impl Obstacle for Sphere {
    fn name(&self) -> String {
        format!("sphere of radius {} m", self.radius)
    }
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        ball(self.centre + self.path.offset(t), self.radius, p, None)
    }
    fn contains(&self, t: f64, p: Vec3) -> bool {
        self.contains_around(self.centre + self.path.offset(t), p)
    }
    fn nodes_inside(&self, t: f64, x: &[Vec3], nodes: &[u32], inside: &mut Vec<u32>) {
        let centre = self.centre + self.path.offset(t);
        for (k, &n) in nodes.iter().enumerate() {
            if self.contains_around(centre, x[n as usize]) {
                inside.push(k as u32);
            }
        }
    }
    path_motion!();
}

impl Obstacle for Cuboid {
    fn name(&self) -> String {
        "box".to_owned()
    }
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        let o = self.path.offset(t);
        let (lo, hi) = (self.min + o, self.max + o);
        if !(0..3).all(|k| p[k] > lo[k] && p[k] < hi[k]) {
            return None;
        }
        // Out through the nearest face.
        let mut best = (f64::INFINITY, 0usize, 1.0);
        for k in 0..3 {
            for (d, sign) in [(p[k] - lo[k], -1.0), (hi[k] - p[k], 1.0)] {
                if d < best.0 {
                    best = (d, k, sign);
                }
            }
        }
        let mut normal = Vec3::zeros();
        normal[best.1] = best.2;
        Some(Penetration {
            depth: best.0,
            normal,
            normal_gradient: Mat3::zeros(),
        })
    }
    path_motion!();
}

impl Obstacle for Capsule {
    fn name(&self) -> String {
        format!("capsule of radius {} m", self.radius)
    }
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        let o = self.path.offset(t);
        let (a, b) = (self.a + o, self.b + o);
        let ab = b - a;
        let len2 = ab.norm_squared();
        let s = if len2 > 0.0 {
            ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let side = (s > 0.0 && s < 1.0).then(|| ab / len2.sqrt());
        ball(a + ab * s, self.radius, p, side)
    }
    path_motion!();
}

/// Contact parameters of one obstacle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSettings {
    /// Penalty stiffness (N/m) of a boundary node of the mean boundary-node
    /// mass; each node's is scaled by its mass, so that every node touches
    /// with the same frequency (and sinks equally under its weight): a
    /// corner node, an eighth of a cell's mass, is not the one that sets the
    /// explicit step.
    pub stiffness: f64,
    /// Static friction coefficient (>= 0).
    pub friction_static: f64,
    /// Kinetic friction coefficient (0 <= mu_k <= mu_s).
    pub friction_kinetic: f64,
    /// Damping ratio of the normal contact spring (0 = elastic contact).
    pub damping_ratio: f64,
}

/// Default contact frequency as a fraction of the bound of the lattice's
/// highest one: a resting body sinks by `g / omega^2` (micrometres), and a
/// pressing obstacle sinks into it by a fraction of the indentation. The
/// explicit step integrates node contact implicitly, so this stiffness does
/// not shorten it; contact of surface vertices does, by about 1.7
/// ([`crate::solver::CONTACT_RESOLUTION`]).
pub const DEFAULT_FREQUENCY_FRACTION: f64 = 0.7;

/// Mean mass of the boundary nodes (kg).
fn mean_boundary_mass(model: &Model, nodes: &[u32]) -> f64 {
    let masses = model.masses();
    let sum: f64 = nodes.iter().map(|&n| masses[n as usize]).sum();
    if nodes.is_empty() {
        0.0
    } else {
        sum / nodes.len() as f64
    }
}

impl ContactSettings {
    /// Defaults for `model`: a stiffness that gives contact
    /// [`DEFAULT_FREQUENCY_FRACTION`] of the bound of the lattice's highest
    /// frequency ([`Model::omega_max_bound`]: a stiffness set by the cells'
    /// own, which the tolerance of penetration follows), friction 0.5,
    /// damping ratio 0.2.
    pub fn for_model(model: &Model) -> Self {
        let omega = DEFAULT_FREQUENCY_FRACTION * model.omega_max_bound();
        let mass = mean_boundary_mass(model, &model.boundary_nodes());
        Self {
            stiffness: mass * omega * omega,
            friction_static: 0.5,
            friction_kinetic: 0.5,
            damping_ratio: 0.2,
        }
    }

    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), ObstacleError> {
        let bad = |m: String| Err(ObstacleError::Invalid(m));
        if !(self.stiffness.is_finite() && self.stiffness > 0.0) {
            return bad(format!(
                "stiffness {} must be a positive number (N/m)",
                self.stiffness
            ));
        }
        if !(self.friction_static.is_finite() && self.friction_static >= 0.0) {
            return bad(format!("friction {} must be >= 0", self.friction_static));
        }
        if !(self.friction_kinetic >= 0.0 && self.friction_kinetic <= self.friction_static) {
            return bad(format!(
                "kinetic friction {} must be in 0 ..= the static friction {}",
                self.friction_kinetic, self.friction_static
            ));
        }
        if !(self.damping_ratio.is_finite() && self.damping_ratio >= 0.0) {
            return bad(format!("damping ratio {} must be >= 0", self.damping_ratio));
        }
        Ok(())
    }
}

/// The stick-slip friction force for the tangential offset `delta` from the
/// anchor, stiffness `k` and normal force `f_n`, and whether it slides.
#[inline(always)]
fn coulomb(delta: Vec3, k: f64, f_n: f64, s: &ContactSettings) -> (Vec3, bool) {
    let stick = delta * (-k);
    if stick.norm() <= s.friction_static * f_n {
        return (stick, false);
    }
    let len = delta.norm();
    let dir = if len > 0.0 {
        delta / len
    } else {
        Vec3::zeros()
    };
    (dir * (-s.friction_kinetic * f_n), true)
}

/// `d(friction)/dx` of [`coulomb`]'s force, given how the offset and the
/// normal force follow the point: `d_delta = d(delta)/dx` and
/// `d_fn = d(f_n)/dx` (as a column).
fn coulomb_jacobian(
    delta: Vec3,
    k: f64,
    f_n: f64,
    s: &ContactSettings,
    d_delta: &Mat3,
    d_fn: Vec3,
) -> Mat3 {
    let (_, sliding) = coulomb(delta, k, f_n, s);
    let len = delta.norm();
    if !sliding {
        return -d_delta * k;
    }
    if len == 0.0 {
        return Mat3::zeros();
    }
    let dir = delta / len;
    let mu = s.friction_kinetic;
    // -mu dir (d f_n / dx) - mu f_n d(dir)/dx, with
    // d(dir)/dx = (I - dir dir^T) d_delta / |delta|.
    let turn = (Mat3::identity() - dir * dir.transpose()) * d_delta / len;
    -(dir * d_fn.transpose()) * mu - turn * (mu * f_n)
}

/// The normal force of a penalty contact of stiffness `k` and damping `c`
/// at `depth`, the point moving along the outward normal at `v_n`, with its
/// derivatives along the depth and along `v_n`: `k depth - c v_n`, never
/// pulling, and the damping of a point moving in at most `k depth`.
///
/// Why the cap: without it the force jumped from zero to `c |v_n|` as a
/// point crossed the surface, and friction's share with it. The Newton steps
/// of an implicit step could not descend across that jump: a refined block
/// sliding on a slope (8 x 8 x 4 cells, mu = 0.5) failed its steps at 1 ms
/// and at every halving down to 62 us. Capped, the force starts from zero
/// as the point enters (as in Hunt and Crossley's contact law, whose damping
/// grows with the depth), and a point that rests or presses in deeper than
/// its damping asks for is damped as before.
#[inline(always)]
fn normal_force(k: f64, c: f64, depth: f64, v_n: f64) -> (f64, f64, f64) {
    let elastic = k * depth;
    if elastic <= 0.0 {
        return (0.0, 0.0, 0.0);
    }
    if v_n < 0.0 && -c * v_n > elastic {
        return (2.0 * elastic, 2.0 * k, 0.0);
    }
    let f = elastic - c * v_n;
    if f > 0.0 { (f, k, -c) } else { (0.0, 0.0, 0.0) }
}

/// How far behind its point a sliding point's anchor is placed (m): at the
/// kinetic limit `mu_k f_n / k`.
fn kinetic_offset(k: f64, f_n: f64, s: &ContactSettings) -> f64 {
    s.friction_kinetic * f_n / k
}

/// A point that can touch: a boundary node, or a vertex of the embedded
/// surface bound to its cell's 8 nodes by trilinear weights.
#[derive(Debug, Clone, Copy)]
struct Point {
    nodes: [u32; 8],
    weights: [f64; 8],
    /// Nodes used (1 for a node, 8 for a surface vertex).
    len: usize,
    /// Mass the point moves (kg): the node's, or the weighted nodes'.
    mass: f64,
    /// Its stiffness over the settings' `stiffness`.
    stiffness_ratio: f64,
}

impl Point {
    fn bound(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.nodes[..self.len]
            .iter()
            .zip(&self.weights[..self.len])
            .map(|(&n, &w)| (n as usize, w))
    }
    fn position(&self, x: &[Vec3]) -> Vec3 {
        if self.len == 1 && self.weights[0] == 1.0 {
            // A node point is its node: the same bits as the node's own
            // coordinates (a sum from zero would turn -0 into +0), as the
            // explicit step's node updates read them.
            return x[self.nodes[0] as usize];
        }
        self.bound().map(|(n, w)| x[n] * w).sum()
    }
}

/// Which points touch the obstacles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ContactPoints {
    /// The lattice's boundary nodes.
    #[default]
    Nodes,
    /// The embedded surface's vertices (what is rendered), their forces
    /// shared by their cells' nodes through the trilinear weights.
    Surface,
    /// Both.
    Both,
}

/// The obstacles of a problem and the points that can touch them.
#[derive(Debug)]
pub struct Contact {
    obstacles: Vec<(Placed, ContactSettings)>,
    points: Vec<Point>,
    /// Contact's part of `omega_max^2` per unit of `stiffness` (1/(s^2 N/m)):
    /// the largest Gershgorin row sum of the mapped stiffness over a node's mass.
    omega_sq_per_stiffness: f64,
    /// The same, of the surface points alone.
    surface_omega_sq_per_stiffness: f64,
    /// The same, of the node points alone.
    node_omega_sq_per_stiffness: f64,
    /// Points that are nodes.
    node_points: Vec<u32>,
    /// The node of each of `node_points`, in their order.
    node_point_nodes: Vec<u32>,
    /// Points that are surface vertices.
    surface_points: Vec<u32>,
    /// Contact between the model's bodies (and of a body with itself).
    bodies: Option<BodyContact>,
}

/// One point's force from one obstacle, and what friction did.
struct Touch {
    force: Vec3,
    normal: Vec3,
    /// Offset from the anchor.
    offset: Vec3,
    /// Its tangential part.
    delta: Vec3,
    sliding: bool,
    /// The point's velocity relative to the obstacle, and its normal part.
    v_rel: Vec3,
    v_n: f64,
}

impl Contact {
    /// Contact of `model`'s boundary nodes with `obstacles`.
    pub fn new(model: &Model, obstacles: Vec<(Box<dyn Obstacle>, ContactSettings)>) -> Self {
        Self::with_points(model, obstacles, ContactPoints::Nodes, None)
    }

    /// Contact of the chosen points with `obstacles`; `surface` is the
    /// embedded surface, needed for [`ContactPoints::Surface`] and `Both`
    /// (without it only the nodes touch). A surface vertex's stiffness is its
    /// share of the nodes' (the boundary nodes over the surface vertices), so
    /// a dense surface does not stiffen the contact.
    pub fn with_points(
        model: &Model,
        obstacles: Vec<(Box<dyn Obstacle>, ContactSettings)>,
        which: ContactPoints,
        surface: Option<&hexmesh::Embedding>,
    ) -> Self {
        let boundary = model.boundary_nodes();
        let mean = mean_boundary_mass(model, &boundary);
        let masses = model.masses();
        let ratio = |m: f64| if mean > 0.0 { m / mean } else { 1.0 };
        let mut points = Vec::new();
        // Without obstacles no point touches anything here (contact between
        // bodies has its own points): the explicit step then visits none.
        let which_nodes =
            !obstacles.is_empty() && (which != ContactPoints::Surface || surface.is_none());
        if which_nodes {
            for &n in &boundary {
                let mut nodes = [0u32; 8];
                let mut weights = [0.0; 8];
                nodes[0] = n;
                weights[0] = 1.0;
                let m = masses[n as usize];
                points.push(Point {
                    nodes,
                    weights,
                    len: 1,
                    mass: m,
                    stiffness_ratio: ratio(m),
                });
            }
        }
        if let (Some(e), true) = (
            surface,
            !obstacles.is_empty() && which != ContactPoints::Nodes,
        ) {
            let count = e.vertex_cells().len();
            let share = boundary.len() as f64 / count.max(1) as f64;
            for i in 0..count {
                let (nodes, weights) = e.vertex_weights(i);
                let m: f64 = nodes
                    .iter()
                    .zip(&weights)
                    .map(|(&n, w)| masses[n as usize] * w.abs())
                    .sum();
                points.push(Point {
                    nodes,
                    weights,
                    len: 8,
                    mass: m,
                    stiffness_ratio: ratio(m) * share.min(1.0),
                });
            }
        }
        // Gershgorin: a point of stiffness k couples its nodes a, b by
        // w_a w_b k; node a's row sums |w_a| (sum_b |w_b|) k over its points.
        let bound = |keep: fn(&Point) -> bool| {
            let mut rows = vec![0.0f64; model.num_nodes()];
            for p in points.iter().filter(|p| keep(p)) {
                let total: f64 = p.bound().map(|(_, w)| w.abs()).sum();
                for (n, w) in p.bound() {
                    rows[n] += w.abs() * total * p.stiffness_ratio;
                }
            }
            rows.iter()
                .zip(masses)
                .filter(|(_, m)| **m > 0.0)
                .map(|(r, m)| r / m)
                .fold(0.0, f64::max)
        };
        let omega_sq_per_stiffness = bound(|_| true);
        let surface_omega_sq_per_stiffness = bound(|p| p.len > 1);
        let node_omega_sq_per_stiffness = bound(|p| p.len == 1);
        let (node_points, surface_points): (Vec<u32>, Vec<u32>) =
            (0..points.len() as u32).partition(|&i| points[i as usize].len == 1);
        let node_point_nodes = node_points
            .iter()
            .map(|&i: &u32| points[i as usize].nodes[0])
            .collect();
        Self {
            obstacles: obstacles
                .into_iter()
                .map(|(o, s)| (Placed::new(o), s))
                .collect(),
            points,
            omega_sq_per_stiffness,
            surface_omega_sq_per_stiffness,
            node_omega_sq_per_stiffness,
            node_points,
            node_point_nodes,
            surface_points,
            bodies: None,
        }
    }

    /// Adds contact between the model's bodies ([`BodyContact`]); its
    /// anchors follow the obstacles' in [`State::contact`](crate::solver::State).
    pub fn with_bodies(mut self, bodies: BodyContact) -> Self {
        self.bodies = Some(bodies);
        self
    }

    /// The contact between bodies, if any.
    pub fn bodies(&self) -> Option<&BodyContact> {
        self.bodies.as_ref()
    }

    /// Entries of the anchor array that belong to the obstacles.
    fn num_obstacle_anchors(&self) -> usize {
        self.points.len() * self.obstacles.len()
    }

    /// The body contact's part of `anchors` (empty when it has none yet).
    fn body_anchors<'a>(&self, anchors: &'a [Option<Vec3>]) -> &'a [Option<Vec3>] {
        anchors.get(self.num_obstacle_anchors()..).unwrap_or(&[])
    }

    /// Whether some contact forces are integrated explicitly by the explicit
    /// solver: those of surface vertices and between bodies
    /// ([`Contact::add_explicit_forces`]).
    pub fn has_explicit_part(&self) -> bool {
        !self.surface_points.is_empty() || self.bodies.is_some()
    }

    /// Adds the forces the explicit solver integrates explicitly: the
    /// surface vertices' and those between bodies; notes in `touched` every
    /// node whose entry of `f` it changed.
    pub fn add_explicit_forces(
        &self,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
        touched: &mut Vec<u32>,
    ) {
        self.add_explicit_forces_with(None, t, x, v, anchors, f, touched);
    }

    /// [`Contact::add_explicit_forces`], with the body contact's pairs that
    /// the last sub-step's end found at these positions, when the caller
    /// vouches for them (see [`BodyContact::add_forces_with`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn add_explicit_forces_with(
        &self,
        found: Option<&StepPairs>,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
        touched: &mut Vec<u32>,
    ) {
        self.add_surface_point_forces(t, x, v, anchors, f, touched);
        if let Some(b) = &self.bodies {
            let anchors = self.body_anchors(anchors);
            match found {
                Some(found) => b.add_forces_with(found, x, v, anchors, f, touched),
                None => b.add_forces_noting(x, v, anchors, f, touched),
            }
        }
    }

    /// The surface vertices' part of [`Contact::add_explicit_forces`].
    fn add_surface_point_forces(
        &self,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
        touched: &mut Vec<u32>,
    ) {
        for &i in &self.surface_points {
            if self.add_point_forces(i as usize, t, x, v, anchors, f) {
                let point = &self.points[i as usize];
                touched.extend_from_slice(&point.nodes[..point.len]);
            }
        }
    }

    /// Updates the anchors of the body contact alone (see
    /// [`Contact::update_anchors`]).
    pub fn update_body_anchors(&self, x: &[Vec3], v: &[Vec3], anchors: &mut Vec<Option<Vec3>>) {
        let Some(b) = &self.bodies else {
            return;
        };
        if anchors.len() != self.num_anchors() {
            *anchors = vec![None; self.num_anchors()];
        }
        let start = self.num_obstacle_anchors();
        b.update_anchors(x, v, &mut anchors[start..]);
    }

    /// Anchors node point `i`, for every obstacle it has no anchor on, where
    /// it was at time `t0` (at `x0`): the explicit step's implicit node
    /// update calls it for a point that may touch during the step, so that a
    /// contact made within the step has its friction from the step's start
    /// (as [`Contact::step_anchors`] does for an implicit step). Anchored at
    /// the step's end instead, a new contact has no friction for its first
    /// step: a block hopping as it slides then loses a step of friction at
    /// every landing and slides too fast. Anchors of obstacles it does not
    /// touch are cleared again by [`Contact::update_anchors_of`].
    pub fn anchor_at_step_start(&self, i: u32, t0: f64, x0: Vec3, anchors: &mut Vec<Option<Vec3>>) {
        if anchors.len() != self.num_anchors() {
            *anchors = vec![None; self.num_anchors()];
        }
        let nobs = self.obstacles.len();
        let i = i as usize;
        for (j, (obstacle, _)) in self.obstacles.iter().enumerate() {
            let a = &mut anchors[i * nobs + j];
            if a.is_none() {
                *a = Some(x0 - obstacle.offset(t0));
            }
        }
    }

    /// Anchors the explicitly integrated contacts that are new at the end
    /// of an explicit step (at time `t1`, positions `x`, after a drift by
    /// `dt v`) where their points were at its start (see
    /// [`Contact::anchor_at_step_start`]): the surface vertices' with the
    /// obstacles and the body contact's.
    pub fn anchor_explicit_at_step_start(
        &self,
        t1: f64,
        x: &[Vec3],
        v: &[Vec3],
        dt: f64,
        anchors: &mut Vec<Option<Vec3>>,
    ) {
        self.anchor_explicit_and_add_forces(t1, x, v, dt, anchors, None);
    }

    /// The surface vertices' part of
    /// [`Contact::anchor_explicit_at_step_start`] (`anchors` of the right
    /// length).
    fn anchor_surface_points_at_step_start(
        &self,
        t1: f64,
        x: &[Vec3],
        v: &[Vec3],
        dt: f64,
        anchors: &mut [Option<Vec3>],
    ) {
        let nobs = self.obstacles.len();
        let t0 = t1 - dt;
        for &i in &self.surface_points {
            let point = &self.points[i as usize];
            let p1 = point.position(x);
            for (j, (obstacle, _)) in self.obstacles.iter().enumerate() {
                let k = i as usize * nobs + j;
                if anchors[k].is_none() && obstacle.penetration(t1, p1).is_some() {
                    let p0 = p1 - point.position(v) * dt;
                    anchors[k] = Some(p0 - obstacle.offset(t0));
                }
            }
        }
    }

    /// [`Contact::anchor_explicit_at_step_start`], then (with `forces`)
    /// [`Contact::add_explicit_forces`] at the same time and positions,
    /// with one search of the body contact's pairs for both; returns those
    /// pairs for [`Contact::update_body_anchors_with`] after the step.
    pub(crate) fn anchor_explicit_and_add_forces(
        &self,
        t1: f64,
        x: &[Vec3],
        v: &[Vec3],
        dt: f64,
        anchors: &mut Vec<Option<Vec3>>,
        forces: Option<(&mut [Vec3], &mut Vec<u32>)>,
    ) -> Option<StepPairs> {
        if anchors.len() != self.num_anchors() {
            *anchors = vec![None; self.num_anchors()];
        }
        self.anchor_surface_points_at_step_start(t1, x, v, dt, anchors);
        let forces = forces.map(|(f, touched)| {
            self.add_surface_point_forces(t1, x, v, anchors, f, touched);
            (f, touched)
        });
        let b = self.bodies.as_ref()?;
        let start = self.num_obstacle_anchors();
        Some(b.anchor_at_step_start_and_add_forces(x, v, dt, &mut anchors[start..], forces, false))
    }

    /// [`Contact::update_body_anchors`] with the pairs
    /// [`Contact::anchor_explicit_and_add_forces`] found at the positions
    /// `x`, which the caller vouches for (see
    /// [`BodyContact::update_anchors_with`]).
    pub(crate) fn update_body_anchors_with(
        &self,
        found: &StepPairs,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &mut Vec<Option<Vec3>>,
    ) {
        let Some(b) = &self.bodies else {
            return;
        };
        if anchors.len() != self.num_anchors() {
            *anchors = vec![None; self.num_anchors()];
        }
        let start = self.num_obstacle_anchors();
        b.update_anchors_with(found, x, v, &mut anchors[start..]);
    }

    /// Anchors for an implicit step from positions `x0` at time `t0`: the
    /// state's `anchors`, and for every point without one, where it is at
    /// the start. A point that touches during the step then sticks where it
    /// was (and slides past Coulomb's limit) within the step already, and
    /// friction's derivative in Newton is that of the force: a contact made
    /// during the step with its anchor following the point would have none,
    /// and a Newton tangent that says otherwise converges only linearly.
    pub fn step_anchors(
        &self,
        t0: f64,
        x0: &[Vec3],
        anchors: &[Option<Vec3>],
    ) -> Vec<Option<Vec3>> {
        let start = self.static_anchors(t0, x0);
        if anchors.len() != start.len() {
            return start;
        }
        anchors.iter().zip(start).map(|(a, s)| a.or(s)).collect()
    }

    /// Anchors for a static solve started at `x` (time `t`): every point
    /// anchored where it is, so that friction holds what starts in contact.
    pub fn static_anchors(&self, t: f64, x: &[Vec3]) -> Vec<Option<Vec3>> {
        let offsets: Vec<Vec3> = self.obstacles().map(|(o, _)| o.offset(t)).collect();
        let mut anchors: Vec<Option<Vec3>> = self
            .point_positions(x)
            .into_iter()
            .flat_map(|p| offsets.iter().map(move |o| Some(p - o)))
            .collect();
        if let Some(b) = &self.bodies {
            anchors.extend(b.static_anchors(x));
        }
        anchors
    }

    /// The obstacles (where a static solve's insertion has put them, see
    /// [`Contact::shift_obstacles`]).
    pub fn obstacles(&self) -> impl Iterator<Item = (&dyn Obstacle, &ContactSettings)> {
        self.obstacles.iter().map(|(o, s)| (o as &dyn Obstacle, s))
    }

    /// Translates obstacle `k` by `shifts[k]` (m) from wherever its path puts
    /// it, for every later query until the next call; `None` puts them all
    /// back. A static solve whose obstacles start deep in the body inserts
    /// them this way, from outside along straight lines, as a slow press
    /// would. Not for use while another solve runs on this contact.
    pub fn shift_obstacles(&self, shifts: Option<&[Vec3]>) {
        for (k, (o, _)) in self.obstacles.iter().enumerate() {
            o.set_shift(shifts.map_or(Vec3::zeros(), |s| s[k]));
        }
    }

    /// Number of points that can touch.
    pub fn num_points(&self) -> usize {
        self.points.len()
    }

    /// Positions of the points that can touch, for node positions `x`.
    pub fn point_positions(&self, x: &[Vec3]) -> Vec<Vec3> {
        self.points.iter().map(|p| p.position(x)).collect()
    }

    /// Entries of the anchor array of [`State::contact`](crate::solver::State):
    /// one per contact point and obstacle.
    pub fn num_anchors(&self) -> usize {
        self.num_obstacle_anchors() + self.bodies.as_ref().map_or(0, BodyContact::num_points)
    }

    /// What contact adds to `omega_max^2` (1/s^2): a Gershgorin bound of
    /// the contact stiffness over the nodes' masses.
    pub fn omega_sq(&self) -> f64 {
        self.max_stiffness() * self.omega_sq_per_stiffness + self.body_omega_sq()
    }

    fn body_omega_sq(&self) -> f64 {
        self.bodies.as_ref().map_or(0.0, BodyContact::omega_sq)
    }

    /// What the surface points and the contact between bodies add to
    /// `omega_max^2` (1/s^2): the part the explicit step integrates
    /// explicitly ([`Contact::add_explicit_forces`]).
    pub fn surface_omega_sq(&self) -> f64 {
        self.max_stiffness() * self.surface_omega_sq_per_stiffness + self.body_omega_sq()
    }

    /// The highest contact frequency squared of a node point (1/s^2): what
    /// the implicit node updates of the explicit step have to integrate.
    pub fn node_omega_sq(&self) -> f64 {
        self.max_stiffness() * self.node_omega_sq_per_stiffness
    }

    fn max_stiffness(&self) -> f64 {
        self.obstacles
            .iter()
            .map(|(_, s)| s.stiffness)
            .fold(0.0, f64::max)
    }

    // Inlined, as the node contact's Newton loop calls it: its answer is
    // larger than registers hold, and reading it back from memory stalled
    // the store forwarding.
    #[inline(always)]
    fn touch(
        &self,
        i: usize,
        j: usize,
        t: f64,
        x: Vec3,
        v: Vec3,
        anchor: Option<Vec3>,
    ) -> Option<(Touch, Penetration)> {
        let (obstacle, s) = &self.obstacles[j];
        let pen = obstacle.penetration(t, x)?;
        let n = pen.normal;
        let point = &self.points[i];
        let k = s.stiffness * point.stiffness_ratio;
        let c = 2.0 * s.damping_ratio * (k * point.mass).sqrt();
        let v_rel = v - obstacle.velocity(t);
        let v_n = v_rel.dot(&n);
        let (f_n, _, _) = normal_force(k, c, pen.depth, v_n);
        // The anchor lives in the obstacle's frame; a new contact starts at x.
        let a = anchor.map_or(x, |a| a + obstacle.offset(t));
        let d = x - a;
        let delta = d - n * d.dot(&n);
        let (friction, sliding) = coulomb(delta, k, f_n, s);
        Some((
            Touch {
                force: n * f_n + friction,
                normal: n,
                offset: d,
                delta,
                sliding,
                v_rel,
                v_n,
            },
            pen,
        ))
    }

    fn anchor_of(anchors: &[Option<Vec3>], k: usize) -> Option<Vec3> {
        anchors.get(k).copied().flatten()
    }

    /// Adds the contact forces at time `t`, positions `x` and velocities `v`
    /// (both absolute) to `f`; `anchors` is [`State::contact`](crate::solver::State)
    /// (empty: every contact is new).
    pub fn add_forces(
        &self,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
    ) {
        for i in 0..self.points.len() {
            self.add_point_forces(i, t, x, v, anchors, f);
        }
        if let Some(b) = &self.bodies {
            b.add_forces(x, v, self.body_anchors(anchors), f);
        }
    }

    /// Indices of the points that are lattice nodes (the explicit
    /// integrator treats their contact implicitly, node by node).
    pub fn node_points(&self) -> &[u32] {
        &self.node_points
    }

    /// Appends to `inside` the node points (indices into the points, as
    /// [`Contact::node_points`] gives them) inside any obstacle at time `t`
    /// at positions `x`, obstacle by obstacle ([`Obstacle::nodes_inside`]):
    /// a point inside two obstacles is listed twice.
    pub fn node_points_inside(&self, t: f64, x: &[Vec3], inside: &mut Vec<u32>) {
        for (o, _) in &self.obstacles {
            let from = inside.len();
            o.nodes_inside(t, x, &self.node_point_nodes, inside);
            for k in &mut inside[from..] {
                *k = self.node_points[*k as usize];
            }
        }
    }

    /// Indices of the points that are embedded-surface vertices (integrated
    /// explicitly: they share their force among 8 nodes).
    pub fn surface_points(&self) -> &[u32] {
        &self.surface_points
    }

    /// Whether point `i` has a friction anchor on any obstacle in `anchors`
    /// ([`State::contact`](crate::solver::State); false where it holds none).
    pub fn is_anchored(&self, i: u32, anchors: &[Option<Vec3>]) -> bool {
        let nobs = self.obstacles.len();
        let i = i as usize;
        anchors
            .get(i * nobs..(i + 1) * nobs)
            .is_some_and(|a| a.iter().any(Option::is_some))
    }

    /// The node of a node point (see [`Contact::node_points`]); for a
    /// surface vertex, the first of its cell's nodes.
    pub fn point_node(&self, i: u32) -> u32 {
        self.points[i as usize].nodes[0]
    }

    /// The force (N) on node point `i` at position `x` and velocity `v`
    /// (both absolute) at time `t`, summed over the obstacles it is inside,
    /// and, if `jacobian`, its derivative with respect to `x` when `v`
    /// follows `x` as `dv/dx = dv_dx` (as in [`Contact::add_jacobian`];
    /// zero otherwise); `None` when it touches nothing.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn node_point_force(
        &self,
        i: u32,
        t: f64,
        x: Vec3,
        v: Vec3,
        dv_dx: f64,
        anchors: &[Option<Vec3>],
        jacobian: bool,
    ) -> Option<(Vec3, Mat3)> {
        let i = i as usize;
        let nobs = self.obstacles.len();
        let mut total: Option<(Vec3, Mat3)> = None;
        for j in 0..nobs {
            let anchor = Self::anchor_of(anchors, i * nobs + j);
            if let Some((touch, pen)) = self.touch(i, j, t, x, v, anchor) {
                let (f, d) = total.get_or_insert((Vec3::zeros(), Mat3::zeros()));
                *f += touch.force;
                if jacobian {
                    *d += self.touch_jacobian(i, j, &touch, &pen, dv_dx);
                }
            }
        }
        total
    }

    /// `d(force)/dx` of one touch of point `i` with obstacle `j`.
    fn touch_jacobian(
        &self,
        i: usize,
        j: usize,
        touch: &Touch,
        pen: &Penetration,
        dv_dx: f64,
    ) -> Mat3 {
        let point = &self.points[i];
        let s = &self.obstacles[j].1;
        let stiffness = s.stiffness * point.stiffness_ratio;
        let nn = touch.normal * touch.normal.transpose();
        let c = 2.0 * s.damping_ratio * (stiffness * point.mass).sqrt();
        // The normal force n f_n: f_n changes with the depth (whose
        // gradient is -n) and with v_n = v_rel . n (v follows x as dv/dx,
        // and n turns on a curved obstacle), and n turns.
        let (n, d) = (touch.normal, touch.offset);
        let g = pen.normal_gradient;
        let (_, df_ddepth, df_dvn) = normal_force(stiffness, c, pen.depth, touch.v_n);
        let d_fn = -n * df_ddepth + (n * dv_dx + g.transpose() * touch.v_rel) * df_dvn;
        let f_n = touch.force.dot(&n);
        let block = n * d_fn.transpose() + g * f_n;
        // d(delta)/dx for delta = d - n (n . d): the tangent
        // projector, and the turning of n on a curved obstacle.
        let d_delta = Mat3::identity() - nn - g * n.dot(&d) - n * (d.transpose() * g);
        block + coulomb_jacobian(touch.delta, stiffness, f_n, s, &d_delta, d_fn)
    }

    /// [`Contact::add_forces`] of the points `which` only.
    pub fn add_forces_of(
        &self,
        which: &[u32],
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
    ) {
        for &i in which {
            self.add_point_forces(i as usize, t, x, v, anchors, f);
        }
    }

    /// Adds point `i`'s contact forces to `f`; whether it touched anything.
    fn add_point_forces(
        &self,
        i: usize,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
    ) -> bool {
        let nobs = self.obstacles.len();
        let point = &self.points[i];
        let (xp, vp) = (point.position(x), point.position(v));
        let mut touched = false;
        for j in 0..nobs {
            let k = i * nobs + j;
            if let Some((touch, _)) = self.touch(i, j, t, xp, vp, Self::anchor_of(anchors, k)) {
                for (n, w) in point.bound() {
                    f[n] += touch.force * w;
                }
                touched = true;
            }
        }
        touched
    }

    /// Adds `d(contact force)/dx` to `jac` (pattern of the model, diagonal
    /// present); `dv_dx` is how velocity follows position (`1 / dt` in an
    /// implicit step, 0 in a static solve).
    #[allow(clippy::too_many_arguments)]
    pub fn add_jacobian(
        &self,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        dv_dx: f64,
        jac: &mut BlockCsr,
    ) {
        let nobs = self.obstacles.len();
        for (i, point) in self.points.iter().enumerate() {
            let (xp, vp) = (point.position(x), point.position(v));
            for j in 0..nobs {
                let k = i * nobs + j;
                let Some((touch, pen)) = self.touch(i, j, t, xp, vp, Self::anchor_of(anchors, k))
                else {
                    continue;
                };
                let block = self.touch_jacobian(i, j, &touch, &pen, dv_dx);
                // The point moves with its nodes by their weights.
                for (a, wa) in point.bound() {
                    for (b, wb) in point.bound() {
                        if let Some(idx) = jac.find(a, b) {
                            jac.blocks[idx] += block * (wa * wb);
                        }
                    }
                }
            }
        }
        if let Some(b) = &self.bodies {
            b.add_jacobian(x, v, self.body_anchors(anchors), dv_dx, jac);
        }
    }

    /// After a step: sets the anchors of new contacts, lets sliding ones
    /// follow their point to the kinetic limit, and clears those of points
    /// that left. `anchors` is resized to [`Contact::num_anchors`] if needed.
    pub fn update_anchors(&self, t: f64, x: &[Vec3], v: &[Vec3], anchors: &mut Vec<Option<Vec3>>) {
        if anchors.len() != self.num_anchors() {
            *anchors = vec![None; self.num_anchors()];
        }
        for i in 0..self.points.len() {
            self.update_point_anchors(i, t, x, v, anchors);
        }
        self.update_body_anchors(x, v, anchors);
    }

    /// [`Contact::update_anchors`] of the points `which` only; the others'
    /// anchors are left as they are (`anchors` is resized, to `None`s, if
    /// needed).
    pub fn update_anchors_of(
        &self,
        which: &[u32],
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &mut Vec<Option<Vec3>>,
    ) {
        self.update_anchors_keeping(which, t, x, v, anchors, |_, _| {});
    }

    /// [`Contact::update_anchors_of`], calling `kept(i, force)` for each
    /// point `i` of `which` that touches and whose anchors on the obstacles
    /// it touches all stay where they were (it sticks): `force` is its total
    /// contact force with the updated anchors, for a node point (as
    /// [`Contact::node_points`] gives them) what
    /// [`Contact::node_point_force`] gives at the same `t`, `x` and `v`
    /// (without the Jacobian), bit for bit, as those anchors are the ones it
    /// was just evaluated with. The explicit step starts its next sub-step
    /// with these forces instead of evaluating them again.
    pub fn update_anchors_keeping(
        &self,
        which: &[u32],
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &mut Vec<Option<Vec3>>,
        mut kept: impl FnMut(u32, Vec3),
    ) {
        if anchors.len() != self.num_anchors() {
            *anchors = vec![None; self.num_anchors()];
        }
        for &i in which {
            if let Some(force) = self.update_point_anchors(i as usize, t, x, v, anchors) {
                kept(i, force);
            }
        }
    }

    /// Updates point `i`'s anchors; returns its total force (summed over
    /// the obstacles as [`Contact::node_point_force`] sums it) when it
    /// touches and none of the anchors its force used moved.
    fn update_point_anchors(
        &self,
        i: usize,
        t: f64,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &mut [Option<Vec3>],
    ) -> Option<Vec3> {
        let nobs = self.obstacles.len();
        let point = &self.points[i];
        let (xp, vp) = (point.position(x), point.position(v));
        let mut total: Option<Vec3> = None;
        let mut anchors_stay = true;
        for j in 0..nobs {
            let k = i * nobs + j;
            let offset = self.obstacles[j].0.offset(t);
            let anchor = Self::anchor_of(anchors, k);
            let touch = self.touch(i, j, t, xp, vp, anchor);
            if let Some((touch, _)) = &touch {
                *total.get_or_insert(Vec3::zeros()) += touch.force;
                anchors_stay &= anchor.is_some() && !touch.sliding;
            }
            anchors[k] = match touch {
                None => None,
                Some(_) if anchor.is_none() => Some(xp - offset),
                Some((touch, _)) if touch.sliding => {
                    let s = &self.obstacles[j].1;
                    let f_n = touch.force.dot(&touch.normal).max(0.0);
                    let len = touch.delta.norm();
                    let k_p = s.stiffness * point.stiffness_ratio;
                    let back = if len > 0.0 {
                        touch.delta * (kinetic_offset(k_p, f_n, s) / len)
                    } else {
                        Vec3::zeros()
                    };
                    Some(xp - back - offset)
                }
                // Sticking: the anchor stays.
                Some(_) => anchors[k],
            };
        }
        total.filter(|_| anchors_stay)
    }

    /// Contact force per node (N) at a state (for output).
    pub fn forces(&self, t: f64, x: &[Vec3], v: &[Vec3], anchors: &[Option<Vec3>]) -> Vec<Vec3> {
        let mut f = vec![Vec3::zeros(); x.len()];
        self.add_forces(t, x, v, anchors, &mut f);
        f
    }

    /// Penalty energy `k d^2 / 2` summed over touching points (J), for energy checks.
    pub fn energy(&self, t: f64, x: &[Vec3]) -> f64 {
        let mut e = 0.0;
        for point in &self.points {
            let xp = point.position(x);
            for (o, s) in &self.obstacles {
                if let Some(p) = o.penetration(t, xp) {
                    e += 0.5 * s.stiffness * point.stiffness_ratio * p.depth * p.depth;
                }
            }
        }
        e + self.bodies.as_ref().map_or(0.0, |b| b.energy(x))
    }
}

/// An obstacle of a [`Contact`] with a translation on top of its own motion
/// (zero except while a static solve inserts it), held as bits in atomics
/// so that the contact can be shared between threads and the queries stay
/// three plain loads.
#[derive(Debug)]
struct Placed {
    inner: Box<dyn Obstacle>,
    /// `inner` when it is a plane ([`Obstacle::as_plane`]), asked directly.
    plane: Option<Plane>,
    shift: [std::sync::atomic::AtomicU64; 3],
}

impl Placed {
    fn new(inner: Box<dyn Obstacle>) -> Self {
        Self {
            plane: inner.as_plane().cloned(),
            inner,
            shift: std::array::from_fn(|_| std::sync::atomic::AtomicU64::new(0.0f64.to_bits())),
        }
    }

    /// The inner obstacle: its plane when it is one, so that the queries
    /// below are static calls, or the trait object.
    #[inline(always)]
    fn with_inner<R>(
        &self,
        ask: impl FnOnce(&dyn Obstacle) -> R,
        ask_plane: impl FnOnce(&Plane) -> R,
    ) -> R {
        match &self.plane {
            Some(plane) => ask_plane(plane),
            None => ask(self.inner.as_ref()),
        }
    }

    fn set_shift(&self, v: Vec3) {
        for (a, c) in self.shift.iter().zip(v.iter()) {
            a.store(c.to_bits(), std::sync::atomic::Ordering::Relaxed);
        }
    }

    #[inline]
    fn shift(&self) -> Vec3 {
        Vec3::from_fn(|d, _| {
            f64::from_bits(self.shift[d].load(std::sync::atomic::Ordering::Relaxed))
        })
    }
}

impl Obstacle for Placed {
    fn name(&self) -> String {
        self.inner.name()
    }
    #[inline]
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        let p = p - self.shift();
        self.with_inner(|o| o.penetration(t, p), |o| o.penetration(t, p))
    }
    fn contains(&self, t: f64, p: Vec3) -> bool {
        self.inner.contains(t, p - self.shift())
    }
    fn nodes_inside(&self, t: f64, x: &[Vec3], nodes: &[u32], inside: &mut Vec<u32>) {
        let shift = self.shift();
        if shift == Vec3::zeros() {
            // `p - 0` is `p`: the inner obstacle's own scan says the same.
            self.inner.nodes_inside(t, x, nodes, inside);
            return;
        }
        for (k, &n) in nodes.iter().enumerate() {
            if self.inner.contains(t, x[n as usize] - shift) {
                inside.push(k as u32);
            }
        }
    }
    #[inline]
    fn velocity(&self, t: f64) -> Vec3 {
        self.with_inner(|o| o.velocity(t), |o| o.velocity(t))
    }
    #[inline]
    fn offset(&self, t: f64) -> Vec3 {
        self.with_inner(|o| o.offset(t), |o| o.offset(t)) + self.shift()
    }
}

/// An obstacle moved by hand (a cursor, a tool): its offset is set through
/// the [`SteerHandle`] returned with it, between steps, and it moves with
/// the velocity of the last change.
#[derive(Debug)]
pub struct Steered {
    inner: Box<dyn Obstacle>,
    pose: std::sync::Arc<std::sync::RwLock<SteerPose>>,
}

#[derive(Debug, Clone, Copy, Default)]
struct SteerPose {
    offset: Vec3,
    velocity: Vec3,
}

/// Moves a [`Steered`] obstacle.
#[derive(Debug, Clone)]
pub struct SteerHandle(std::sync::Arc<std::sync::RwLock<SteerPose>>);

impl SteerHandle {
    /// Puts the obstacle at `offset` (m) from its placement, as if it had
    /// moved there in `dt` seconds (its velocity for contact damping and
    /// friction until the next call).
    pub fn move_to(&self, offset: Vec3, dt: f64) {
        let mut pose = self.0.write().unwrap_or_else(|e| e.into_inner());
        pose.velocity = if dt > 0.0 {
            (offset - pose.offset) / dt
        } else {
            Vec3::zeros()
        };
        pose.offset = offset;
    }

    /// The obstacle's current offset (m).
    pub fn offset(&self) -> Vec3 {
        self.0.read().unwrap_or_else(|e| e.into_inner()).offset
    }
}

impl Steered {
    /// `obstacle`, steerable through the handle.
    pub fn new(obstacle: Box<dyn Obstacle>) -> (Self, SteerHandle) {
        let pose = std::sync::Arc::new(std::sync::RwLock::new(SteerPose::default()));
        (
            Self {
                inner: obstacle,
                pose: std::sync::Arc::clone(&pose),
            },
            SteerHandle(pose),
        )
    }

    fn pose(&self) -> SteerPose {
        *self.pose.read().unwrap_or_else(|e| e.into_inner())
    }
}

impl Obstacle for Steered {
    fn name(&self) -> String {
        format!("steered {}", self.inner.name())
    }
    fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
        self.inner.penetration(t, p - self.pose().offset)
    }
    fn contains(&self, t: f64, p: Vec3) -> bool {
        self.inner.contains(t, p - self.pose().offset)
    }
    fn velocity(&self, t: f64) -> Vec3 {
        self.inner.velocity(t) + self.pose().velocity
    }
    fn offset(&self, t: f64) -> Vec3 {
        self.inner.offset(t) + self.pose().offset
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every obstacle's scan of nodes says what `contains` says of each
    /// node, in order: planes and spheres (their own scans) moving along a
    /// path, a box (the default scan), each also shifted as a static
    /// solve's insertion shifts it; points on the surface, inside, outside,
    /// and NaN.
    #[test]
    fn the_scan_of_nodes_is_contains_of_each() {
        let path = Path::new(vec![(0.0, Vec3::zeros()), (1.0, Vec3::new(0.1, -0.2, 0.3))]).unwrap();
        let shapes: Vec<Box<dyn Obstacle>> = vec![
            Box::new(Plane::new(Vec3::new(0.0, 0.0, 0.1), Vec3::new(0.2, 0.1, 1.0)).unwrap()),
            Box::new(
                Plane::new(Vec3::zeros(), Vec3::z())
                    .unwrap()
                    .moving(path.clone()),
            ),
            Box::new(
                Sphere::new(Vec3::new(0.3, 0.2, 0.1), 0.25)
                    .unwrap()
                    .moving(path.clone()),
            ),
            Box::new(Cuboid::new(Vec3::zeros(), Vec3::new(0.4, 0.3, 0.2)).unwrap()),
        ];
        let mut seed = 5u64;
        let mut x: Vec<Vec3> = (0..400)
            .map(|_| {
                Vec3::new(
                    crate::noise(&mut seed),
                    crate::noise(&mut seed),
                    crate::noise(&mut seed),
                ) * 0.6
            })
            .collect();
        x.push(Vec3::new(f64::NAN, 0.0, 0.0));
        x.push(Vec3::new(0.0, 0.0, 0.1));
        let nodes: Vec<u32> = (0..x.len() as u32).rev().step_by(2).collect();
        for shape in shapes {
            let placed = Placed::new(shape);
            for shift in [Vec3::zeros(), Vec3::new(0.05, 0.0, -0.1)] {
                placed.set_shift(shift);
                for t in [0.0, 0.4, 2.0] {
                    let want: Vec<u32> = (0..nodes.len() as u32)
                        .filter(|&k| placed.contains(t, x[nodes[k as usize] as usize]))
                        .collect();
                    let mut got = vec![7];
                    placed.nodes_inside(t, &x, &nodes, &mut got);
                    assert_eq!(got[0], 7, "appended");
                    assert_eq!(
                        got[1..],
                        want[..],
                        "{} at {t}, shift {shift:?}",
                        placed.name()
                    );
                    assert!(!want.is_empty() && want.len() < nodes.len());
                }
            }
        }
    }

    /// A plane that the contact asks directly ([`Obstacle::as_plane`])
    /// gives the bits it gives through the trait object: the forces, their
    /// Jacobians and the anchors of points above, on and below a moving,
    /// tilted plane, shifted as a static solve shifts it, with and without
    /// anchors.
    #[test]
    fn a_plane_asked_directly_gives_the_trait_objects_bits() {
        /// Forwards every query to the plane, but does not say it is one.
        #[derive(Debug)]
        struct Veiled(Plane);
        impl Obstacle for Veiled {
            fn name(&self) -> String {
                self.0.name()
            }
            fn penetration(&self, t: f64, p: Vec3) -> Option<Penetration> {
                self.0.penetration(t, p)
            }
            fn velocity(&self, t: f64) -> Vec3 {
                self.0.velocity(t)
            }
            fn offset(&self, t: f64) -> Vec3 {
                self.0.offset(t)
            }
        }
        let path = Path::new(vec![
            (0.0, Vec3::zeros()),
            (1.0, Vec3::new(0.01, -0.02, 0.03)),
        ])
        .unwrap();
        let plane = Plane::new(Vec3::new(0.0, 0.0, 0.01), Vec3::new(0.2, 0.1, 1.0))
            .unwrap()
            .moving(path);
        let lattice = hexmesh::Lattice::block([3, 3, 2], 0.02, [0.0; 3]).unwrap();
        let model = Model::new(
            &lattice,
            crate::Material::new(1e5, 0.3, 1000.0).unwrap(),
            &crate::PaperModel,
        )
        .unwrap();
        let settings = ContactSettings::for_model(&model);
        let direct = Contact::new(&model, vec![(Box::new(plane.clone()), settings)]);
        let veiled = Contact::new(&model, vec![(Box::new(Veiled(plane)), settings)]);
        assert!(direct.obstacles[0].0.plane.is_some() && veiled.obstacles[0].0.plane.is_none());
        let mut seed = 3u64;
        let mut noise = |scale: f64| {
            Vec3::new(
                crate::noise(&mut seed),
                crate::noise(&mut seed),
                crate::noise(&mut seed),
            ) * scale
        };
        let x: Vec<Vec3> = model
            .rest_positions()
            .iter()
            .map(|p| p + noise(0.03))
            .collect();
        let v: Vec<Vec3> = x.iter().map(|_| noise(0.5)).collect();
        let bits = |a: &Vec3, b: &Vec3| (0..3).all(|d| a[d].to_bits() == b[d].to_bits());
        for shift in [Vec3::zeros(), Vec3::new(0.003, 0.0, -0.004)] {
            direct.obstacles[0].0.set_shift(shift);
            veiled.obstacles[0].0.set_shift(shift);
            for t in [0.0, 0.3, 1.5] {
                let mut anchors = [Vec::new(), Vec::new()];
                let mut touched = 0;
                for round in 0..2 {
                    for &i in direct.node_points() {
                        let n = direct.point_node(i) as usize;
                        let [a, b] = [&direct, &veiled]
                            .map(|c| c.node_point_force(i, t, x[n], v[n], 40.0, &anchors[0], true));
                        assert_eq!(a.is_some(), b.is_some());
                        if let (Some((fa, ja)), Some((fb, jb))) = (a, b) {
                            touched += 1;
                            assert!(bits(&fa, &fb), "point {i} at {t}, round {round}");
                            assert!(
                                ja.iter()
                                    .zip(jb.iter())
                                    .all(|(p, q)| p.to_bits() == q.to_bits())
                            );
                        }
                    }
                    // Anchored for the second round.
                    let which = direct.node_points().to_vec();
                    for (c, anchors) in [&direct, &veiled].into_iter().zip(&mut anchors) {
                        c.update_anchors_keeping(&which, t, &x, &v, anchors, |_, _| {});
                    }
                    assert_eq!(anchors[0].len(), anchors[1].len());
                    for (a, b) in anchors[0].iter().zip(&anchors[1]) {
                        assert_eq!(a.is_some(), b.is_some());
                        assert!(a.zip(*b).is_none_or(|(a, b)| bits(&a, &b)));
                    }
                    let copy = anchors[0].clone();
                    anchors[1] = copy;
                }
                assert!(touched > 0 && touched < 2 * direct.node_points().len());
            }
        }
    }

    /// The normal force starts from zero as a point enters, however fast
    /// (the damping is capped by the elastic force), never pulls, and its
    /// derivatives are those of the force (central differences), in each
    /// regime: capped, damped, pulled out.
    #[test]
    fn the_normal_force_is_continuous_and_its_derivatives_are_exact() {
        let (k, c) = (2.0e4, 30.0);
        for v_n in [-5.0, -0.01, 0.0, 0.2] {
            assert_eq!(normal_force(k, c, -1e-6, v_n), (0.0, 0.0, 0.0));
            let (f, _, _) = normal_force(k, c, 1e-12, v_n);
            assert!(
                (0.0..=2.0 * k * 1e-12 * (1.0 + 1e-9)).contains(&f),
                "{v_n}: {f}"
            );
        }
        for (depth, v_n) in [(1e-4, -1.0), (1e-3, -0.01), (1e-3, 0.3), (1e-3, 1.0)] {
            let (f, dd, dv) = normal_force(k, c, depth, v_n);
            assert!(f >= 0.0);
            let h = 1e-9;
            let fd_d = (normal_force(k, c, depth + h, v_n).0
                - normal_force(k, c, depth - h, v_n).0)
                / (2.0 * h);
            let fd_v = (normal_force(k, c, depth, v_n + h).0
                - normal_force(k, c, depth, v_n - h).0)
                / (2.0 * h);
            assert!(
                (fd_d - dd).abs() <= 1e-6 * k,
                "{depth} {v_n}: {fd_d} vs {dd}"
            );
            assert!(
                (fd_v - dv).abs() <= 1e-6 * c,
                "{depth} {v_n}: {fd_v} vs {dv}"
            );
        }
        // Damped as before where the point presses in slowly or rests.
        assert_eq!(normal_force(k, c, 1e-3, -0.01).0, k * 1e-3 + c * 0.01);
    }
}
