//! Contact between the bodies of a [`Model::union`], and of a body with
//! itself.
//!
//! **Geometry.** Each body's surface is its lattice's boundary: every cell
//! face no other cell shares, split into two triangles along a diagonal,
//! oriented outward. The points that touch are the boundary nodes. A point
//! `p` is inside another body when its nearest surface triangle (by the
//! distance to the triangle's closest point, within half a cell of that
//! body) lies in front of it: the gap `g = n . (p - a)` to the triangle's
//! plane is negative. The nearest one decides, so that a point just outside
//! a thin body is not taken for inside the face behind it, and a point
//! pressed into a vertex or an edge of the other surface (where it projects
//! onto no triangle) still touches: its force goes to the closest point.
//! Triangles that face the point (their outward normals opposed within
//! [`FACING_COSINE`]) are preferred to nearer ones that do not: surfaces
//! in contact face each other, and a point that a sinking edge passes over
//! is not pushed out through the side face behind that edge.
//!
//! **Broad phase.** The triangles' boxes, grown by the depth limit, go into
//! a uniform grid of the largest cell size, as sorted `(grid cell,
//! triangle)` keys; each point examines the triangles of its own grid cell.
//! Building it is a sort of `O(n log n)` for `n` surface triangles, done at
//! every force evaluation (the surface moves).
//!
//! **Forces.** The penalty `f_n = k d - c v_n` (never pulling) along the
//! triangle's normal `n`, with `d = -g`, on the point, and `-beta_i` times
//! it on the triangle's nodes (`beta` the barycentric coordinates of the
//! point's closest point on it): the forces sum to zero, so momentum is
//! kept. As `dg/dp = n` and `dg/dx_i = -beta_i n` exactly where the point
//! projects inside the triangle, this is there the gradient of the energy
//! `k d^2 / 2`. Friction is the obstacles'
//! stick-slip law, the anchor being a material point of the touched body: a
//! triangle and barycentric coordinates, stored in
//! [`State::contact`](crate::solver::State) as `(triangle, beta_b, beta_c)`
//! after the obstacles' anchors. The anchor moves to the triangle its point
//! touches now (a point of that triangle's plane), so that it stays within
//! the friction's reach of the point as the point slides over many
//! triangles; a contact made during an explicit step is anchored where its
//! point was at the step's start ([`BodyContact::anchor_at_step_start`]).
//!
//! **Derivatives.** The tangent is the exact derivative of these forces
//! ([`super::pair_tangent`], forward-mode dual numbers over the point, the
//! touched triangle's corners and the anchor triangle's): the normal
//! turning with the triangle, the weights sliding with the closest point
//! (on the face, or on an edge at a rim), the normal force following the
//! depth and the damping the velocity, stick or slip as the force found
//! them. A touch couples the point with the corners of its triangle and of
//! its anchor's: the matrix's pattern grows by those pairs
//! ([`BlockCsr::extend_pattern`]). A static solve counts points within
//! [`STATIC_MARGIN`] of a cell outside a surface as touching in its tangent
//! (`-k n n^T`, not in its forces): a body held by contact alone would
//! otherwise have a singular tangent wherever an iterate lifts it off.
//!
//! A point just outside a body, beside the rim of a face whose plane it is
//! below and within reach of (half a cell), is taken as touching at that
//! rim (its depth is the plane's, its weights the rim's closest point's).
//! The depth is that of the body's tilt at its rim, so the force is small;
//! it is not the gradient of an energy there (the torque of the pair is not
//! zero), but the tangent is its derivative all the same.
//!
//! **Embedded surfaces** ([`BodyContact::on_surface`]): the points and the
//! triangles are the embedded input surfaces' vertices and triangles
//! instead of the lattices' boundaries (refined by the scene to the cells'
//! size, `hexmesh::TriMesh::refined`, so that a reaction goes to cells near
//! where it acts). The search and the forces work on the vertices'
//! positions; a force at a vertex goes to its cell's 8 nodes by the
//! trilinear weights, and a derivative block between vertices `a` and `b`
//! to their nodes with the products of their weights. The broad phase then
//! also keeps the triangles whose boxes meet another body's with none of
//! their corners there (a large face).
//!
//! **Self-contact** (per body) lets a body's points touch its own surface,
//! except the triangles whose nodes lay within [`SELF_EXCLUSION`] cells of
//! the point at rest: the point's own and neighbouring cells, which touch
//! it by construction.

use rayon::prelude::*;

use super::ContactSettings;
use crate::{BlockCsr, Mat3, Model, Vec3};

/// Triangles of a body's own surface whose nodes lay within this many cell
/// sizes of a point at rest do not touch it (its own cells and their
/// neighbours).
pub const SELF_EXCLUSION: f64 = 2.5;

/// How deep (in cells of the touched body) a point may be inside a body
/// and still be pushed out; deeper, it is taken for the far side's business.
pub const DEPTH_LIMIT: f64 = 0.5;

/// Default contact frequency between bodies as a fraction of the bound of
/// the lattice's highest frequency: body contact is explicit in the
/// explicit solver, so it shortens the step (by about 15 % here).
pub const DEFAULT_BODY_FREQUENCY_FRACTION: f64 = 0.25;

/// How deep (in cells of the touched body) a point that touched at the end
/// of the last step is still pushed back out of the side it came in
/// through: beyond the search's [`DEPTH_LIMIT`] after a fast impact.
pub const PERSIST_LIMIT: f64 = 2.0;

/// How close to a surface (in cells) a point counts as touching in a static
/// solve's tangent (not in its forces).
pub const STATIC_MARGIN: f64 = 0.1;

/// A triangle faces a point when their outward normals make a cosine below
/// minus this: surfaces in contact face each other. Where a body's edge
/// sinks into another's surface (by the penalty's depth), that surface's
/// points just past the edge lie inside the body behind its side face too,
/// and the side face, at right angles to them, may be the nearer: pushed out
/// through it, they hold the edge back like a ridge, and a block sliding on
/// another slowed as if friction were 10 % higher.
pub const FACING_COSINE: f64 = 0.25;

/// A point keeps the triangle it is anchored to (the one it touched at the
/// end of the last step, or its nearest at the start of an implicit step)
/// while its projection on that triangle's plane lies within this fraction
/// of the triangle beyond its edges (the smallest barycentric coordinate at
/// least minus this), so that its anchor too stays there. Where two
/// triangles meet at an angle (the two halves of a bent face, neighbouring
/// faces of a dented surface) the nearest one changes as a point crosses
/// their edge, and with it the force's direction: the Newton iterates of
/// an implicit step, moving points back and forth across such edges,
/// found a different force at every iteration and stalled (a ball landing
/// on a block: 4 of its 34 touching points switching triangles at every
/// iteration, the residual stuck at 5e-4 N, the step halved down to
/// 1.25 ms and the run stopped). Narrower bands, or anchors moved to the
/// nearest triangle after each step, left the switches at the band's edge
/// (the bundled squeeze run implicitly at 10 ms: 4 to 13 halved steps, and
/// runs that stopped); at half a triangle, none.
pub const TRIANGLE_PREFERENCE: f64 = 0.5;

/// Whether `p` projects onto triangle `g` within [`TRIANGLE_PREFERENCE`]
/// (false for a position with no projection, NaN).
fn projects_within_preference(g: &Geometry, p: Vec3) -> bool {
    let beyond = g.barycentric(p).into_iter().fold(f64::INFINITY, f64::min);
    beyond >= -TRIANGLE_PREFERENCE
}

/// Grid cells a lattice face's box may cover in the broad phase (see
/// [`BodyContact`]'s `span_limit`).
const LATTICE_SPAN_LIMIT: i64 = 64;

/// Points per parallel task of the narrow phase.
const POINT_CHUNK: usize = 256;

/// The margin (in cells of the finest body) of the candidate lists: a
/// search lists, per point, every triangle within reach plus this margin,
/// and the next searches test only those while no point has moved more
/// than half of it (a Verlet list).
pub const CANDIDATE_SKIN: f64 = 0.2;

/// The nodes that carry a point or corner, with their weights.
type WeightedNodes = Vec<(u32, f64)>;

#[derive(Debug, Clone, Copy)]
struct Triangle {
    nodes: [u32; 3],
    body: u32,
}

/// A triangle in a grid cell of the broad phase, with its grown box.
#[derive(Debug, Clone, Copy)]
struct Entry {
    key: u64,
    /// Index into the grid's triangle geometry.
    geometry: u32,
    /// The triangle's body: a point skips its own body's triangles (unless
    /// it touches itself) before their geometry is read.
    body: u32,
}

/// A candidate triangle at the current positions, with what every point
/// near it needs: its plane, and the vectors whose dot products with
/// `p - a` are the barycentric coordinates of `p`'s projection (computed
/// once per search, not once per point).
///
/// Two cache lines: what a point projecting inside needs (the plane, the
/// barycentric vectors, the first corner), and nothing else. A search
/// makes and reads thousands, and the step's own data should keep the
/// second-level cache: a point beside the triangle reads its other corners
/// from the positions.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(64))]
struct Geometry {
    triangle: u32,
    /// How far from the triangle a point still touches it (m): the depth
    /// limit in its body's cells.
    reach: f64,
    normal: Vec3,
    /// `(e2 x n) / |e1 x e2|`: `beta_b = (p - a) . to_b`.
    to_b: Vec3,
    /// `(n x e1) / |e1 x e2|`: `beta_c = (p - a) . to_c`.
    to_c: Vec3,
    /// The first corner, `a`.
    origin: Vec3,
    /// `|e1 x e2|`, twice the area.
    double_area: f64,
}

impl Geometry {
    /// The triangle's geometry at `corners`, within reach `grow` (m);
    /// `None` when it has no area.
    fn new(triangle: u32, corners: [Vec3; 3], grow: f64) -> Option<Self> {
        let mut g = Self::default();
        g.set(triangle, corners, grow).then_some(g)
    }

    /// Makes `self` [`Geometry::new`]'s, in place (a search makes
    /// thousands: built elsewhere and moved, each cost two copies); false
    /// when the triangle has no area.
    #[inline]
    fn set(&mut self, triangle: u32, corners: [Vec3; 3], grow: f64) -> bool {
        let [a, b, c] = corners;
        let (e1, e2) = (b - a, c - a);
        let cross = e1.cross(&e2);
        let area2 = cross.norm();
        if !(area2 > 0.0 && area2.is_finite()) {
            return false;
        }
        // One division, not nine.
        let inverse = 1.0 / area2;
        let normal = cross * inverse;
        self.triangle = triangle;
        self.reach = grow;
        self.origin = a;
        self.double_area = area2;
        self.normal = normal;
        self.to_b = e2.cross(&normal) * inverse;
        self.to_c = normal.cross(&e1) * inverse;
        true
    }

    /// The triangle's normal times twice its area: summed over a point's
    /// own triangles, its outward direction.
    fn area_normal(&self) -> Vec3 {
        self.normal * self.double_area
    }

    /// The barycentric coordinates of `p`'s projection onto the plane
    /// (outside `[0, 1]` where it falls outside the triangle).
    fn barycentric(&self, p: Vec3) -> [f64; 3] {
        let w = p - self.origin;
        let (beta_b, beta_c) = (w.dot(&self.to_b), w.dot(&self.to_c));
        [1.0 - beta_b - beta_c, beta_b, beta_c]
    }

