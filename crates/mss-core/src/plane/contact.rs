//! Contact of a 2D body's nodes with rigid obstacles in the plane.
//!
//! Each obstacle has its own [`PlaneContactSettings`], as in 3D: a penalty
//! spring along the obstacle's normal (stiffness per node), a damper
//! beside it (a ratio of the node's critical damping, acting on the normal
//! velocity relative to the obstacle, never pulling), and Coulomb friction
//! with a static and a kinetic coefficient. Friction acts on the velocity
//! each step ends with: the impulse the static coefficient allows stops
//! the tangential motion if it can (stick), else the kinetic one slows it
//! (slide). Obstacles may move along [`Path`]s (their x and y).

use thiserror::Error;

use super::norm;
use crate::contact::Path;
use crate::{BlockCsr, Vec3};

/// A rigid obstacle in the plane: the solid a node must stay out of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlaneObstacle {
    /// The half-plane behind the line through `point` with outward `normal`
    /// (unit length).
    HalfPlane {
        /// A point of the line (m).
        point: [f64; 2],
        /// Outward unit normal.
        normal: [f64; 2],
    },
    /// A disc.
    Disc {
        /// Centre (m).
        centre: [f64; 2],
        /// Radius (m).
        radius: f64,
    },
    /// An axis-aligned rectangle.
    Rect {
        /// Lower-left corner (m).
        min: [f64; 2],
        /// Upper-right corner (m).
        max: [f64; 2],
    },
}

impl PlaneObstacle {
    /// How deep `p` lies inside (m, > 0) and the outward normal of the
    /// surface nearest to it; `None` outside.
    pub fn penetration(&self, p: [f64; 2]) -> Option<(f64, [f64; 2])> {
        self.within(p, 0.0)
    }

    /// [`PlaneObstacle::penetration`], counting points up to `margin` (m)
    /// outside too (with a negative depth).
    pub fn within(&self, p: [f64; 2], margin: f64) -> Option<(f64, [f64; 2])> {
        match *self {
            PlaneObstacle::HalfPlane { point, normal } => {
                let d = (point[0] - p[0]) * normal[0] + (point[1] - p[1]) * normal[1];
                (d > -margin).then_some((d, normal))
            }
            PlaneObstacle::Disc { centre, radius } => {
                let r = [p[0] - centre[0], p[1] - centre[1]];
                let len = norm(r);
                (len < radius + margin).then(|| {
                    let n = if len > 0.0 {
                        [r[0] / len, r[1] / len]
                    } else {
                        [0.0, 1.0]
                    };
                    (radius - len, n)
                })
            }
            PlaneObstacle::Rect { min, max } => {
                let inside = p[0] > min[0] - margin
                    && p[0] < max[0] + margin
                    && p[1] > min[1] - margin
                    && p[1] < max[1] + margin;
                inside.then(|| {
                    // Out through the nearest side.
                    [
                        (p[0] - min[0], [-1.0, 0.0]),
                        (max[0] - p[0], [1.0, 0.0]),
                        (p[1] - min[1], [0.0, -1.0]),
                        (max[1] - p[1], [0.0, 1.0]),
                    ]
                    .into_iter()
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .expect("four sides")
                })
            }
        }
    }
}

/// Contact parameters of one obstacle in the plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneContactSettings {
    /// Penalty stiffness per node (N/m).
    pub stiffness: f64,
    /// Static friction coefficient (>= 0).
    pub friction_static: f64,
    /// Kinetic friction coefficient (`0 <= mu_k <= mu_s`).
    pub friction_kinetic: f64,
    /// Damping ratio of the normal contact spring, a fraction of each
    /// node's critical damping `2 sqrt(k m)` (0: elastic contact).
    pub damping_ratio: f64,
}

impl PlaneContactSettings {
    /// Elastic contact (no damping) with one friction coefficient for
    /// sticking and sliding.
    pub fn elastic(stiffness: f64, friction: f64) -> Self {
        Self {
            stiffness,
            friction_static: friction,
            friction_kinetic: friction,
            damping_ratio: 0.0,
        }
    }

