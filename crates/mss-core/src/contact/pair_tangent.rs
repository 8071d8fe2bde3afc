//! The exact derivative of one touch between bodies: the point's force and
//! its reactions on the touched triangle's corners, differentiated in
//! forward mode with respect to every position they depend on.
//!
//! The force of a touch ([`super::bodies`]) is `n f_n + friction` on the
//! point and minus `beta_j` times it on corner `j`, where the normal `n`
//! turns with the triangle, the weights `beta` slide with the point's
//! projection (or its closest point on an edge, at a rim), the normal force
//! follows the depth and the normal velocity, and the friction anchor is a
//! material point of a triangle that may be another than the touched one.
//! A closed form of all that is long and easy to get wrong; the same
//! formulas evaluated on dual numbers ([`Dual`]) give the derivative of
//! exactly the force computed, kinks aside (where stick turns to slip, a
//! closest point reaches a corner, or the damping's cap starts, the
//! derivative of the side the value is on). It costs a few thousand flops
//! per touching point per tangent, against a force pass per Newton
//! iteration: nothing.
//!
//! Velocities follow positions by the scalar `dv_dx` (an implicit step's
//! `v = (x - x_0) / dt`-like update: `dv/dx = dv_dx I`), so the damping's
//! derivative comes with the stiffness's.

use super::{ContactSettings, coulomb, normal_force};
use crate::model::kernel::{Dual, Scalar};
use crate::{Mat3, Vec3};

/// Positions the force of a touch may depend on: the point, the touched
/// triangle's three corners, and the anchor triangle's three corners.
pub(super) const MAX_SLOTS: usize = 7;

type D = Dual<{ 3 * MAX_SLOTS }>;
type DVec = [D; 3];

/// One touch, with its positions gathered in slots: slot 0 is the point,
/// slots 1 to 3 the touched triangle's corners, and the anchor triangle's
/// corners are slots named by `anchor` (any of them, repeats allowed).
pub(super) struct PairInput<'a> {
    /// Positions of the slots (m).
    pub x: &'a [Vec3],
    /// Velocities of the slots (m/s).
    pub v: &'a [Vec3],
    /// The anchor's triangle (three slots) and its coordinates
    /// `(beta_b, beta_c)` on it.
    pub anchor: Option<([usize; 3], f64, f64)>,
    /// The point's contact stiffness (N/m).
    pub stiffness: f64,
    /// The point's contact damping (N s/m).
    pub damping: f64,
    /// How velocities follow positions (1/s).
    pub dv_dx: f64,
    /// Friction coefficients.
    pub settings: &'a ContactSettings,
}

/// The forces of a touch on its point and its triangle's three corners,
/// and their derivatives: `blocks[r * slots + s]` is `d(force r)/d(x_s)`.
pub(super) struct PairTangent {
    /// Forces on the point and the corners (N): those the derivatives are
    /// of (the tests compare them with the force pass's).
    #[cfg_attr(not(test), allow(dead_code))]
    pub forces: [Vec3; 4],
    /// Row-major blocks, 4 rows by as many columns as slots.
    pub blocks: Vec<Mat3>,
}