    /// Where `p` is against the triangle, unless it is certainly no nearer
    /// than `beyond` (its distance is at least its gap to the plane);
    /// `corners` gives the triangle's corners, asked for only when `p`
    /// projects outside it.
    #[inline(always)]
    fn closest(
        &self,
        p: Vec3,
        beyond: f64,
        corners: impl FnOnce() -> [Vec3; 3],
    ) -> Option<Closest> {
        let gap = self.normal.dot(&(p - self.origin));
        let beta = self.barycentric(p);
        if beta.iter().all(|&w| w >= 0.0) {
            return Some(Closest {
                distance: gap.abs(),
                gap,
                beta,
                normal: self.normal,
            });
        }
        if gap.abs() >= beyond {
            return None;
        }
        let t = &corners();
        // Outside. Beyond the line of one edge only (the opposite
        // corner's weight negative), `p` lies in the cone from that corner
        // through the edge, so the segment from it to that corner crosses
        // the edge: the closest point is on it. Beyond two, it is on one of
        // their edges (on the inner side of the third line, `p` is nearest
        // to no point inside the third edge); at a corner of 90 degrees or
        // less, their common corner, but past an obtuse corner, inside
        // either edge.
        let edge = |i: usize, j: usize| closest_on_edge(t, p, i, j);
        // The nearer of two edges, the first of equals (in the order
        // (0, 1), (1, 2), (2, 0), as the tangent takes them).
        let nearer = |a: (f64, [f64; 3]), b: (f64, [f64; 3])| if b.0 < a.0 { b } else { a };
        let best = match beta.map(|w| w < 0.0) {
            [true, false, false] => edge(1, 2),
            [false, true, false] => edge(2, 0),
            [false, false, true] => edge(0, 1),
            [false, true, true] => nearer(edge(0, 1), edge(2, 0)),
            [true, false, true] => nearer(edge(0, 1), edge(1, 2)),
            [true, true, false] => nearer(edge(1, 2), edge(2, 0)),
            // Not a number: nothing is near.
            _ => return None,
        };
        Some(Closest {
            distance: best.0.sqrt(),
            gap,
            beta: best.1,
            normal: self.normal,
        })
    }
}

/// The squared distance from `p` to the edge from corner `i` to corner `j`
/// of `t`, and the weights of its closest point. Inlined: returned through
/// memory, the pair cost a store and a reload per edge on the search's path.
#[inline(always)]
fn closest_on_edge(t: &[Vec3; 3], p: Vec3, i: usize, j: usize) -> (f64, [f64; 3]) {
    let e = t[j] - t[i];
    let s = ((p - t[i]).dot(&e) / e.norm_squared()).clamp(0.0, 1.0);
    let mut w = [0.0; 3];
    w[i] = 1.0 - s;
    w[j] = s;
    ((p - (t[i] + e * s)).norm_squared(), w)
}

/// The broad phase's grid: its entries bucketed by a hash of their grid
/// cell (a counting sort: linear, and in triangle order within a bucket,
/// so the same for any thread count).
struct Grid {
    mask: u64,
    starts: Vec<u32>,
    entries: Vec<Entry>,
    geometry: Vec<Geometry>,
    /// Per geometry, its corners' box grown by its reach.
    boxes: Vec<(Vec3, Vec3)>,
    /// Per point, the sum of its own triangles' area-weighted normals at
    /// the positions searched (zero for points far from other bodies).
    point_normals: Vec<Vec3>,
}

impl Grid {
    fn new(
        unsorted: Vec<Entry>,
        geometry: Vec<Geometry>,
        boxes: Vec<(Vec3, Vec3)>,
        point_normals: Vec<Vec3>,
    ) -> Self {
        let size = (2 * unsorted.len()).next_power_of_two().max(1);
        let mask = size as u64 - 1;
        let mut starts = vec![0u32; size + 1];
        for e in &unsorted {
            starts[(Self::bucket_of(e.key) & mask) as usize + 1] += 1;
        }
        for b in 0..size {
            starts[b + 1] += starts[b];
        }
        let mut fill = starts.clone();
        let mut entries = Vec::with_capacity(unsorted.len());
        entries.resize(
            unsorted.len(),
            Entry {
                key: 0,
                geometry: 0,
                body: 0,
            },
        );
        for e in unsorted {
            let b = (Self::bucket_of(e.key) & mask) as usize;
            entries[fill[b] as usize] = e;
            fill[b] += 1;
        }
        Self {
            mask,
            starts,
            entries,
            geometry,
            boxes,
            point_normals,
        }
    }

    fn bucket_of(key: u64) -> u64 {
        (key ^ (key >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9) >> 17
    }

    /// The entries whose cell's key falls in `key`'s bucket (others too:
    /// compare the key).
    fn bucket(&self, key: u64) -> &[Entry] {
        let b = (Self::bucket_of(key) & self.mask) as usize;
        &self.entries[self.starts[b] as usize..self.starts[b + 1] as usize]
    }
}

/// The pairs of the last positions asked about (by their key): a step asks
/// two or three times at the same positions (its forces, its anchors, the
/// next step's start).
type PairCache = crate::cache::Cache<(u64, std::sync::Arc<Vec<Pair>>)>;

/// Per point that may touch, the triangles it may touch while no point has
/// moved more than half the skin since `reference` (a Verlet list).
struct Candidates {
    /// The points' positions when the lists were made.
    reference: Vec<Vec3>,
    /// Half the skin (m).
    half_skin: f64,
    /// The points that may touch (point indices, ascending).
    near: Vec<u32>,
    /// Per near point, its range of `slots`.
    offsets: Vec<u32>,
    /// Candidate triangles as indices into `needed`, ascending by triangle
    /// per point.
    slots: Vec<u32>,
    /// The candidate triangles (ascending): those whose geometry a search
    /// builds.
    needed: Vec<u32>,
    /// Every triangle with a corner among the near points (ascending),
    /// with its index in `needed` (`u32::MAX` for none: its geometry is
    /// made apart) and the index in `near` of each corner (`u32::MAX` for a
    /// corner that is no near point): the near points' outward normals.
    own: Vec<(u32, u32, [u32; 3])>,
    /// The needed triangles' geometry at the last positions searched
    /// (kept to reuse its memory), and whether each has any (an area).
    geometry: Vec<Geometry>,
    valid: Vec<bool>,
    /// Per needed triangle, whether the last search wanted its geometry
    /// (a point whose anchor decides it weighs none of its candidates).
    wanted: Vec<bool>,
    /// Per near point, its pair where its anchor decided it at the last
    /// search ([`BodyContact::anchored_pair`]), `None` where it was
    /// searched (empty: every point was).
    decided: Vec<Option<Pair>>,
    /// Per near point, the sum of its own triangles' area-weighted normals
    /// at the last positions searched.
    normals: Vec<Vec3>,
}

impl Candidates {
    /// Whether every point is within half the skin of where it was.
    fn hold(&self, x: &[Vec3], points: &[u32]) -> bool {
        let limit = self.half_skin * self.half_skin;
        points
            .iter()
            .zip(&self.reference)
            .all(|(&n, r)| (x[n as usize] - r).norm_squared() < limit)
    }
}

/// The candidate lists of the last search, kept while they hold.
type CandidateCache = crate::cache::Cache<Candidates>;

/// The search of the triangle nearest to a point: the best facing the
/// point (its outward normal against theirs) and the best of the others.
struct Nearest {
    point: usize,
    outward: Vec3,
    facing: Option<(f64, Pair)>,
    other: Option<(f64, Pair)>,
}

impl Nearest {
    /// A search for point `point` whose own triangles' area-weighted
    /// normals sum to `normals`.
    fn new(point: usize, normals: Option<Vec3>) -> Self {
        let sum = normals.unwrap_or_default();
        let outward = if sum.norm() > 0.0 && sum.norm().is_finite() {
            sum / sum.norm()
        } else {
            Vec3::zeros()
        };
        Self {
            point,
            outward,
            facing: None,
            other: None,
        }
    }

    /// The nearest triangle by true distance (to its closest point), then
    /// by the gap to its plane: continuous as the point moves from one
    /// triangle's region to the next, edges and vertices included.
    /// Triangles that face the point come first (FACING_COSINE); the
    /// nearest of the others only when none faces it, so that nothing
    /// passes through where surfaces meet at an angle.
    fn pair(self) -> Option<Pair> {
        self.facing.or(self.other).map(|(_, pair)| pair)
    }
}

/// One point inside a body: the triangle it is pushed out of.
#[derive(Debug, Clone, Copy)]
struct Pair {
    point: u32,
    triangle: u32,
    beta: [f64; 3],
    normal: Vec3,
    /// Depth (m), > 0.
    depth: f64,
}

/// The pairs an explicit step's end found
/// ([`BodyContact::anchor_at_step_start_and_add_forces`]), kept for the
/// anchors' update after the step ([`BodyContact::update_anchors_with`])
/// and the forces the next sub-step starts with
/// ([`BodyContact::add_forces_with`]): one search, one pass over the
/// anchors and three keys of the positions fewer per step.
#[derive(Debug, Clone)]
pub(crate) struct StepPairs {
    /// The positions' key they were found at (checked in debug builds:
    /// the explicit step hands them on only while it knows the positions
    /// are those).
    key: u64,
    /// What the search found at those positions, before the anchors had
    /// their say ([`BodyContact::with_persisting`]).
    searched: std::sync::Arc<Vec<Pair>>,
    /// The pairs, with the anchors at the step's end.
    pairs: std::sync::Arc<Vec<Pair>>,
}

/// One touch's force and what friction did.
struct Touch {
    /// Force on the point (N); its reaction goes to the triangle.
    force: Vec3,
    /// Tangential offset from the anchor.
    delta: Vec3,
    /// Normal force (N).
    f_n: f64,
    sliding: bool,
    stiffness: f64,
}

/// Contact between the bodies of a model, and self-contact where asked.
#[derive(Debug, Clone)]
pub struct BodyContact {
    settings: ContactSettings,
    triangles: Vec<Triangle>,
    /// Boundary nodes that can touch.
    points: Vec<u32>,
    /// Per node, its index in `points` (`u32::MAX` for none).
    point_of_node: Vec<u32>,
    point_body: Vec<u32>,
    /// Each point's stiffness over the settings' (its mass over the mean).
    stiffness_ratio: Vec<f64>,
    point_mass: Vec<f64>,
    /// Per body: whether it touches itself, its cell size.
    self_contact: Vec<bool>,
    body_h: Vec<f64>,
    /// Rest positions of the points and of the triangles' nodes, for the
    /// self-contact exclusion.
    rest: Vec<Vec3>,
    grid_size: f64,
    omega_sq_per_stiffness: f64,
    cache: PairCache,
    candidates: CandidateCache,
    /// Grid cells a triangle's box may cover in the broad phase: more is
    /// taken for an exploded surface and left out (the solver's checks see
    /// it). 64 for lattice faces; for an embedded surface, room for its
    /// largest triangle stretched to twice its size.
    span_limit: i64,
    /// With the embedded surfaces as the bodies' surfaces: how each of its
    /// vertices (the points, and the triangles' corners) follows the
    /// nodes. The search and the forces then work on the vertices'
    /// positions, and the forces and their derivatives go to the nodes by
    /// the trilinear weights.
    carrier: Option<Carrier>,
}

/// The embedded surface's vertices bound to the lattice: each one the
/// trilinear combination of its cell's 8 nodes.
#[derive(Debug, Clone)]
struct Carrier {
    nodes: Vec<[u32; 8]>,
    weights: Vec<[f64; 8]>,
}

impl Carrier {
    /// The vertices' positions (or velocities) for the nodes' `x`.
    fn carry(&self, x: &[Vec3]) -> Vec<Vec3> {
        self.nodes
            .par_iter()
            .zip(&self.weights)
            .with_min_len(POINT_CHUNK)
            .map(|(nodes, weights)| {
                nodes
                    .iter()
                    .zip(weights)
                    .map(|(&n, &w)| x[n as usize] * w)
                    .sum()
            })
            .collect()
    }

    /// The nodes of vertex `v`, with their weights.
    fn bound(&self, v: u32) -> impl Iterator<Item = (u32, f64)> + '_ {
        self.nodes[v as usize]
            .iter()
            .copied()
            .zip(self.weights[v as usize].iter().copied())
    }
}

/// Why body contact could not be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BodyContactError {
    /// `self_contact` does not have one entry per body.
    #[error("self_contact has {given} entries for {bodies} bodies")]
    SelfContactCount {
        /// Entries given.
        given: usize,
        /// Bodies in the model.
        bodies: usize,
    },
    /// The settings are out of range.
    #[error(transparent)]
    Settings(#[from] super::ObstacleError),
}

impl ContactSettings {
    /// Defaults for contact between `model`'s bodies: a stiffness that gives
    /// [`DEFAULT_BODY_FREQUENCY_FRACTION`] of the lattice's highest
    /// frequency, friction 0.5, damping ratio 0.2.
    pub fn for_bodies(model: &Model) -> Self {
        let obstacles = Self::for_model(model);
        let ratio = DEFAULT_BODY_FREQUENCY_FRACTION / super::DEFAULT_FREQUENCY_FRACTION;
        Self {
            stiffness: obstacles.stiffness * ratio * ratio,
            ..obstacles
        }
    }
}