    /// Checks the ranges (those of the 3D settings, whose fields these
    /// are).
    pub fn validate(&self) -> Result<(), PlaneContactError> {
        crate::contact::ContactSettings {
            stiffness: self.stiffness,
            friction_static: self.friction_static,
            friction_kinetic: self.friction_kinetic,
            damping_ratio: self.damping_ratio,
        }
        .validate()
        .map_err(|e| PlaneContactError(e.to_string()))
    }

    /// The damping coefficient (N s/m) of a node of mass `mass`.
    fn damper(&self, mass: f64) -> f64 {
        2.0 * self.damping_ratio * (self.stiffness * mass).sqrt()
    }
}

/// Contact settings that do not fit their obstacles.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("2D contact: {0}")]
pub struct PlaneContactError(pub String);

/// Contact of a 2D body's nodes with rigid obstacles (see the module's
/// overview). Built by [`PlaneContact::new`], which checks that every
/// obstacle has its settings and at most one path.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneContact {
    obstacles: Vec<PlaneObstacle>,
    paths: Vec<Path>,
    settings: Vec<PlaneContactSettings>,
}

impl PlaneContact {
    /// The obstacles (where they are at t = 0), each obstacle's settings,
    /// and its translation in time (`paths` empty: every obstacle stays;
    /// else one path per obstacle, [`Path::fixed`] for one that stays).
    pub fn new(
        obstacles: Vec<PlaneObstacle>,
        paths: Vec<Path>,
        settings: Vec<PlaneContactSettings>,
    ) -> Result<Self, PlaneContactError> {
        if settings.len() != obstacles.len() {
            return Err(PlaneContactError(format!(
                "{} obstacles with {} settings: give one per obstacle",
                obstacles.len(),
                settings.len()
            )));
        }
        if !(paths.is_empty() || paths.len() == obstacles.len()) {
            return Err(PlaneContactError(format!(
                "{} obstacles with {} paths: give none or one per obstacle",
                obstacles.len(),
                paths.len()
            )));
        }
        for (i, s) in settings.iter().enumerate() {
            s.validate()
                .map_err(|e| PlaneContactError(format!("obstacle {}: {}", i + 1, e.0)))?;
        }
        Ok(Self {
            obstacles,
            paths,
            settings,
        })
    }

    /// The same settings for every obstacle.
    pub fn uniform(
        obstacles: Vec<PlaneObstacle>,
        paths: Vec<Path>,
        settings: PlaneContactSettings,
    ) -> Result<Self, PlaneContactError> {
        let all = vec![settings; obstacles.len()];
        Self::new(obstacles, paths, all)
    }

    /// The obstacles, where they are at t = 0.
    pub fn obstacles(&self) -> &[PlaneObstacle] {
        &self.obstacles
    }

    /// Each obstacle's settings.
    pub fn settings(&self) -> &[PlaneContactSettings] {
        &self.settings
    }

    /// Each obstacle's path (empty: all stay).
    pub fn paths(&self) -> &[Path] {
        &self.paths
    }

    /// The stiffest obstacle's penalty (N/m) and the largest damping ratio,
    /// which bound the explicit step.
    pub(super) fn stiffest(&self) -> (f64, f64) {
        self.settings.iter().fold((0.0, 0.0), |(k, z), s| {
            (f64::max(k, s.stiffness), f64::max(z, s.damping_ratio))
        })
    }

    /// Each obstacle with `p` (m) in the frame it had at t = 0, at time `t`.
    pub(super) fn placed(
        &self,
        p: [f64; 2],
        t: f64,
    ) -> impl Iterator<Item = (usize, &PlaneObstacle, [f64; 2])> {
        self.obstacles.iter().enumerate().map(move |(i, o)| {
            let d = self
                .paths
                .get(i)
                .map_or(Vec3::zeros(), |path| path.offset(t));
            (i, o, [p[0] - d.x, p[1] - d.y])
        })
    }

    /// The velocity of obstacle `i` at time `t` (m/s).
    fn velocity(&self, i: usize, t: f64) -> [f64; 2] {
        let v = self
            .paths
            .get(i)
            .map_or(Vec3::zeros(), |path| path.velocity(t));
        [v.x, v.y]
    }