fn sub(a: DVec, b: DVec) -> DVec {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: DVec, b: DVec) -> DVec {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn times(a: DVec, s: D) -> DVec {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn dot(a: DVec, b: DVec) -> D {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: DVec, b: DVec) -> DVec {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn value(a: DVec) -> Vec3 {
    Vec3::new(a[0].v, a[1].v, a[2].v)
}

/// The barycentric weights of the point's closest point on the triangle
/// `t`, as `Geometry::closest` picks it: the projection where it falls
/// inside, else the nearest point of the edge it lies beyond (of the
/// nearer of two it lies beyond).
fn closest_weights(p: DVec, t: [DVec; 3], normal: DVec, area2: D) -> [D; 3] {
    let (e1, e2) = (sub(t[1], t[0]), sub(t[2], t[0]));
    let w = sub(p, t[0]);
    let to_b = times(cross(e2, normal), D::cst(1.0) / area2);
    let to_c = times(cross(normal, e1), D::cst(1.0) / area2);
    let (beta_b, beta_c) = (dot(w, to_b), dot(w, to_c));
    let beta = [D::cst(1.0) - beta_b - beta_c, beta_b, beta_c];
    if beta.iter().all(|b| b.v >= 0.0) {
        return beta;
    }
    let edge = |i: usize, j: usize| {
        let e = sub(t[j], t[i]);
        let s = dot(sub(p, t[i]), e) / dot(e, e);
        // A clamped parameter is a constant: the closest point stays at
        // the corner while the point moves a little.
        let s = if s.v < 0.0 {
            D::cst(0.0)
        } else if s.v > 1.0 {
            D::cst(1.0)
        } else {
            s
        };
        let mut weights = [D::cst(0.0); 3];
        weights[i] = D::cst(1.0) - s;
        weights[j] = s;
        let distance2 = value(sub(p, add(t[i], times(e, s)))).norm_squared();
        (distance2, weights)
    };
    let nearer = |a: (f64, [D; 3]), b: (f64, [D; 3])| if b.0 < a.0 { b } else { a };
    let (_, weights) = match beta.map(|b| b.v < 0.0) {
        [true, false, false] => edge(1, 2),
        [false, true, false] => edge(2, 0),
        [false, false, true] => edge(0, 1),
        [false, true, true] => nearer(edge(0, 1), edge(2, 0)),
        [true, false, true] => nearer(edge(0, 1), edge(1, 2)),
        [true, true, false] => nearer(edge(1, 2), edge(2, 0)),
        _ => (f64::NAN, [D::cst(f64::NAN); 3]),
    };
    weights
}

/// The forces of the touch `input` describes and their exact derivatives,
/// for a point behind the touched triangle's plane (positive depth).
pub(super) fn pair_tangent(input: &PairInput<'_>) -> PairTangent {
    let slots = input.x.len();
    debug_assert!((4..=MAX_SLOTS).contains(&slots) && input.v.len() == slots);
    let x: Vec<DVec> = (0..slots)
        .map(|s| std::array::from_fn(|d| D::var(input.x[s][d], 3 * s + d)))
        .collect();
    let v: Vec<DVec> = (0..slots)
        .map(|s| {
            std::array::from_fn(|d| {
                let mut g = [0.0; 3 * MAX_SLOTS];
                g[3 * s + d] = input.dv_dx;
                D {
                    v: input.v[s][d],
                    g,
                }
            })
        })
        .collect();
    let (p, corners) = (x[0], [x[1], x[2], x[3]]);
    let normal_raw = cross(sub(corners[1], corners[0]), sub(corners[2], corners[0]));
    let area2 = dot(normal_raw, normal_raw).sqrt();
    let n = times(normal_raw, D::cst(1.0) / area2);
    let depth = -dot(n, sub(p, corners[0]));
    let beta = closest_weights(p, corners, n, area2);
    let v_face = (0..3).fold([D::cst(0.0); 3], |acc, j| {
        add(acc, times(v[1 + j], beta[j]))
    });
    let v_n = dot(sub(v[0], v_face), n);
    let (k, c) = (input.stiffness, input.damping);
    let (f_value, df_ddepth, df_dvn) = normal_force(k, c, depth.v, v_n.v);
    let mut f_n = depth.scale(df_ddepth) + v_n.scale(df_dvn);
    f_n.v = f_value;
    let mut force = times(n, f_n);
    if let Some((tri, beta_b, beta_c)) = input.anchor {
        let [a, b, c_] = tri.map(|s| x[s]);
        let at = add(
            a,
            add(
                times(sub(b, a), D::cst(beta_b)),
                times(sub(c_, a), D::cst(beta_c)),
            ),
        );
        let offset = sub(p, at);
        let delta = sub(offset, times(n, dot(offset, n)));
        // Stick or slip as the force decided it, from the values.
        let (_, sliding) = coulomb(value(delta), k, f_value, input.settings);
        let friction = if !sliding {
            times(delta, D::cst(-k))
        } else {
            let len = dot(delta, delta).sqrt();
            if len.v > 0.0 {
                times(delta, -(f_n.scale(input.settings.friction_kinetic)) / len)
            } else {
                [D::cst(0.0); 3]
            }
        };
        force = add(force, friction);
    }
    let rows: [DVec; 4] = [
        force,
        times(force, -beta[0]),
        times(force, -beta[1]),
        times(force, -beta[2]),
    ];
    let mut blocks = vec![Mat3::zeros(); 4 * slots];
    for (r, row) in rows.iter().enumerate() {
        for s in 0..slots {
            let block = &mut blocks[r * slots + s];
            for d in 0..3 {
                for e in 0..3 {
                    block[(d, e)] = row[d].g[3 * s + e];
                }
            }
        }
    }
    PairTangent {
        forces: rows.map(value),
        blocks,
    }
}