/// The 2-triangle split of each boundary quad, oriented outward.
fn boundary_triangles(model: &Model) -> Vec<Triangle> {
    use std::collections::HashMap;
    let mut seen: HashMap<[u32; 4], (u32, u8, u32)> = HashMap::new();
    for (c, cell) in model.cells().iter().enumerate() {
        for (f, corners) in hexmesh::CELL_FACES.iter().enumerate() {
            let mut key = corners.map(|k| cell[k]);
            key.sort_unstable();
            seen.entry(key)
                .and_modify(|e| e.2 += 1)
                .or_insert((c as u32, f as u8, 1));
        }
    }
    let mut faces: Vec<(u32, u8)> = seen
        .into_values()
        .filter(|&(_, _, count)| count == 1)
        .map(|(c, f, _)| (c, f))
        .collect();
    faces.sort_unstable();
    let mut out = Vec::with_capacity(2 * faces.len());
    for (c, f) in faces {
        let cell = &model.cells()[c as usize];
        let q = hexmesh::CELL_FACES[f as usize].map(|k| cell[k]);
        let body = model.body_of_node(q[0] as usize) as u32;
        out.push(Triangle {
            nodes: [q[0], q[1], q[2]],
            body,
        });
        out.push(Triangle {
            nodes: [q[0], q[2], q[3]],
            body,
        });
    }
    out
}

/// Grid cell of a position.
fn grid_cell(p: Vec3, size: f64) -> [i64; 3] {
    std::array::from_fn(|k| (p[k] / size).floor() as i64)
}

/// A key of a grid cell (distinct cells may share one: the narrow phase
/// sorts them out).
fn grid_key(c: [i64; 3]) -> u64 {
    let mix = |v: i64, m: u64| (v as u64).wrapping_mul(m);
    mix(c[0], 0x9E37_79B9_7F4A_7C15)
        ^ mix(c[1], 0xC2B2_AE3D_27D4_EB4F)
        ^ mix(c[2], 0x1656_67B1_9E37_79F9)
}

impl BodyContact {
    /// Contact between `model`'s bodies ([`Model::bodies`]), with
    /// self-contact for the bodies where `self_contact[b]` is true.
    pub fn new(
        model: &Model,
        settings: ContactSettings,
        self_contact: &[bool],
    ) -> Result<Self, BodyContactError> {
        let base = Self::base(model, settings, self_contact)?;
        let bodies = model.bodies();
        let triangles = boundary_triangles(model);
        let boundary = model.boundary_nodes();
        let masses = model.masses();
        let mean = super::mean_boundary_mass(model, &boundary);
        // A body touches something when another body exists or it touches itself.
        let takes_part = |b: usize| bodies.len() > 1 || self_contact[b];
        let points: Vec<u32> = boundary
            .into_iter()
            .filter(|&n| takes_part(model.body_of_node(n as usize)))
            .collect();
        let mut point_of_node = vec![u32::MAX; model.num_nodes()];
        for (i, &n) in points.iter().enumerate() {
            point_of_node[n as usize] = i as u32;
        }
        let point_body = points
            .iter()
            .map(|&n| model.body_of_node(n as usize) as u32)
            .collect();
        let point_mass: Vec<f64> = points.iter().map(|&n| masses[n as usize]).collect();
        let stiffness_ratio: Vec<f64> = point_mass
            .iter()
            .map(|&m| if mean > 0.0 { m / mean } else { 1.0 })
            .collect();
        // Gershgorin: a touching point couples itself and its triangle's
        // nodes with a row sum of 2 k; a triangle node gathers about one
        // point's share per node of the touching side (its mass grows as
        // fast as the shares where resolutions differ). A margin of 1.5.
        let omega_sq_per_stiffness = 3.0
            * points
                .iter()
                .zip(&stiffness_ratio)
                .map(|(&n, r)| r / masses[n as usize])
                .fold(0.0, f64::max);
        Ok(Self {
            triangles,
            points,
            point_of_node,
            point_body,
            stiffness_ratio,
            point_mass,
            rest: if self_contact.iter().any(|&s| s) {
                model.rest_positions().to_vec()
            } else {
                Vec::new()
            },
            omega_sq_per_stiffness,
            ..base
        })
    }

    /// What both constructors share: the settings and the self-contact
    /// flags checked, each body's cell, the broad phase's grid size (twice
    /// the largest cell: a triangle's grown box spans at most two grid
    /// cells per axis), and no points or triangles yet.
    fn base(
        model: &Model,
        settings: ContactSettings,
        self_contact: &[bool],
    ) -> Result<Self, BodyContactError> {
        settings.validate()?;
        let bodies = model.bodies();
        if self_contact.len() != bodies.len() {
            return Err(BodyContactError::SelfContactCount {
                given: self_contact.len(),
                bodies: bodies.len(),
            });
        }
        Ok(Self {
            settings,
            triangles: Vec::new(),
            points: Vec::new(),
            point_of_node: Vec::new(),
            point_body: Vec::new(),
            stiffness_ratio: Vec::new(),
            point_mass: Vec::new(),
            self_contact: self_contact.to_vec(),
            body_h: bodies.iter().map(|b| b.h).collect(),
            rest: Vec::new(),
            grid_size: 2.0 * bodies.iter().map(|b| b.h).fold(0.0, f64::max),
            omega_sq_per_stiffness: 0.0,
            cache: PairCache::default(),
            candidates: CandidateCache::default(),
            span_limit: LATTICE_SPAN_LIMIT,
            carrier: None,
        })
    }