    /// The normal force (N, >= 0) of obstacle `i` on a node of mass `mass`
    /// at depth `depth` along `n`, moving at `v` (`None`: at rest, as in a
    /// static solve).
    fn normal_force(
        &self,
        i: usize,
        t: f64,
        depth: f64,
        n: [f64; 2],
        v: Option<[f64; 2]>,
        mass: f64,
    ) -> f64 {
        let s = &self.settings[i];
        let spring = s.stiffness * depth;
        let Some(v) = v.filter(|_| s.damping_ratio > 0.0) else {
            return spring;
        };
        let w = self.velocity(i, t);
        let approach = (v[0] - w[0]) * n[0] + (v[1] - w[1]) * n[1];
        (spring - s.damper(mass) * approach).max(0.0)
    }

    /// The contact force (N) on a node of mass `mass` at `p`, moving at `v`
    /// (`None`: at rest), at time `t`.
    pub(super) fn force(&self, p: [f64; 2], v: Option<[f64; 2]>, mass: f64, t: f64) -> [f64; 2] {
        let mut f = [0.0; 2];
        for (i, o, q) in self.placed(p, t) {
            if let Some((depth, n)) = o.penetration(q) {
                let f_n = self.normal_force(i, t, depth, n, v, mass);
                f[0] += f_n * n[0];
                f[1] += f_n * n[1];
            }
        }
        f
    }

    /// Adds the contact's tangent at node `i` (at `p`, mass `mass`) to
    /// `j`, the Jacobian of the forces: the penalty's along each touching
    /// normal (exact for lines; a disc's turning normal is left out), and,
    /// in an implicit step of `dt` where the node moves at
    /// `v = (x - x0) / dt`, the damper's through that velocity (none where
    /// the damper has cancelled the spring: the force is zero there).
    /// Nodes within `margin` of touching count too: a body that rests on
    /// an obstacle at its start is held by it from the first Newton step.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn add_tangent(
        &self,
        j: &mut BlockCsr,
        i: usize,
        p: [f64; 2],
        moving: Option<([f64; 2], f64)>,
        mass: f64,
        t: f64,
        margin: f64,
    ) {
        for (o_index, o, q) in self.placed(p, t) {
            if let Some((depth, n)) = o.within(q, margin) {
                let s = &self.settings[o_index];
                let k = match moving {
                    Some((v, dt)) if depth > 0.0 && s.damping_ratio > 0.0 => {
                        if self.normal_force(o_index, t, depth, n, Some(v), mass) > 0.0 {
                            s.stiffness + s.damper(mass) / dt
                        } else {
                            0.0
                        }
                    }
                    _ => s.stiffness,
                };
                let b = j.find(i, i).expect("the diagonal is in the pattern");
                for e in 0..2 {
                    for d in 0..2 {
                        j.blocks[b][(e, d)] -= k * n[e] * n[d];
                    }
                }
            }
        }
    }

    /// Coulomb friction on a touching node's velocity `v` (its mass
    /// `mass`, over a step `dt`): the impulse `mu_s f_n dt` stops its
    /// tangential motion relative to the obstacle if it can (stick), else
    /// `mu_k f_n dt` slows it (slide). The normal force is the one the
    /// node's position and velocity give.
    pub(super) fn apply_friction(&self, t: f64, x: Vec3, v: &mut Vec3, mass: f64, dt: f64) {
        for (i, o, q) in self.placed([x.x, x.y], t) {
            let s = &self.settings[i];
            if s.friction_static == 0.0 {
                continue;
            }
            if let Some((depth, n)) = o.penetration(q) {
                let f_n = self.normal_force(i, t, depth, n, Some([v.x, v.y]), mass);
                let w = self.velocity(i, t);
                let r = [v.x - w[0], v.y - w[1]];
                let vn = r[0] * n[0] + r[1] * n[1];
                let vt = [r[0] - vn * n[0], r[1] - vn * n[1]];
                let speed = norm(vt);
                let impulse_per_mass = f_n * dt / mass;
                let scale = if speed <= s.friction_static * impulse_per_mass {
                    1.0
                } else {
                    s.friction_kinetic * impulse_per_mass / speed
                };
                v.x -= scale * vt[0];
                v.y -= scale * vt[1];
            }
        }
    }
}