    /// Contact between `model`'s bodies through their embedded surfaces
    /// (`surface`, every body's, in the model's node numbering as
    /// [`Model::union`] joins them): each vertex is a point that touches the
    /// other bodies' surface triangles (and its own body's, for a body in
    /// `self_contact`), and the forces go to the vertices' cells' nodes by
    /// the trilinear weights. The bodies then touch where they are drawn,
    /// not up to a cell away where their lattices end.
    ///
    /// A vertex's stiffness is its share of the nodes' (a body's boundary
    /// nodes over its surface vertices, as for obstacles), so a dense
    /// surface does not stiffen the contact. A surface wound inward (a
    /// negative enclosed volume) is turned outward.
    pub fn on_surface(
        model: &Model,
        surface: &hexmesh::Embedding,
        settings: ContactSettings,
        self_contact: &[bool],
    ) -> Result<Self, BodyContactError> {
        let base = Self::base(model, settings, self_contact)?;
        let bodies = model.bodies();
        let count = surface.vertex_cells().len();
        let (nodes, weights): (Vec<[u32; 8]>, Vec<[f64; 8]>) =
            (0..count).map(|i| surface.vertex_weights(i)).unzip();
        let carrier = Carrier { nodes, weights };
        let rest = carrier.carry(model.rest_positions());
        let vertex_body: Vec<u32> = carrier
            .nodes
            .iter()
            .map(|n| model.body_of_node(n[0] as usize) as u32)
            .collect();
        // Each body's triangles, turned outward where its surface encloses
        // a negative volume.
        let mut volume = vec![0.0; bodies.len()];
        for t in surface.triangles() {
            let [a, b, c] = t.map(|v| rest[v as usize]);
            volume[vertex_body[t[0] as usize] as usize] += a.dot(&b.cross(&c)) / 6.0;
        }
        let triangles: Vec<Triangle> = surface
            .triangles()
            .iter()
            .map(|t| {
                let body = vertex_body[t[0] as usize];
                let nodes = if volume[body as usize] < 0.0 {
                    [t[0], t[2], t[1]]
                } else {
                    *t
                };
                Triangle { nodes, body }
            })
            .collect();
        let masses = model.masses();
        let boundary = model.boundary_nodes();
        let mean = super::mean_boundary_mass(model, &boundary);
        let mut boundary_per_body = vec![0usize; bodies.len()];
        for &n in &boundary {
            boundary_per_body[model.body_of_node(n as usize)] += 1;
        }
        let mut vertices_per_body = vec![0usize; bodies.len()];
        for &b in &vertex_body {
            vertices_per_body[b as usize] += 1;
        }
        let takes_part = |b: usize| bodies.len() > 1 || self_contact[b];
        let points: Vec<u32> = (0..count as u32)
            .filter(|&v| takes_part(vertex_body[v as usize] as usize))
            .collect();
        let mut point_of_node = vec![u32::MAX; count];
        for (i, &v) in points.iter().enumerate() {
            point_of_node[v as usize] = i as u32;
        }
        let point_body: Vec<u32> = points.iter().map(|&v| vertex_body[v as usize]).collect();
        let point_mass: Vec<f64> = points
            .iter()
            .map(|&v| {
                carrier
                    .bound(v)
                    .map(|(n, w)| masses[n as usize] * w.abs())
                    .sum()
            })
            .collect();
        let stiffness_ratio: Vec<f64> = points
            .iter()
            .zip(&point_mass)
            .map(|(&v, &m)| {
                let b = vertex_body[v as usize] as usize;
                let share = boundary_per_body[b] as f64 / vertices_per_body[b].max(1) as f64;
                (if mean > 0.0 { m / mean } else { 1.0 }) * share.min(1.0)
            })
            .collect();
        // Gershgorin on the stiffness mapped to the nodes: a vertex of
        // stiffness k couples its nodes a, b by w_a w_b k (row sums
        // |w_a| k), and its triangle's side as much again; a margin of 1.5.
        let mut rows = vec![0.0f64; model.num_nodes()];
        for (&v, &r) in points.iter().zip(&stiffness_ratio) {
            for (n, w) in carrier.bound(v) {
                rows[n as usize] += w.abs() * r;
            }
        }
        let omega_sq_per_stiffness = 3.0
            * rows
                .iter()
                .zip(masses)
                .filter(|(_, m)| **m > 0.0)
                .map(|(r, m)| r / m)
                .fold(0.0, f64::max);
        let grid_size = base.grid_size;
        let span_limit = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.nodes.map(|n| rest[n as usize]);
                let extent = a.sup(&b).sup(&c) - a.inf(&b).inf(&c);
                // Twice the size, grown by the depth limit, in grid cells.
                extent
                    .iter()
                    .map(|e| (2.0 * e / grid_size).ceil() as i64 + 2)
                    .product::<i64>()
            })
            .fold(LATTICE_SPAN_LIMIT, i64::max);
        Ok(Self {
            triangles,
            points,
            point_of_node,
            point_body,
            stiffness_ratio,
            point_mass,
            rest,
            omega_sq_per_stiffness,
            span_limit,
            carrier: Some(carrier),
            ..base
        })
    }

    /// Whether the bodies touch through their embedded surfaces
    /// ([`BodyContact::on_surface`]) rather than their lattices' boundaries.
    pub fn on_embedded_surface(&self) -> bool {
        self.carrier.is_some()
    }

    /// The positions (or velocities) the search and the forces work on:
    /// the nodes' own, or the embedded surface's vertices'.
    fn carried<'a>(&self, x: &'a [Vec3]) -> std::borrow::Cow<'a, [Vec3]> {
        match &self.carrier {
            None => std::borrow::Cow::Borrowed(x),
            Some(c) => std::borrow::Cow::Owned(c.carry(x)),
        }
    }

    /// The nodes that carry point-or-corner `v`, with their weights (the
    /// node itself without an embedded surface).
    fn nodes_of(&self, v: u32) -> Vec<(u32, f64)> {
        match &self.carrier {
            None => vec![(v, 1.0)],
            Some(c) => c.bound(v).collect(),
        }
    }

    /// Adds `force` at point-or-corner `v` to the node forces `f`.
    fn add_at(&self, v: u32, force: Vec3, f: &mut [Vec3]) {
        match &self.carrier {
            None => f[v as usize] += force,
            Some(c) => {
                for (n, w) in c.bound(v) {
                    f[n as usize] += force * w;
                }
            }
        }
    }

    /// The contact settings.
    pub fn settings(&self) -> &ContactSettings {
        &self.settings
    }

    /// Number of points that can touch another body (or their own).
    pub fn num_points(&self) -> usize {
        self.points.len()
    }

    /// Number of surface triangles.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// What body contact adds to `omega_max^2` (1/s^2), a Gershgorin bound.
    pub fn omega_sq(&self) -> f64 {
        self.settings.stiffness * self.omega_sq_per_stiffness
    }

    fn excluded(&self, point: usize, tri: &Triangle) -> bool {
        let body = self.point_body[point];
        if tri.body != body {
            return false;
        }
        if !self.self_contact[body as usize] {
            return true;
        }
        let p = self.rest[self.points[point] as usize];
        let r = SELF_EXCLUSION * self.body_h[body as usize];
        tri.nodes
            .iter()
            .any(|&n| (self.rest[n as usize] - p).norm_squared() < r * r)
    }

    /// Each body's box at `x` (of its boundary points), grown by one and a
    /// half of its cells: what another body's points must be inside to
    /// touch it (half a cell deep), and its triangles' nodes to be touched
    /// (a cell further).
    ///
    /// Grown by `extra` (m) more: the boxes of the candidate lists.
    fn body_boxes_grown(&self, x: &[Vec3], extra: f64) -> Vec<(Vec3, Vec3)> {
        let mut boxes =
            vec![(Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)); self.body_h.len()];
        for (&node, &b) in self.points.iter().zip(&self.point_body) {
            let (lo, hi) = &mut boxes[b as usize];
            *lo = lo.inf(&x[node as usize]);
            *hi = hi.sup(&x[node as usize]);
        }
        for (b, (lo, hi)) in boxes.iter_mut().enumerate() {
            let grow = (DEPTH_LIMIT + 1.0) * self.body_h[b] + extra;
            *lo = lo.add_scalar(-grow);
            *hi = hi.add_scalar(grow);
        }
        boxes
    }

    /// Whether something of body `body` with the box `[lo, hi]` can touch:
    /// the body touches itself, or another body's box meets it.
    fn may_touch(&self, body: usize, lo: &Vec3, hi: &Vec3, boxes: &[(Vec3, Vec3)]) -> bool {
        self.self_contact[body]
            || boxes.iter().enumerate().any(|(other, (olo, ohi))| {
                other != body && (0..3).all(|k| lo[k] <= ohi[k] && olo[k] <= hi[k])
            })
    }

    /// The broad phase's grid at `x`: the triangles with a node in
    /// `near` (a node another body's box holds, or of a body that touches
    /// itself), each in the grid cells its box covers.
    fn broad_phase(&self, x: &[Vec3], near: &[bool]) -> Grid {
        let size = self.grid_size;
        let mut entries = Vec::new();
        let mut geometry = Vec::new();
        let mut boxes = Vec::new();
        let mut point_normals = vec![Vec3::zeros(); self.points.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            if !tri.nodes.iter().any(|&n| near[n as usize]) {
                continue;
            }
            let corners = tri.nodes.map(|n| x[n as usize]);
            let [a, b, c] = corners;
            // A degenerate or exploded surface must not make the grid blow
            // up: such a triangle is left out (the solver's checks see it).
            if !corners.iter().all(|p| p.iter().all(|v| v.is_finite())) {
                continue;
            }
            let (lo, hi) = (a.inf(&b).inf(&c), a.sup(&b).sup(&c));
            let (first, last) = (grid_cell(lo, size), grid_cell(hi, size));
            let span = (0..3).try_fold(1i64, |n, k| {
                last[k]
                    .checked_sub(first[k])
                    .and_then(|d| d.checked_add(1))
                    .and_then(|d| n.checked_mul(d))
            });
            if !span.is_some_and(|n| (1..=self.span_limit).contains(&n)) {
                continue;
            }
            let grow = DEPTH_LIMIT * self.body_h[tri.body as usize];
            let Some(g) = Geometry::new(t as u32, corners, grow) else {
                continue;
            };
            // Every triangle of a near point is here: its normal is whole.
            let normal = g.area_normal();
            for &n in &tri.nodes {
                if let Some(sum) = point_normals.get_mut(self.point_of_node[n as usize] as usize) {
                    *sum += normal;
                }
            }
            let index = geometry.len() as u32;
            geometry.push(g);
            boxes.push((lo.add_scalar(-grow), hi.add_scalar(grow)));
            for i in first[0]..=last[0] {
                for j in first[1]..=last[1] {
                    for k in first[2]..=last[2] {
                        entries.push(Entry {
                            key: grid_key([i, j, k]),
                            geometry: index,
                            body: tri.body,
                        });
                    }
                }
            }
        }
        Grid::new(entries, geometry, boxes, point_normals)
    }

    /// The points that may touch at `x` (inside another body's box, or of a
    /// body that touches itself), and the nodes that do, as a mask.
    fn near_points(&self, x: &[Vec3]) -> (Vec<u32>, Vec<bool>) {
        self.near_points_within(x, 0.0)
    }

    /// [`BodyContact::near_points`] with the boxes grown by `extra` (m).
    fn near_points_within(&self, x: &[Vec3], extra: f64) -> (Vec<u32>, Vec<bool>) {
        let boxes = self.body_boxes_grown(x, extra);
        let mut near = vec![false; x.len()];
        let mut points = Vec::new();
        for (i, (&node, &b)) in self.points.iter().zip(&self.point_body).enumerate() {
            let p = x[node as usize];
            if self.may_touch(b as usize, &p, &p, &boxes) {
                near[node as usize] = true;
                points.push(i as u32);
            }
        }
        if self.carrier.is_some() {
            // A surface's triangles may be much larger than a cell: one
            // reaches into another body's box with none of its corners
            // there (a block's top face under a ball resting on it).
            for tri in &self.triangles {
                let [a, b, c] = tri.nodes.map(|n| x[n as usize]);
                let (lo, hi) = (a.inf(&b).inf(&c), a.sup(&b).sup(&c));
                if self.may_touch(tri.body as usize, &lo, &hi, &boxes) {
                    tri.nodes.iter().for_each(|&n| near[n as usize] = true);
                }
            }
        }
        (points, near)
    }

    /// The points inside a body at `x`, in point order, the points anchored
    /// in `anchors` (this contact's part of the state's) kept on their side.
    fn pairs(&self, x: &[Vec3], anchors: &[Option<Vec3>]) -> std::sync::Arc<Vec<Pair>> {
        self.with_persisting(self.searched(x), x, anchors, 0.0)
    }

    /// The points the search finds inside a body at `x` (cached: a step
    /// asks two or three times at the same positions).
    fn searched(&self, x: &[Vec3]) -> std::sync::Arc<Vec<Pair>> {
        self.searched_keyed(x).1
    }

    /// [`BodyContact::searched`], with the positions' key.
    fn searched_keyed(&self, x: &[Vec3]) -> (u64, std::sync::Arc<Vec<Pair>>) {
        let key = self.positions_key(x);
        let mut cache = self.cache.lock();
        if let Some((k, pairs)) = cache.as_ref()
            && *k == key
        {
            return (key, pairs.clone());
        }
        let pairs = std::sync::Arc::new(self.pairs_of_candidates(x, &[]));
        *cache = Some((key, pairs.clone()));
        (key, pairs)
    }

    /// `found` (in point order, deeper than `-margin` cells) with each
    /// anchored point kept on its anchor's triangle while it projects
    /// nearly onto it ([`TRIANGLE_PREFERENCE`]), and with the
    /// anchored points it lacks that are still behind their anchor's
    /// triangle ([`BodyContact::persisting`]).
    fn with_persisting(
        &self,
        found: std::sync::Arc<Vec<Pair>>,
        x: &[Vec3],
        anchors: &[Option<Vec3>],
        margin: f64,
    ) -> std::sync::Arc<Vec<Pair>> {
        let mut preferred: Option<Vec<Pair>> = None;
        for (k, pair) in found.iter().enumerate() {
            if let Some(keep) = self.preferred(pair, x, anchors, margin) {
                let list = preferred.get_or_insert_with(|| found[..k].to_vec());
                list.extend(keep);
            } else if let Some(list) = &mut preferred {
                list.push(*pair);
            }
        }
        let found = preferred.map_or(found, std::sync::Arc::new);
        // Both in point order: one walk finds the anchored points missing.
        let mut next = found.iter().map(|p| p.point as usize).peekable();
        let mut kept = Vec::new();
        for (i, anchor) in anchors.iter().enumerate().take(self.points.len()) {
            if anchor.is_none() {
                continue;
            }
            while next.next_if(|&j| j < i).is_some() {}
            if next.peek() != Some(&i)
                && let Some(pair) = self.persisting(i, x[self.points[i] as usize], x, anchors)
            {
                kept.push(pair);
            }
        }
        if kept.is_empty() {
            return found;
        }
        let mut all = Vec::with_capacity(found.len() + kept.len());
        let (mut a, mut b) = (found.iter().peekable(), kept.into_iter().peekable());
        while let (Some(p), Some(q)) = (a.peek(), b.peek()) {
            if p.point < q.point {
                all.extend(a.next());
            } else {
                all.extend(b.next());
            }
        }
        all.extend(a.copied());
        all.extend(b);
        std::sync::Arc::new(all)
    }

    /// `None` when `pair` stands; else what replaces it: its point against
    /// the triangle it is anchored to, when that is another one it projects
    /// onto within [`TRIANGLE_PREFERENCE`] (dropped when it is not deeper
    /// than `-margin` cells there).
    fn preferred(
        &self,
        pair: &Pair,
        x: &[Vec3],
        anchors: &[Option<Vec3>],
        margin: f64,
    ) -> Option<Option<Pair>> {
        let i = pair.point as usize;
        let (t, _, _) = Self::anchor_of(anchors, i)?;
        let tri = self.triangles.get(t as usize)?;
        if t == pair.triangle || !self.point_may_meet(i, tri.body) {
            return None;
        }
        let (g, corners) = self.anchor_geometry(i, x, anchors)?;
        let p = x[self.points[i] as usize];
        if !projects_within_preference(&g, p) {
            return None;
        }
        let near = g.closest(p, f64::INFINITY, || corners)?;
        let h = self.body_h[tri.body as usize];
        Some((-near.gap > -margin * h).then_some(Pair {
            point: pair.point,
            triangle: t,
            beta: near.beta,
            normal: near.normal,
            depth: -near.gap,
        }))
    }

    /// Point `i` at `p` against the plane of the triangle it is anchored to
    /// (it touched it at the end of the last step), when it is behind it by
    /// less than [`PERSIST_LIMIT`] of that body's cells: a point driven
    /// deeper than half a cell in one step (a fast impact) is still pushed
    /// back out of the side it came in through, not through the body.
    fn persisting(&self, i: usize, p: Vec3, x: &[Vec3], anchors: &[Option<Vec3>]) -> Option<Pair> {
        let (g, corners) = self.anchor_geometry(i, x, anchors)?;
        self.behind(i, p, &g, corners)
    }

    /// The geometry (grown by nothing) and corners at `x` of the triangle
    /// point `i` is anchored to.
    fn anchor_geometry(
        &self,
        i: usize,
        x: &[Vec3],
        anchors: &[Option<Vec3>],
    ) -> Option<(Geometry, [Vec3; 3])> {
        let (t, _, _) = Self::anchor_of(anchors, i)?;
        let tri = self.triangles.get(t as usize)?;
        let corners = tri.nodes.map(|n| x[n as usize]);
        Some((Geometry::new(t, corners, 0.0)?, corners))
    }

    /// Point `i` at `p` against triangle `g` (at `corners`), when it is
    /// behind its plane by less than [`PERSIST_LIMIT`] of that body's cells.
    fn behind(&self, i: usize, p: Vec3, g: &Geometry, corners: [Vec3; 3]) -> Option<Pair> {
        let near = g.closest(p, f64::INFINITY, || corners)?;
        let body = self.triangles[g.triangle as usize].body;
        let limit = PERSIST_LIMIT * self.body_h[body as usize];
        (near.gap < 0.0 && -near.gap < limit).then_some(Pair {
            point: i as u32,
            triangle: g.triangle,
            beta: near.beta,
            normal: near.normal,
            depth: -near.gap,
        })
    }

    /// A key of the points' positions' bits (every node of a surface
    /// triangle is a point): any change of one coordinate changes it.
    fn positions_key(&self, x: &[Vec3]) -> u64 {
        // A wrapping sum of each coordinate's bits times an odd number of
        // its own: one coordinate's change changes it, and the terms are
        // independent (a step asks four times; a chain of multiplications
        // waited on each product in turn).
        let mut key = x.len() as u64;
        for (k, &n) in self.points.iter().enumerate() {
            let p = x[n as usize];
            let m = (k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c16) | 1;
            let bits =
                p.x.to_bits() ^ p.y.to_bits().rotate_left(21) ^ p.z.to_bits().rotate_left(42);
            key = key.wrapping_add(bits.wrapping_mul(m));
        }
        key
    }

    /// The points deeper than `-margin` cells in a body at `x` (a negative
    /// depth: outside, that close), in point order.
    fn pairs_within(&self, x: &[Vec3], margin: f64) -> Vec<Pair> {
        if self.points.is_empty() {
            return Vec::new();
        }
        let (near, near_nodes) = self.near_points(x);
        let keys = self.broad_phase(x, &near_nodes);
        if keys.entries.is_empty() {
            return Vec::new();
        }
        let per_chunk: Vec<Vec<Pair>> = near
            .par_chunks(POINT_CHUNK)
            .map(|chunk| {
                let mut out = Vec::new();
                for &i in chunk {
                    let i = i as usize;
                    let p = x[self.points[i] as usize];
                    if let Some(pair) = self.nearest(i, p, x, &keys) {
                        let h = self.body_h[self.triangles[pair.triangle as usize].body as usize];
                        if pair.depth > -margin * h {
                            out.push(pair);
                        }
                    }
                }
                out
            })
            .collect();
        per_chunk.into_iter().flatten().collect()
    }

    /// The nearest triangle that point `i` at `p` projects onto, within the
    /// depth limit on either side (its depth may be negative: outside).
    fn nearest(&self, i: usize, p: Vec3, x: &[Vec3], keys: &Grid) -> Option<Pair> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        let reach = DEPTH_LIMIT * self.grid_size / 2.0;
        let first = grid_cell(p.add_scalar(-reach), self.grid_size);
        let last = grid_cell(p.add_scalar(reach), self.grid_size);
        let cells = (first[0]..=last[0]).flat_map(|a| {
            (first[1]..=last[1]).flat_map(move |b| (first[2]..=last[2]).map(move |c| [a, b, c]))
        });
        let mut best = Nearest::new(i, keys.point_normals.get(i).copied());
        for key in cells.map(grid_key) {
            for e in keys.bucket(key) {
                if e.key == key {
                    let g = e.geometry as usize;
                    self.consider(&mut best, p, x, e.body, &keys.geometry[g], keys.boxes[g]);
                }
            }
        }
        best.pair()
    }

    /// Counts triangle `g` (of body `body`, its grown box `(lo, hi)`) in
    /// `best`, the search of the nearest triangle that `best`'s point at
    /// `p` projects onto (the positions `x`).
    fn consider(
        &self,
        best: &mut Nearest,
        p: Vec3,
        x: &[Vec3],
        body: u32,
        g: &Geometry,
        (lo, hi): (Vec3, Vec3),
    ) {
        let i = best.point;
        if !self.point_may_meet(i, body) {
            return;
        }
        if (0..3).any(|k| p[k] < lo[k] || p[k] > hi[k]) {
            return;
        }
        if self.excluded(i, &self.triangles[g.triangle as usize]) {
            return;
        }
        self.weigh(best, p, g, x);
    }

    /// Counts triangle `g`, which may touch `best`'s point at `p`, in
    /// `best`: [`BodyContact::consider`] past its checks, which a
    /// candidate list passed when it was made (its box check is implied by
    /// the distance within reach).
    #[inline(always)]
    fn weigh(&self, best: &mut Nearest, p: Vec3, g: &Geometry, x: &[Vec3]) {
        let t = g.triangle;
        let faces = best.outward == Vec3::zeros() || best.outward.dot(&g.normal) < -FACING_COSINE;
        let slot = if faces {
            &mut best.facing
        } else {
            &mut best.other
        };
        let beyond = slot.as_ref().map_or(f64::INFINITY, |(d, _)| *d);
        let corners = || self.triangles[t as usize].nodes.map(|n| x[n as usize]);
        let Some(near) = g.closest(p, beyond, corners) else {
            return;
        };
        if near.distance >= g.reach {
            return;
        }
        // Nearer, or as near and less deep, or (an exact tie, where two
        // triangles share the closest point) the smaller triangle: the
        // same pick in whatever order the triangles come.
        let better = slot.as_ref().is_none_or(|(d, b)| {
            near.distance < *d
                || (near.distance == *d
                    && (near.gap.abs() < b.depth.abs()
                        || (near.gap.abs() == b.depth.abs() && t < b.triangle)))
        });
        if better {
            *slot = Some((
                near.distance,
                Pair {
                    point: best.point as u32,
                    triangle: t,
                    beta: near.beta,
                    normal: near.normal,
                    depth: -near.gap,
                },
            ));
        }
    }

    /// Candidate lists at `x`: the points that may touch while no point
    /// moves more than half the skin, and per point the triangles it may
    /// touch then (their boxes grown by the skin hold it).
    fn build_candidates(&self, x: &[Vec3]) -> Candidates {
        let h_min = self.body_h.iter().copied().fold(f64::INFINITY, f64::min);
        let skin = CANDIDATE_SKIN * h_min;
        let (near, near_nodes) = self.near_points_within(x, skin);
        let keys = self.broad_phase(x, &near_nodes);
        let reach = DEPTH_LIMIT * self.grid_size / 2.0 + skin;
        let lists: Vec<Vec<u32>> = near
            .par_chunks(POINT_CHUNK)
            .flat_map_iter(|chunk| {
                chunk.iter().map(|&i| {
                    let i = i as usize;
                    let p = x[self.points[i] as usize];
                    let mut list = Vec::new();
                    if !p.iter().all(|v| v.is_finite()) {
                        return list;
                    }
                    let first = grid_cell(p.add_scalar(-reach), self.grid_size);
                    let last = grid_cell(p.add_scalar(reach), self.grid_size);
                    for a in first[0]..=last[0] {
                        for b in first[1]..=last[1] {
                            for c in first[2]..=last[2] {
                                let key = grid_key([a, b, c]);
                                for e in keys.bucket(key) {
                                    let g = &keys.geometry[e.geometry as usize];
                                    let (lo, hi) = keys.boxes[e.geometry as usize];
                                    let inside = (0..3)
                                        .all(|k| p[k] >= lo[k] - skin && p[k] <= hi[k] + skin);
                                    // Within reach plus the skin: a point and the
                                    // corners each move less than half the skin
                                    // while the lists hold, so a triangle farther
                                    // now stays beyond reach.
                                    if e.key == key
                                        && inside
                                        && !self.excluded(i, &self.triangles[g.triangle as usize])
                                        && g.closest(p, f64::INFINITY, || {
                                            self.triangles[g.triangle as usize]
                                                .nodes
                                                .map(|n| x[n as usize])
                                        })
                                        .is_some_and(|c| c.distance < g.reach + skin)
                                    {
                                        list.push(g.triangle);
                                    }
                                }
                            }
                        }
                    }
                    list.sort_unstable();
                    list.dedup();
                    list
                })
            })
            .collect();
        // The needed triangles: the candidates and the near points' own.
        let mut near_of_node = vec![u32::MAX; x.len()];
        for (k, &i) in near.iter().enumerate() {
            near_of_node[self.points[i as usize] as usize] = k as u32;
        }
        let mut slot_of = vec![u32::MAX; self.triangles.len()];
        for list in &lists {
            for &t in list {
                slot_of[t as usize] = 0;
            }
        }
        let mut needed = Vec::new();
        let mut own = Vec::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            if slot_of[t] == 0 {
                slot_of[t] = needed.len() as u32;
                needed.push(t as u32);
            }
            let corners = tri.nodes.map(|n| near_of_node[n as usize]);
            if corners.iter().any(|&k| k != u32::MAX) {
                own.push((t as u32, slot_of[t], corners));
            }
        }
        let mut offsets = Vec::with_capacity(near.len() + 1);
        offsets.push(0u32);
        let mut slots = Vec::new();
        for list in lists {
            slots.extend(list.into_iter().map(|t| slot_of[t as usize]));
            offsets.push(slots.len() as u32);
        }
        Candidates {
            reference: self.points.iter().map(|&n| x[n as usize]).collect(),
            half_skin: 0.5 * skin,
            offsets,
            slots,
            geometry: vec![Geometry::default(); needed.len()],
            valid: vec![false; needed.len()],
            wanted: vec![false; needed.len()],
            decided: Vec::with_capacity(near.len()),
            normals: vec![Vec3::zeros(); near.len()],
            near,
            needed,
            own,
        }
    }

    /// The points inside a body at `x` (as [`BodyContact::pairs_within`]
    /// with no margin finds them), from the candidate lists, made again
    /// when a point has moved more than half their skin.
    ///
    /// With `anchors` (this contact's part of the state's; empty for none),
    /// a point that its anchor decides ([`BodyContact::anchored_pair`])
    /// is not searched: it comes as its anchor's pair, which is what
    /// [`BodyContact::with_persisting`] makes of whatever a search finds
    /// for it, at these anchors and at those the anchors' update leaves
    /// (anchored on the same triangle). The result is then no search's,
    /// but `with_persisting` turns it into the same pairs, bit for bit.
    fn pairs_of_candidates(&self, x: &[Vec3], anchors: &[Option<Vec3>]) -> Vec<Pair> {
        if self.points.is_empty() {
            return Vec::new();
        }
        let mut held = self.candidates.lock();
        if !held.as_ref().is_some_and(|c| c.hold(x, &self.points)) {
            *held = Some(self.build_candidates(x));
        }
        let c = held.as_mut().expect("made above");
        // Which near points their anchors decide (in contact, most: they
        // touched their anchor's triangle at the last sub-step's end).
        let decided = &mut c.decided;
        decided.clear();
        let mut searched = 0;
        if !anchors.is_empty() {
            let (near, points) = (&c.near, &self.points);
            decided.par_extend(near.par_iter().with_min_len(POINT_CHUNK).map(|&i| {
                let p = x[points[i as usize] as usize];
                self.anchored_pair(i as usize, p, x, anchors)
            }));
            searched = decided.iter().filter(|d| d.is_none()).count();
        }
        let every = decided.is_empty() || searched == decided.len();
        if !every {
            // Only the lists of the points left are weighed.
            c.wanted.fill(false);
            for (k, d) in decided.iter().enumerate() {
                if d.is_none() {
                    let list = &c.slots[c.offsets[k] as usize..c.offsets[k + 1] as usize];
                    list.iter().for_each(|&slot| c.wanted[slot as usize] = true);
                }
            }
        }
        let wanted = |slot: usize| every || c.wanted[slot];
        // The candidates' geometry now (in place: a search makes thousands
        // and each is two cache lines), and the near points' normals from all
        // their own triangles, as the broad phase makes them.
        for (slot, ((&t, g), valid)) in c
            .needed
            .iter()
            .zip(&mut c.geometry)
            .zip(&mut c.valid)
            .enumerate()
        {
            if !wanted(slot) {
                continue;
            }
            let tri = &self.triangles[t as usize];
            let corners = tri.nodes.map(|n| x[n as usize]);
            let grow = DEPTH_LIMIT * self.body_h[tri.body as usize];
            *valid =
                corners.iter().all(|p| p.iter().all(|v| v.is_finite())) && g.set(t, corners, grow);
        }
        c.normals.fill(Vec3::zeros());
        let searches = |k: u32| every || decided.get(k as usize).is_some_and(Option::is_none);
        for &(t, slot, corner_near) in &c.own {
            if !corner_near.iter().any(|&k| k != u32::MAX && searches(k)) {
                continue;
            }
            // As the broad phase: a triangle it leaves out (not finite, no
            // area) counts nowhere.
            let normal = if let Some(g) = c.geometry.get(slot as usize)
                && wanted(slot as usize)
            {
                if !c.valid[slot as usize] {
                    continue;
                }
                g.area_normal()
            } else {
                let tri = &self.triangles[t as usize];
                let corners = tri.nodes.map(|n| x[n as usize]);
                if !corners.iter().all(|p| p.iter().all(|v| v.is_finite())) {
                    continue;
                }
                let Some(g) = Geometry::new(t, corners, 0.0) else {
                    continue;
                };
                g.area_normal()
            };
            for k in corner_near {
                if let Some(sum) = c.normals.get_mut(k as usize) {
                    *sum += normal;
                }
            }
        }
        let c = &*c;
        let starts: Vec<usize> = (0..c.near.len()).step_by(POINT_CHUNK).collect();
        let per_chunk: Vec<Vec<Pair>> = starts
            .into_par_iter()
            .map(|start| {
                let mut out = Vec::new();
                for k in start..(start + POINT_CHUNK).min(c.near.len()) {
                    if let Some(Some(pair)) = c.decided.get(k) {
                        out.push(*pair);
                        continue;
                    }
                    let i = c.near[k] as usize;
                    let p = x[self.points[i] as usize];
                    if !p.iter().all(|v| v.is_finite()) {
                        continue;
                    }
                    let mut best = Nearest::new(i, Some(c.normals[k]));
                    let list = &c.slots[c.offsets[k] as usize..c.offsets[k + 1] as usize];
                    for &slot in list {
                        if c.valid[slot as usize] {
                            self.weigh(&mut best, p, &c.geometry[slot as usize], x);
                        }
                    }
                    // Inside only (a point just outside is a candidate,
                    // not a touch).
                    out.extend(best.pair().filter(|pair| pair.depth > 0.0));
                }
                out
            })
            .collect();
        per_chunk.into_iter().flatten().collect()
    }

    /// Point `i` at `p` against the triangle it is anchored to, when that
    /// decides its pair whatever a search finds: it projects onto the
    /// triangle within [`TRIANGLE_PREFERENCE`] (so a pair found elsewhere
    /// gives way to it, [`BodyContact::preferred`]) and lies behind it by
    /// less than [`PERSIST_LIMIT`] cells (so with no pair found it is kept,
    /// [`BodyContact::persisting`]). `None` where the search has its say:
    /// outside the band, in front of the plane (a pair found elsewhere
    /// would be dropped, but the anchors' update forgets the anchor and
    /// the next sub-step's start takes the search's pair), too deep, or
    /// an anchor on the point's own body without self-contact.
    fn anchored_pair(
        &self,
        i: usize,
        p: Vec3,
        x: &[Vec3],
        anchors: &[Option<Vec3>],
    ) -> Option<Pair> {
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        let (g, corners) = self.anchor_geometry(i, x, anchors)?;
        let body = self.triangles[g.triangle as usize].body;
        if !self.point_may_meet(i, body) || !projects_within_preference(&g, p) {
            return None;
        }
        self.behind(i, p, &g, corners)
    }

    /// Whether point `i` may touch a triangle of `body`: any other body's,
    /// its own only where that body touches itself.
    #[inline]
    fn point_may_meet(&self, i: usize, body: u32) -> bool {
        body != self.point_body[i] || self.self_contact[body as usize]
    }

    fn anchor_of(anchors: &[Option<Vec3>], i: usize) -> Option<(u32, f64, f64)> {
        let a = anchors.get(i).copied().flatten()?;
        let t = a.x;
        (t >= 0.0 && t.fract() == 0.0).then_some((t as u32, a.y, a.z))
    }

    /// Where the anchor `(triangle, beta_b, beta_c)` is at `x`.
    fn anchor_position(&self, x: &[Vec3], anchor: (u32, f64, f64)) -> Option<Vec3> {
        let tri = self.triangles.get(anchor.0 as usize)?;
        let [a, b, c] = tri.nodes.map(|n| x[n as usize]);
        Some(a + (b - a) * anchor.1 + (c - a) * anchor.2)
    }

    fn touch(&self, pair: &Pair, x: &[Vec3], v: &[Vec3], anchors: &[Option<Vec3>]) -> Touch {
        let i = pair.point as usize;
        let tri = &self.triangles[pair.triangle as usize];
        let node = self.points[i] as usize;
        let s = &self.settings;
        let k = s.stiffness * self.stiffness_ratio[i];
        let c = 2.0 * s.damping_ratio * (k * self.point_mass[i]).sqrt();
        let n = pair.normal;
        let v_face: Vec3 = (0..3)
            .map(|j| v[tri.nodes[j] as usize] * pair.beta[j])
            .sum();
        let v_rel = v[node] - v_face;
        let v_n = v_rel.dot(&n);
        let (f_n, _, _) = super::normal_force(k, c, pair.depth, v_n);
        let p = x[node];
        let anchored = Self::anchor_of(anchors, i).and_then(|a| self.anchor_position(x, a));
        let d = anchored.map_or(Vec3::zeros(), |a| p - a);
        let delta = d - n * d.dot(&n);
        let (friction, sliding) = super::coulomb(delta, k, f_n, s);
        Touch {
            force: n * f_n + friction,
            delta,
            f_n,
            sliding,
            stiffness: k,
        }
    }

    /// Adds the contact forces at positions `x` and velocities `v` to `f`;
    /// `anchors` are this contact's entries of the state's anchors (empty:
    /// every contact is new).
    pub fn add_forces(&self, x: &[Vec3], v: &[Vec3], anchors: &[Option<Vec3>], f: &mut [Vec3]) {
        let (x, v) = (self.carried(x), self.carried(v));
        for pair in self.pairs(&x, anchors).iter() {
            let touch = self.touch(pair, &x, &v, anchors);
            self.spread(pair, touch.force, f);
        }
    }

    /// [`BodyContact::add_forces`], noting in `touched` every node whose
    /// entry of `f` it changed (the explicit step then clears those only,
    /// not every node's).
    pub fn add_forces_noting(
        &self,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
        touched: &mut Vec<u32>,
    ) {
        let (x, v) = (self.carried(x), self.carried(v));
        let pairs = self.pairs(&x, anchors);
        self.add_pair_forces(&pairs, &x, &v, anchors, f, touched);
    }

    /// [`BodyContact::add_forces_noting`] at the positions `x` where the
    /// last sub-step's end found `found`, which the caller vouches for (the
    /// next sub-step of the same call starts there; debug builds check the
    /// key): what the search found there, with `anchors` (updated since)
    /// having their say.
    pub(crate) fn add_forces_with(
        &self,
        found: &StepPairs,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
        touched: &mut Vec<u32>,
    ) {
        let (x, v) = (self.carried(x), self.carried(v));
        debug_assert_eq!(
            found.key,
            self.positions_key(&x),
            "pairs of other positions"
        );
        let pairs = self.with_persisting(found.searched.clone(), &x, anchors, 0.0);
        self.add_pair_forces(&pairs, &x, &v, anchors, f, touched);
    }

    /// The forces of `pairs` into `f`, their nodes noted in `touched`.
    fn add_pair_forces(
        &self,
        pairs: &[Pair],
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        f: &mut [Vec3],
        touched: &mut Vec<u32>,
    ) {
        for pair in pairs {
            let touch = self.touch(pair, x, v, anchors);
            self.spread(pair, touch.force, f);
            self.note_nodes(pair, touched);
        }
    }

    /// The force on the point and minus it on the triangle, by its weights.
    fn spread(&self, pair: &Pair, force: Vec3, f: &mut [Vec3]) {
        let tri = &self.triangles[pair.triangle as usize];
        self.add_at(self.points[pair.point as usize], force, f);
        for (j, &n) in tri.nodes.iter().enumerate() {
            self.add_at(n, -force * pair.beta[j], f);
        }
    }

    /// Notes in `touched` the nodes a pair's force moves: its point's and
    /// its triangle's (a node of several may come more than once).
    fn note_nodes(&self, pair: &Pair, touched: &mut Vec<u32>) {
        let tri = &self.triangles[pair.triangle as usize];
        let point = self.points[pair.point as usize];
        match &self.carrier {
            None => {
                touched.push(point);
                touched.extend_from_slice(&tri.nodes);
            }
            Some(c) => {
                for v in std::iter::once(point).chain(tri.nodes) {
                    touched.extend(c.bound(v).map(|(n, _)| n));
                }
            }
        }
    }

    /// Adds the contact's exact `d(force)/dx` to `jac` (see the module
    /// docs); `dv_dx` as in [`super::Contact::add_jacobian`].
    pub fn add_jacobian(
        &self,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        dv_dx: f64,
        jac: &mut BlockCsr,
    ) {
        // A static solve (no velocity) takes the points just outside a
        // surface as touching in its tangent: a body that only contact holds
        // otherwise has a singular tangent wherever an iterate lifts it off.
        let margin = if dv_dx == 0.0 { STATIC_MARGIN } else { 0.0 };
        let (x, v) = (self.carried(x), self.carried(v));
        let (x, v) = (&x[..], &v[..]);
        let pairs = self.with_persisting(
            std::sync::Arc::new(self.pairs_within(x, margin)),
            x,
            anchors,
            margin,
        );
        // Per pair, the nodes (with their weights) of each point or corner
        // its forces depend on, found once for the pattern and the blocks.
        let tangents: Vec<(Vec<WeightedNodes>, Vec<Mat3>)> = pairs
            .par_iter()
            .with_min_len(64)
            .map(|pair| {
                let (vertices, blocks) = self.pair_blocks(pair, x, v, anchors, dv_dx);
                (vertices.iter().map(|&m| self.nodes_of(m)).collect(), blocks)
            })
            .collect();
        // The point, its triangle's corners and its anchor's are coupled:
        // grow the pattern (both ways, so that it stays symmetric).
        let mut extra = Vec::new();
        for (nodes, _) in &tangents {
            for a in &nodes[..4] {
                for b in nodes {
                    for &(na, _) in a {
                        for &(nb, _) in b {
                            extra.push((na, nb));
                            extra.push((nb, na));
                        }
                    }
                }
            }
        }
        jac.extend_pattern(&extra);
        for (nodes, blocks) in &tangents {
            let slots = nodes.len();
            for (r, a) in nodes[..4].iter().enumerate() {
                for (s, b) in nodes.iter().enumerate() {
                    let block = blocks[r * slots + s];
                    for &(na, wa) in a {
                        for &(nb, wb) in b {
                            if let Some(idx) = jac.find(na as usize, nb as usize) {
                                jac.blocks[idx] += block * (wa * wb);
                            }
                        }
                    }
                }
            }
        }
    }

    /// The derivative of `pair`'s forces: the points and corners they
    /// depend on (the point, its triangle's corners, then its anchor
    /// triangle's other corners) and the blocks `d(force r)/d(x_s)`, row
    /// `r` one of the first four, row-major. Exact where the point is
    /// behind the triangle's plane ([`super::pair_tangent`]); a point just
    /// outside (a static solve's margin) has the contact's stiffness along
    /// the normal, and its stick spring where anchored.
    fn pair_blocks(
        &self,
        pair: &Pair,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &[Option<Vec3>],
        dv_dx: f64,
    ) -> (Vec<u32>, Vec<Mat3>) {
        let i = pair.point as usize;
        let tri = &self.triangles[pair.triangle as usize];
        let mut vertices = vec![self.points[i]];
        vertices.extend(tri.nodes);
        let anchor = Self::anchor_of(anchors, i)
            .and_then(|(t, b, c)| Some((self.triangles.get(t as usize)?, b, c)));
        let k = self.settings.stiffness * self.stiffness_ratio[i];
        if pair.depth <= 0.0 {
            let n = pair.normal;
            let nn = n * n.transpose();
            let stick = if anchor.is_some() {
                Mat3::identity() - nn
            } else {
                Mat3::zeros()
            };
            let block = -(nn + stick) * k;
            let w = [1.0, -pair.beta[0], -pair.beta[1], -pair.beta[2]];
            let blocks = (0..16).map(|rs| block * (w[rs / 4] * w[rs % 4])).collect();
            return (vertices, blocks);
        }
        let anchor_slots = anchor.map(|(t, b, c)| {
            let slots = t.nodes.map(|n| {
                vertices.iter().position(|&m| m == n).unwrap_or_else(|| {
                    vertices.push(n);
                    vertices.len() - 1
                })
            });
            (slots, b, c)
        });
        let xs: Vec<Vec3> = vertices.iter().map(|&m| x[m as usize]).collect();
        let vs: Vec<Vec3> = vertices.iter().map(|&m| v[m as usize]).collect();
        let tangent = super::pair_tangent::pair_tangent(&super::pair_tangent::PairInput {
            x: &xs,
            v: &vs,
            anchor: anchor_slots,
            stiffness: k,
            damping: 2.0 * self.settings.damping_ratio * (k * self.point_mass[i]).sqrt(),
            dv_dx,
            settings: &self.settings,
        });
        (vertices, tangent.blocks)
    }

    /// Anchors every point that touches at `x` and has no anchor where it
    /// was on its triangle at the start of the step, the positions then
    /// being `x - dt v` (as after a drift by `v`): the explicit step calls
    /// it before the forces at a step's end, so that a contact made during
    /// the step has its friction at once. Anchored where it touched (by
    /// [`BodyContact::update_anchors`]), a new contact's first forces have
    /// no friction, and a body that hops as it slides loses a step of
    /// friction at every landing.
    ///
    /// `anchors` holds one entry per point ([`BodyContact::num_points`]);
    /// of another length it is left alone.
    pub fn anchor_at_step_start(
        &self,
        x: &[Vec3],
        v: &[Vec3],
        dt: f64,
        anchors: &mut [Option<Vec3>],
    ) {
        self.anchor_at_step_start_and_add_forces(x, v, dt, anchors, None, true);
    }

    /// [`BodyContact::anchor_at_step_start`], then
    /// [`BodyContact::add_forces_noting`] at the same positions with the
    /// anchors so set, from one search of the pairs (anchoring a new
    /// contact on the triangle it touches changes no pair); returns those
    /// pairs for [`BodyContact::update_anchors_with`] after the step.
    /// `anchors` holds one entry per point ([`BodyContact::num_points`]);
    /// of another length nothing is anchored. With `cached`, the search
    /// goes through the cache of the last positions searched; without, it
    /// is made afresh and not kept: the explicit step, which hands the
    /// pairs on itself, saves a key of the positions per step (the key of
    /// the pairs handed on is then made in debug builds only, which check
    /// it).
    pub(crate) fn anchor_at_step_start_and_add_forces(
        &self,
        x: &[Vec3],
        v: &[Vec3],
        dt: f64,
        anchors: &mut [Option<Vec3>],
        forces: Option<(&mut [Vec3], &mut Vec<u32>)>,
        cached: bool,
    ) -> StepPairs {
        let (xc, vc) = (self.carried(x), self.carried(v));
        let (key, searched) = if cached {
            self.searched_keyed(&xc)
        } else {
            let key = if cfg!(debug_assertions) {
                self.positions_key(&xc)
            } else {
                0
            };
            (
                key,
                std::sync::Arc::new(self.pairs_of_candidates(&xc, anchors)),
            )
        };
        let pairs = self.with_persisting(searched.clone(), &xc, anchors, 0.0);
        if anchors.len() == self.points.len() {
            self.anchor_pairs_at_step_start(&pairs, &xc, &vc, dt, anchors);
        }
        if let Some((f, touched)) = forces {
            self.add_pair_forces(&pairs, &xc, &vc, anchors, f, touched);
        }
        StepPairs {
            key,
            searched,
            pairs,
        }
    }

    /// Anchors each of `pairs` without an anchor where its point and
    /// triangle were at the step's start (`x - dt v`).
    fn anchor_pairs_at_step_start(
        &self,
        pairs: &[Pair],
        x: &[Vec3],
        v: &[Vec3],
        dt: f64,
        anchors: &mut [Option<Vec3>],
    ) {
        let start = |n: u32| x[n as usize] - v[n as usize] * dt;
        for pair in pairs {
            let i = pair.point as usize;
            if anchors[i].is_some() {
                continue;
            }
            let tri = &self.triangles[pair.triangle as usize];
            if let Some(g) = Geometry::new(pair.triangle, tri.nodes.map(start), 0.0) {
                let beta = g.barycentric(start(self.points[i]));
                anchors[i] = Some(Vec3::new(f64::from(pair.triangle), beta[1], beta[2]));
            }
        }
    }

    /// After a step: anchors new contacts where they touched, lets sliding
    /// ones follow to the kinetic limit, clears those that left. `anchors`
    /// holds one entry per point ([`BodyContact::num_points`]; of another
    /// length it is refilled with `None`s first).
    ///
    /// In place: a pair's new anchor depends on its own point's old one
    /// only, and the pairs are found before any changes.
    pub fn update_anchors(&self, x: &[Vec3], v: &[Vec3], anchors: &mut [Option<Vec3>]) {
        if anchors.len() != self.points.len() {
            anchors.fill(None);
            if anchors.len() != self.points.len() {
                return;
            }
        }
        let (x, v) = (self.carried(x), self.carried(v));
        let pairs = self.pairs(&x, anchors);
        self.update_anchors_of_pairs(&pairs, &x, &v, anchors);
    }

    /// [`BodyContact::update_anchors`] with the pairs an explicit step's
    /// end found ([`BodyContact::anchor_at_step_start_and_add_forces`]) at
    /// the positions `x`, which the caller vouches for (the kick after the
    /// drift moves velocities only; debug builds check the key): at the
    /// same positions and anchors, they are the pairs.
    pub(crate) fn update_anchors_with(
        &self,
        found: &StepPairs,
        x: &[Vec3],
        v: &[Vec3],
        anchors: &mut [Option<Vec3>],
    ) {
        let (xc, vc) = (self.carried(x), self.carried(v));
        debug_assert_eq!(
            found.key,
            self.positions_key(&xc),
            "pairs of other positions"
        );
        if anchors.len() != self.points.len() {
            self.update_anchors(x, v, anchors);
            return;
        }
        self.update_anchors_of_pairs(&found.pairs, &xc, &vc, anchors);
    }

    /// [`BodyContact::update_anchors`] with the pairs at `x` found.
    fn update_anchors_of_pairs(
        &self,
        pairs: &[Pair],
        x: &[Vec3],
        v: &[Vec3],
        anchors: &mut [Option<Vec3>],
    ) {
        // The points that touch no more (pairs are in point order).
        let mut next_pair = pairs.iter().map(|p| p.point as usize).peekable();
        for (i, a) in anchors.iter_mut().enumerate() {
            while next_pair.next_if(|&p| p < i).is_some() {}
            if next_pair.peek() != Some(&i) {
                *a = None;
            }
        }
        for pair in pairs.iter() {
            let i = pair.point as usize;
            let encode = |t: u32, beta: [f64; 3]| Some(Vec3::new(f64::from(t), beta[1], beta[2]));
            let here = encode(pair.triangle, pair.beta);
            let old = Self::anchor_of(anchors, i);
            anchors[i] = match old {
                None => here,
                Some(anchor) => {
                    let touch = self.touch(pair, x, v, anchors);
                    let target = if !touch.sliding {
                        if anchor.0 == pair.triangle {
                            continue;
                        }
                        self.anchor_position(x, anchor)
                    } else {
                        let len = touch.delta.norm();
                        let back = if len > 0.0 {
                            touch.delta
                                * (super::kinetic_offset(
                                    touch.stiffness,
                                    touch.f_n,
                                    &self.settings,
                                ) / len)
                        } else {
                            Vec3::zeros()
                        };
                        Some(x[self.points[i] as usize] - back)
                    };
                    // The anchor moves to the triangle the point touches now
                    // (a point of its plane, outside it if need be). Kept on
                    // the triangle first touched, it would be extrapolated
                    // ever farther as the point slides on, and the small
                    // turns of that triangle swung it about: a block
                    // sliding over another's many triangles then had
                    // friction forces several times mu f_n.
                    let tri = &self.triangles[pair.triangle as usize];
                    let plane = Geometry::new(pair.triangle, tri.nodes.map(|n| x[n as usize]), 0.0);
                    match (plane, target) {
                        (Some(g), Some(target)) => encode(pair.triangle, g.barycentric(target)),
                        _ => here,
                    }
                }
            };
        }
    }

    /// Anchors for a static solve: every point that lies within the depth
    /// limit of a surface at `x` is anchored at its projection there (so
    /// that friction holds it where it starts, as for obstacles).
    pub fn static_anchors(&self, x: &[Vec3]) -> Vec<Option<Vec3>> {
        let x = self.carried(x);
        let x = &x[..];
        let keys = self.broad_phase(x, &self.near_points(x).1);
        (0..self.points.len())
            .map(|i| {
                let pair = self.nearest(i, x[self.points[i] as usize], x, &keys)?;
                Some(Vec3::new(
                    f64::from(pair.triangle),
                    pair.beta[1],
                    pair.beta[2],
                ))
            })
            .collect()
    }

    /// Penalty energy `k d^2 / 2` over the touching points (J).
    pub fn energy(&self, x: &[Vec3]) -> f64 {
        self.pairs(&self.carried(x), &[])
            .iter()
            .map(|p| {
                0.5 * self.settings.stiffness
                    * self.stiffness_ratio[p.point as usize]
                    * p.depth
                    * p.depth
            })
            .sum()
    }

    /// Total contact force on each body (N), at `x` and `v`: equal and
    /// opposite between two bodies (self-contact adds zero to its body).
    pub fn body_forces(&self, x: &[Vec3], v: &[Vec3], anchors: &[Option<Vec3>]) -> Vec<Vec3> {
        let mut out = vec![Vec3::zeros(); self.body_h.len()];
        let (x, v) = (self.carried(x), self.carried(v));
        for pair in self.pairs(&x, anchors).iter() {
            let touch = self.touch(pair, &x, &v, anchors);
            let tri = &self.triangles[pair.triangle as usize];
            out[self.point_body[pair.point as usize] as usize] += touch.force;
            out[tri.body as usize] -= touch.force;
        }
        out
    }

    /// How deep the deepest point is inside another body (or its own
    /// surface) at `x` (m; 0 when none is).
    pub fn max_depth(&self, x: &[Vec3]) -> f64 {
        self.max_depth_with(x, &[])
    }

    /// [`BodyContact::max_depth`] with the state's anchors (this contact's
    /// part): the depth of points kept on their side too.
    pub fn max_depth_with(&self, x: &[Vec3], anchors: &[Option<Vec3>]) -> f64 {
        self.pairs(&self.carried(x), anchors)
            .iter()
            .map(|p| p.depth)
            .fold(0.0, f64::max)
    }
}

/// Where a point is against a triangle.
struct Closest {
    /// Distance to the triangle's closest point (m).
    distance: f64,
    /// Gap to the triangle's plane along its normal (m, negative behind).
    gap: f64,
    /// Barycentric coordinates of the closest point (in the triangle).
    beta: [f64; 3],
    /// The triangle's unit normal.
    normal: Vec3,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Material;
    use crate::model::PaperModel;

    fn cube(n: u32, h: f64, origin: [f64; 3]) -> Model {
        let lattice = hexmesh::Lattice::block([n, n, n], h, origin).unwrap();
        Model::new(
            &lattice,
            Material::new(1e5, 0.3, 1000.0).unwrap(),
            &PaperModel,
        )
        .unwrap()
    }

    /// `rest` with the nodes `upper` (a cube above another) moved down 2 mm
    /// into the lower cube over 60 steps, across by 0.3 mm and turned by
    /// 2 mrad about z per step: positions at step `s`.
    fn sunk_and_turned(rest: &[Vec3], upper: std::ops::Range<usize>, s: f64) -> Vec<Vec3> {
        let (dz, dx, angle) = (-0.002 * (s / 60.0).min(1.0), 3e-4 * s, 0.002 * s);
        let (c, sn) = (angle.cos(), angle.sin());
        let mut x = rest.to_vec();
        for n in upper {
            let p = rest[n] - Vec3::new(0.06, 0.05, 0.0);
            x[n] = Vec3::new(
                c * p.x - sn * p.y + 0.06 + dx,
                sn * p.x + c * p.y + 0.05,
                p.z + dz,
            );
        }
        x
    }

    fn same(a: &[Pair], b: &[Pair]) -> bool {
        a.len() == b.len()
            && a.iter().zip(b).all(|(p, q)| {
                p.point == q.point
                    && p.triangle == q.triangle
                    && p.depth == q.depth
                    && p.beta == q.beta
                    && p.normal == q.normal
            })
    }

    /// `Geometry::closest` picks the edge by the weights' signs: its
    /// distance and closest point are those of the nearest of all three
    /// edges (or the projection inside), for triangles acute and obtuse
    /// and points all around them (past an obtuse corner, an edge's inside
    /// is nearer than the corner).
    #[test]
    fn the_closest_point_is_the_nearest_of_the_triangle() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut obtuse_inside_an_edge = 0;
        for _ in 0..2000 {
            let corners = [(); 3].map(|_| Vec3::new(next(), next(), 0.2 * next()));
            let Some(g) = Geometry::new(0, corners, 0.0) else {
                continue;
            };
            let p = Vec3::new(2.0 * next(), 2.0 * next(), next());
            let near = g.closest(p, f64::INFINITY, || corners).unwrap();
            let q: Vec3 = (0..3).map(|k| corners[k] * near.beta[k]).sum();
            // The brute force: the projection if inside, else every edge.
            let beta = g.barycentric(p);
            let expected = if beta.iter().all(|&w| w >= 0.0) {
                near.gap.abs()
            } else {
                (0..3)
                    .map(|i| {
                        let (a, b) = (corners[i], corners[(i + 1) % 3]);
                        let s = ((p - a).dot(&(b - a)) / (b - a).norm_squared()).clamp(0.0, 1.0);
                        (p - (a + (b - a) * s)).norm()
                    })
                    .fold(f64::INFINITY, f64::min)
            };
            assert!(
                (near.distance - expected).abs() <= 1e-12,
                "{} vs {expected}",
                near.distance
            );
            assert!(((p - q).norm() - expected).abs() <= 1e-12);
            let negative = beta.iter().filter(|&&w| w < 0.0).count();
            let on_corner = near.beta.contains(&1.0);
            obtuse_inside_an_edge += usize::from(negative == 2 && !on_corner);
        }
        assert!(obtuse_inside_an_edge > 10, "{obtuse_inside_an_edge}");
    }

    /// The candidate lists find exactly the pairs the grid search finds, as
    /// the upper cube slides, sinks and turns on the lower one (the lists
    /// kept while they hold, made again when they do not), with and
    /// without self-contact.
    #[test]
    fn candidate_lists_find_what_the_grid_finds() {
        for self_contact in [false, true] {
            let lower = cube(4, 0.025, [0.0, 0.0, 0.0]);
            let upper = cube(5, 0.016, [0.02, 0.01, 0.1]);
            let model = Model::union(&[lower, upper]).unwrap();
            let contact = BodyContact::new(
                &model,
                ContactSettings::for_bodies(&model),
                &[false, self_contact],
            )
            .unwrap();
            let rest = model.rest_positions().to_vec();
            let upper_nodes = model.bodies()[1].nodes.clone();
            let (mut rebuilt, mut kept, mut touching) = (0, 0, 0);
            for step in 0..120 {
                let x = sunk_and_turned(&rest, upper_nodes.clone(), step as f64);
                let held = contact
                    .candidates
                    .lock()
                    .as_ref()
                    .is_some_and(|c| c.hold(&x, &contact.points));
                if held {
                    kept += 1;
                } else {
                    rebuilt += 1;
                }
                let grid = contact.pairs_within(&x, 0.0);
                let lists = contact.pairs_of_candidates(&x, &[]);
                assert!(
                    same(&grid, &lists),
                    "step {step}: {} vs {} pairs",
                    grid.len(),
                    lists.len()
                );
                touching += usize::from(!grid.is_empty());
            }
            assert!(touching > 60, "{touching}");
            assert!(kept > 10 && rebuilt > 2, "kept {kept}, made {rebuilt}");
        }
    }
    /// What the explicit step hands on from a sub-step's end (the search's
    /// pairs, `StepPairs`) gives the anchors' update and the next
    /// sub-step's start forces that a search of their own gives, bit for
    /// bit: a cube sinking into another, sliding across it and turning
    /// (new contacts, sticking and sliding ones, points kept on their
    /// anchor's triangle), with friction and damping. Without the cache,
    /// the points their anchors decide are not searched
    /// (`BodyContact::anchored_pair`): the pairs are still a search's.
    #[test]
    fn the_pairs_handed_on_give_what_a_search_gives() {
        let lower = cube(4, 0.025, [0.0, 0.0, 0.0]);
        let upper = cube(5, 0.016, [0.02, 0.01, 0.1]);
        let model = Model::union(&[lower, upper]).unwrap();
        let contact =
            BodyContact::new(&model, ContactSettings::for_bodies(&model), &[false, false]).unwrap();
        let rest = model.rest_positions().to_vec();
        let upper_nodes = model.bodies()[1].nodes.clone();
        let dt = 1e-3;
        // Then back the other way.
        let placed = |s: f64| {
            let s = if s < 80.0 { s } else { 160.0 - s };
            sunk_and_turned(&rest, upper_nodes.clone(), s)
        };
        let mut anchors = vec![None; contact.num_points()];
        let (mut touching, mut sliding_steps) = (0, 0);
        // Points the search left to their anchors, and points searched
        // beside them (in steps that do both).
        let (mut decided, mut mixed) = (0, 0);
        for step in 1..140 {
            let x = placed(step as f64);
            let before = placed(step as f64 - 1.0);
            let v: Vec<Vec3> = x.iter().zip(&before).map(|(a, b)| (a - b) / dt).collect();
            let mut f = vec![Vec3::zeros(); x.len()];
            let mut touched = Vec::new();
            let found = contact.anchor_at_step_start_and_add_forces(
                &x,
                &v,
                dt,
                &mut anchors,
                Some((&mut f, &mut touched)),
                // Through the search's cache or not: the same pairs.
                step % 2 == 0,
            );
            if let Some(c) = contact.candidates.lock().as_ref()
                && step % 2 == 1
            {
                let by_anchor = c.decided.iter().filter(|d| d.is_some()).count();
                decided += by_anchor;
                mixed += usize::from(by_anchor > 0 && by_anchor < c.decided.len());
            }
            let mut searched_anchors = anchors.clone();
            contact.update_anchors(&x, &v, &mut searched_anchors);
            let kept_before = anchors.clone();
            contact.update_anchors_with(&found, &x, &v, &mut anchors);
            assert_eq!(anchors, searched_anchors, "step {step}: anchors");
            sliding_steps += usize::from(
                anchors
                    .iter()
                    .zip(&kept_before)
                    .any(|(a, b)| a.is_some() && b.is_some() && a != b),
            );
            let (mut f_searched, mut f_handed) =
                (vec![Vec3::zeros(); x.len()], vec![Vec3::zeros(); x.len()]);
            let (mut t_searched, mut t_handed) = (Vec::new(), Vec::new());
            contact.add_forces_noting(&x, &v, &anchors, &mut f_searched, &mut t_searched);
            contact.add_forces_with(&found, &x, &v, &anchors, &mut f_handed, &mut t_handed);
            assert_eq!(f_searched, f_handed, "step {step}: forces");
            assert_eq!(t_searched, t_handed, "step {step}: nodes noted");
            touching += usize::from(!found.pairs.is_empty());
        }
        assert!(touching > 100, "{touching}");
        assert!(sliding_steps > 20, "{sliding_steps}");
        assert!(
            decided > 1000 && mixed > 50,
            "{decided} decided, {mixed} mixed"
        );
    }

    /// The tangent of body contact is the exact derivative of its forces:
    /// with friction (points sticking and sliding, anchored on the
    /// triangle they touch or on its neighbour), with damping (velocities
    /// following positions by `dv_dx`), the normal turning with the
    /// triangles and the weights sliding with the points, against central
    /// differences of the forces. The forces the derivatives are taken of
    /// are the force pass's.
    #[test]
    fn the_contact_tangent_is_the_derivative_of_the_forces() {
        let lower = cube(4, 0.025, [0.0, 0.0, 0.0]);
        let upper = cube(5, 0.016, [0.012, 0.007, 0.1 - 2e-5]);
        let model = Model::union(&[lower, upper]).unwrap();
        let settings = ContactSettings {
            friction_static: 0.5,
            friction_kinetic: 0.4,
            damping_ratio: 0.3,
            ..ContactSettings::for_bodies(&model)
        };
        let contact = BodyContact::new(&model, settings, &[false, false]).unwrap();
        let wobble = |i: usize, scale: f64| {
            let t = i as f64;
            Vec3::new((1.3 * t).sin(), (0.7 * t).cos(), (2.1 * t).sin()) * scale
        };
        let x0: Vec<Vec3> = (model.rest_positions().iter().enumerate())
            .map(|(i, r)| r + wobble(i, 1e-6))
            .collect();
        // Anchored where they touch at x0; every other anchor expressed on
        // the other triangle of its face (the same material point).
        let mut anchors = contact.static_anchors(&x0);
        let mut moved = 0;
        for a in anchors.iter_mut().step_by(2).flatten() {
            let t = a.x as u32;
            let corners = |t: u32| contact.triangles[t as usize].nodes.map(|n| x0[n as usize]);
            let [p, q, r] = corners(t);
            let at = p + (q - p) * a.y + (r - p) * a.z;
            let other = Geometry::new(t ^ 1, corners(t ^ 1), 0.0).unwrap();
            let beta = other.barycentric(at);
            *a = Vec3::new(f64::from(t ^ 1), beta[1], beta[2]);
            moved += 1;
        }
        assert!(moved > 5, "{moved}");
        // The upper body slid by up to three times the stick limit.
        let upper_nodes = model.bodies()[1].nodes.clone();
        let mut x = x0.clone();
        for n in upper_nodes {
            let f = |k: f64| (n as f64 * k).fract();
            x[n] += Vec3::new(3e-5 * f(0.618), 1e-5 * f(0.377), 0.0);
        }
        let v: Vec<Vec3> = (0..x.len()).map(|i| wobble(i + 7, 1e-3)).collect();
        let dv_dx = 100.0;
        // The pairs the forces and the tangent take.
        let pairs = contact.with_persisting(
            std::sync::Arc::new(contact.pairs_within(&x, 0.0)),
            &x,
            &anchors,
            0.0,
        );
        let (mut sliding, mut sticking, mut elsewhere) = (0, 0, 0);
        let mut columns: Vec<usize> = Vec::new();
        for pair in pairs.iter() {
            let touch = contact.touch(pair, &x, &v, &anchors);
            if touch.f_n > 0.0 && touch.delta.norm() > 0.0 {
                if touch.sliding {
                    sliding += 1;
                } else {
                    sticking += 1;
                }
            }
            let (vertices, _) = contact.pair_blocks(pair, &x, &v, &anchors, dv_dx);
            elsewhere += usize::from(vertices.len() > 4);
            columns.extend(vertices.iter().map(|&m| m as usize));
            // The derivatives are of the force pass's forces.
            let xs: Vec<Vec3> = vertices.iter().map(|&m| x[m as usize]).collect();
            let vs: Vec<Vec3> = vertices.iter().map(|&m| v[m as usize]).collect();
            let anchor = BodyContact::anchor_of(&anchors, pair.point as usize).map(|(t, b, c)| {
                let nodes = contact.triangles[t as usize].nodes;
                (
                    nodes.map(|n| vertices.iter().position(|&m| m == n).unwrap()),
                    b,
                    c,
                )
            });
            let k = contact.settings.stiffness * contact.stiffness_ratio[pair.point as usize];
            let tangent = crate::contact::pair_tangent::pair_tangent(
                &crate::contact::pair_tangent::PairInput {
                    x: &xs,
                    v: &vs,
                    anchor,
                    stiffness: k,
                    damping: 2.0
                        * settings.damping_ratio
                        * (k * contact.point_mass[pair.point as usize]).sqrt(),
                    dv_dx,
                    settings: &settings,
                },
            );
            assert!(
                (tangent.forces[0] - touch.force).norm() <= 1e-12 * touch.force.norm(),
                "{:?} vs {:?}",
                tangent.forces[0],
                touch.force
            );
        }
        assert!(
            sliding > 3 && sticking > 3 && elsewhere > 3,
            "{sliding} {sticking} {elsewhere}"
        );
        columns.sort_unstable();
        columns.dedup();
        let mut jac = model.tangent(&x);
        jac.blocks.iter_mut().for_each(|b| *b = Mat3::zeros());
        contact.add_jacobian(&x, &v, &anchors, dv_dx, &mut jac);
        let force = |x: &[Vec3], v: &[Vec3]| {
            let mut f = vec![Vec3::zeros(); x.len()];
            contact.add_forces(x, v, &anchors, &mut f);
            f
        };
        let rows: Vec<usize> = (0..x.len())
            .filter(|&i| force(&x, &v)[i].norm() > 0.0)
            .collect();
        let scale = jac.blocks.iter().map(|b| b.norm()).fold(0.0, f64::max);
        let eps = 1e-9;
        let mut worst = 0.0f64;
        for &j in &columns {
            for d in 0..3 {
                let shifted = |sign: f64| {
                    let (mut xs, mut vs) = (x.clone(), v.clone());
                    xs[j][d] += sign * eps;
                    vs[j][d] += sign * eps * dv_dx;
                    force(&xs, &vs)
                };
                let (fp, fm) = (shifted(1.0), shifted(-1.0));
                for &i in &rows {
                    let fd = (fp[i] - fm[i]) / (2.0 * eps);
                    let exact = jac
                        .find(i, j)
                        .map_or(Vec3::zeros(), |k| jac.blocks[k].column(d).into());
                    worst = worst.max((fd - exact).norm());
                }
            }
        }
        assert!(worst < 1e-7 * scale, "worst {worst} of {scale}");
    }
}
