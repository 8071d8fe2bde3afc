//! The per-cell force kernel, written once over a scalar type so that the same
//! code gives forces (`f64`) and their exact derivatives (forward-mode duals).

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use hexmesh::{CELL_DIAGONALS, CELL_EDGES, CORNER_OFFSETS};

/// The arithmetic the kernel needs.
pub(crate) trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    fn cst(v: f64) -> Self;
    fn scale(self, k: f64) -> Self;
    fn sqrt(self) -> Self;
    /// `f(self)`, given `f` and its derivative at a value: `(f(v), f'(v))`.
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self;
}

impl Scalar for f64 {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        self * k
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        f(self).0
    }
}

/// Forward-mode dual number with `N` directional derivatives.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dual<const N: usize> {
    pub v: f64,
    pub g: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// The variable number `i` (derivative 1 along direction `i`).
    pub fn var(v: f64, i: usize) -> Self {
        let mut g = [0.0; N];
        g[i] = 1.0;
        Self { v, g }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self {
            v: self.v + o.v,
            g: std::array::from_fn(|i| self.g[i] + o.g[i]),
        }
    }
}
impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self {
            v: self.v - o.v,
            g: std::array::from_fn(|i| self.g[i] - o.g[i]),
        }
    }
}
// The product rule: the derivative of a product is a sum.
#[allow(clippy::suspicious_arithmetic_impl)]
impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Self {
            v: self.v * o.v,
            g: std::array::from_fn(|i| self.g[i] * o.v + o.g[i] * self.v),
        }
    }
}
impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let v = self.v / o.v;
        let inv = 1.0 / o.v;
        Self {
            v,
            g: std::array::from_fn(|i| (self.g[i] - v * o.g[i]) * inv),
        }
    }
}
impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self {
            v: -self.v,
            g: self.g.map(|x| -x),
        }
    }
}
impl<const N: usize> AddAssign for Dual<N> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<const N: usize> SubAssign for Dual<N> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}
impl<const N: usize> Scalar for Dual<N> {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Self { v, g: [0.0; N] }
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        Self {
            v: self.v * k,
            g: self.g.map(|x| x * k),
        }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let d = 0.5 / s;
        Self {
            v: s,
            g: self.g.map(|x| x * d),
        }
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        let (v, d) = f(self.v);
        Self {
            v,
            g: self.g.map(|x| x * d),
        }
    }
}

/// Correction-force constants of one cell (docs/model.md steps 4-5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Correction {
    /// `c` of docs/model.md step 4.
    pub c: f64,
    /// Inverse of `(1 + c) I - c J`.
    pub minv: [[f64; 3]; 3],
}

impl Correction {
    /// `None` when the 3x3 system is singular (nu = 0.5 or nu = -0.25).
    pub fn new(c: f64) -> Option<Self> {
        // (a I + b J)^-1 = (I - b / (a + 3 b) J) / a with a = 1 + c, b = -c.
        let a = 1.0 + c;
        let b = -c;
        let d = a + 3.0 * b;
        if a.abs() < 1e-12 || d.abs() < 1e-12 {
            return None;
        }
        let minv =
            std::array::from_fn(|i| std::array::from_fn(|j| ((i == j) as u8 as f64 - b / d) / a));
        Some(Self { c, minv })
    }
}

/// Constants of one cell for the kernel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CellParams {
    pub k_edge: f64,
    pub k_diag: f64,
    pub rest_edge: f64,
    pub rest_diag: f64,
    pub correction: Option<Correction>,
    /// `lambda h^3` of the volumetric energy (0 for none).
    pub vol_lambda_h3: f64,
    /// The volumetric energy's law: `(ln J)^2 / 2` (a barrier) instead of
    /// `(J - 1)^2 / 2`.
    pub vol_barrier: bool,
    /// `1 / (4 h)`: magnitude of the shape-function gradients at the centre.
    pub grad_scale: f64,
    /// Stiffness of the hourglass control on the lattice's three mechanisms
    /// (N/m per unit hourglass amplitude; 0 for none).
    pub k_hourglass: f64,
}

pub(crate) type V3<T> = [T; 3];

#[inline(always)]
fn sub<T: Scalar>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline(always)]
fn dot<T: Scalar>(a: V3<T>, b: V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline(always)]
fn cross<T: Scalar>(a: V3<T>, b: V3<T>) -> V3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline(always)]
fn add_to<T: Scalar>(acc: &mut V3<T>, v: V3<T>) {
    acc[0] += v[0];
    acc[1] += v[1];
    acc[2] += v[2];
}
#[inline(always)]
fn sub_from<T: Scalar>(acc: &mut V3<T>, v: V3<T>) {
    acc[0] -= v[0];
    acc[1] -= v[1];
    acc[2] -= v[2];
}
#[inline(always)]
fn mul_s<T: Scalar>(v: V3<T>, s: T) -> V3<T> {
    [v[0] * s, v[1] * s, v[2] * s]
}

#[inline(always)]
fn spring<T: Scalar>(k: f64, rest: f64, d: V3<T>, a: usize, b: usize, f: &mut [V3<T>; 8]) {
    let l = dot(d, d).sqrt();
    // k (l - L0) / l, the force on a per unit of d.
    let s = (T::cst(1.0) - T::cst(rest) / l).scale(k);
    let fd = mul_s(d, s);
    add_to(&mut f[a], fd);
    sub_from(&mut f[b], fd);
}

/// The part of the cell's forces that is not the springs' (corrections and
/// volumetric), given the springs' forces already in `f`.
#[inline(always)]
fn finish_cell<T: Scalar>(
    p: &CellParams,
    x: &[V3<T>; 8],
    axis_sum: [V3<T>; 3],
    f: &mut [V3<T>; 8],
) {
    // The current axes serve both the corrections and the hourglass control.
    let axes = (p.correction.is_some() || p.k_hourglass != 0.0).then(|| cell_axes(&axis_sum));
    if let (Some(corr), Some((axes, _))) = (&p.correction, &axes) {
        // T_i = 1/2 sum_n s_i(n) (f_n . a_i) = 1/2 a_i . sum_n s_i(n) f_n, with
        // s_i = +1 on the -i face and -1 on the +i face.
        // Loops rather than `array::from_fn` throughout the kernel: the
        // closures would be functions of their own, not inlined into the
        // AVX2 entry point.
        let mut t = [T::cst(0.0); 3];
        for (i, ti) in t.iter_mut().enumerate() {
            let mut acc = [T::cst(0.0); 3];
            for (n, fn_) in f.iter().enumerate() {
                if CORNER_OFFSETS[n][i] == 0 {
                    add_to(&mut acc, *fn_);
                } else {
                    sub_from(&mut acc, *fn_);
                }
            }
            *ti = dot(acc, axes[i]).scale(0.5);
        }
        let m = &corr.minv;
        let mut nf = [T::cst(0.0); 3];
        for (i, ni) in nf.iter_mut().enumerate() {
            *ni = t[0].scale(m[i][0]) + t[1].scale(m[i][1]) + t[2].scale(m[i][2]);
        }
        let sum = nf[0] + nf[1] + nf[2];
        // Node on the +j face gets -(c/4) (sum_{i != j} N_i) a_j, on the -j face the opposite.
        let q = -corr.c / 4.0;
        let mut g = [[T::cst(0.0); 3]; 3];
        for (j, gj) in g.iter_mut().enumerate() {
            *gj = mul_s(axes[j], (sum - nf[j]).scale(q));
        }
        for (n, fn_) in f.iter_mut().enumerate() {
            for j in 0..3 {
                if CORNER_OFFSETS[n][j] == 1 {
                    add_to(fn_, g[j]);
                } else {
                    sub_from(fn_, g[j]);
                }
            }
        }
    }
    if p.vol_lambda_h3 != 0.0 {
        let (fcols, jac) = deformation_gradient(x, p.grad_scale);
        let cof = [
            cross(fcols[1], fcols[2]),
            cross(fcols[2], fcols[0]),
            cross(fcols[0], fcols[1]),
        ];
        let slope = if p.vol_barrier {
            jac.apply(barrier_slope)
        } else {
            jac - T::cst(1.0)
        };
        let coef = slope.scale(-p.vol_lambda_h3 * p.grad_scale);
        let cs = [
            mul_s(cof[0], coef),
            mul_s(cof[1], coef),
            mul_s(cof[2], coef),
        ];
        for (n, fn_) in f.iter_mut().enumerate() {
            for (j, c) in cs.iter().enumerate() {
                if CORNER_OFFSETS[n][j] == 1 {
                    add_to(fn_, *c);
                } else {
                    sub_from(fn_, *c);
                }
            }
        }
    }
    if let (true, Some((axes, inv_len))) = (p.k_hourglass != 0.0, &axes) {
        add_hourglass_forces(p.k_hourglass, x, axes, inv_len, f);
    }
}

/// Below this volume ratio the barrier law continues with a constant
/// curvature instead of `(ln J)^2 / 2`, so that the energy, its forces and
/// their derivatives stay finite through `J <= 0` (an explicit step may still
/// land there: the force that pushes the cell back is then very large instead
/// of undefined).
pub(crate) const BARRIER_KNEE: f64 = 0.1;

/// The barrier law `phi(J) = (ln J)^2 / 2` (docs/model.md, the volumetric
/// variants), with the quadratic continuation below [`BARRIER_KNEE`].
pub(crate) fn barrier_energy(j: f64) -> f64 {
    if j >= BARRIER_KNEE {
        0.5 * j.ln().powi(2)
    } else {
        let (s, c) = barrier_slope(BARRIER_KNEE);
        let d = j - BARRIER_KNEE;
        0.5 * BARRIER_KNEE.ln().powi(2) + s * d + 0.5 * c * d * d
    }
}

/// How much the volumetric term's stiffness has grown at `x` relative to
/// rest: `phi''(J) |cof F|^2 / 3 + |phi'(J)| |F| / sqrt(3)` (1 at rest), from
/// the two parts of its Hessian, `phi'' b b^T` with `b = dJ/dx` (of size
/// `|cof F| |grad N|`) and `phi' d b/dx` (of size `|F| |grad N|^2`).
pub(crate) fn volumetric_growth(p: &CellParams, x: &[V3<f64>; 8]) -> f64 {
    let (cols, jac) = deformation_gradient(x, p.grad_scale);
    let (slope, curvature) = if p.vol_barrier {
        barrier_slope(jac)
    } else {
        (jac - 1.0, 1.0)
    };
    let cof2: f64 = (0..3)
        .map(|j| {
            let c = cross(cols[(j + 1) % 3], cols[(j + 2) % 3]);
            dot(c, c)
        })
        .sum();
    let f2: f64 = cols.iter().map(|c| dot(*c, *c)).sum();
    curvature * cof2 / 3.0 + slope.abs() * (f2 / 3.0).sqrt()
}

/// Largest Gershgorin row sum of a cell's 24x24 Jacobian.
pub(crate) fn gershgorin(jac: &[[f64; 24]; 24]) -> f64 {
    jac.iter()
        .map(|row| row.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// `phi'(J)` and `phi''(J)` of [`barrier_energy`].
fn barrier_slope(j: f64) -> (f64, f64) {
    if j >= BARRIER_KNEE {
        let l = j.ln();
        (l / j, (1.0 - l) / (j * j))
    } else {
        let l = BARRIER_KNEE.ln();
        let c = (1.0 - l) / (BARRIER_KNEE * BARRIER_KNEE);
        (l / BARRIER_KNEE + c * (j - BARRIER_KNEE), c)
    }
}

/// Sign `+1` / `-1` of corner `n` along axis `j`.
#[inline(always)]
pub(crate) fn corner_sign(n: usize, j: usize) -> f64 {
    if CORNER_OFFSETS[n][j] == 1 { 1.0 } else { -1.0 }
}

/// The hourglass vector of the mechanism along axis `i`: the corner pattern
/// `s_j s_k` (the product of the signs along the two other axes). Displacing
/// every corner along `i` by `s_j s_k` stretches none of the 16 springs (their
/// ends always have equal `s_j s_k`), so the springs and the corrections, which
/// are built from the springs' forces, give it no stiffness.
#[inline(always)]
fn hourglass_sign(n: usize, i: usize) -> f64 {
    corner_sign(n, (i + 1) % 3) * corner_sign(n, (i + 2) % 3)
}

/// The current cell axes `a_i` (normalized `axis_sum[i]`, docs/model.md step 2)
/// and `1 / |axis_sum[i]|`.
#[inline(always)]
fn cell_axes<T: Scalar>(axis_sum: &[V3<T>; 3]) -> ([V3<T>; 3], [T; 3]) {
    let mut inv = [T::cst(0.0); 3];
    let mut axes = [[T::cst(0.0); 3]; 3];
    for i in 0..3 {
        inv[i] = T::cst(1.0) / dot(axis_sum[i], axis_sum[i]).sqrt();
        axes[i] = mul_s(axis_sum[i], inv[i]);
    }
    (axes, inv)
}

/// The hourglass vectors `g_i = 1/8 sum_n s_j s_k(n) x_n` and amplitudes
/// `q_i = a_i . g_i` of the cell along its current axes `a_i`. `g_i` vanishes
/// for every affine motion and rotates with the cell, so `q_i` is zero for any
/// homogeneous strain (tension results stay exact) and invariant under rigid
/// motions.
#[inline(always)]
fn hourglass_amplitudes<T: Scalar>(x: &[V3<T>; 8], axes: &[V3<T>; 3]) -> ([V3<T>; 3], [T; 3]) {
    let mut g = [[T::cst(0.0); 3]; 3];
    let mut q = [T::cst(0.0); 3];
    for i in 0..3 {
        let mut gi = [T::cst(0.0); 3];
        for (n, xn) in x.iter().enumerate() {
            if hourglass_sign(n, i) > 0.0 {
                add_to(&mut gi, *xn);
            } else {
                sub_from(&mut gi, *xn);
            }
        }
        g[i] = [gi[0].scale(0.125), gi[1].scale(0.125), gi[2].scale(0.125)];
        q[i] = dot(axes[i], g[i]);
    }
    (g, q)
}

/// Forces of the hourglass energy `W = k/2 sum_i q_i^2`, `f_n = -dW/dx_n`,
/// including the derivative of the current axis (so the forces are exactly
/// conservative): `dq_i/dx_n = s_j s_k(n) / 8 a_i + s_i(n) (g_i - q_i a_i) / |m_i|`.
#[inline(always)]
fn add_hourglass_forces<T: Scalar>(
    k: f64,
    x: &[V3<T>; 8],
    axes: &[V3<T>; 3],
    inv_len: &[T; 3],
    f: &mut [V3<T>; 8],
) {
    let (g, q) = hourglass_amplitudes(x, axes);
    for i in 0..3 {
        let kq = q[i].scale(-k);
        let along = mul_s(axes[i], kq.scale(0.125));
        let tilt = mul_s(sub(g[i], mul_s(axes[i], q[i])), kq * inv_len[i]);
        // Each corner gets +-along (its hourglass sign) +- tilt (its side
        // along i): two sums cover the four combinations.
        let same = [along[0] + tilt[0], along[1] + tilt[1], along[2] + tilt[2]];
        let opposite = sub(along, tilt);
        for (n, fn_) in f.iter_mut().enumerate() {
            let plus_side = CORNER_OFFSETS[n][i] == 1;
            match (hourglass_sign(n, i) > 0.0, plus_side) {
                (true, true) => add_to(fn_, same),
                (false, false) => sub_from(fn_, same),
                (true, false) => add_to(fn_, opposite),
                (false, true) => sub_from(fn_, opposite),
            }
        }
    }
}

/// Columns of F = sum_a x_a (grad N_a)^T at the cell centre, and det F.
#[inline(always)]
pub(crate) fn deformation_gradient<T: Scalar>(x: &[V3<T>; 8], grad_scale: f64) -> ([V3<T>; 3], T) {
    let mut cols = [[T::cst(0.0); 3]; 3];
    for (n, xn) in x.iter().enumerate() {
        for (j, col) in cols.iter_mut().enumerate() {
            if CORNER_OFFSETS[n][j] == 1 {
                add_to(col, *xn);
            } else {
                sub_from(col, *xn);
            }
        }
    }
    for col in &mut cols {
        for v in col.iter_mut() {
            *v = v.scale(grad_scale);
        }
    }
    let jac = dot(cols[0], cross(cols[1], cols[2]));
    (cols, jac)
}

/// Internal forces of one cell on its 8 corners (springs, corrections,
/// volumetric term), the reference implementation.
#[inline(always)]
pub(crate) fn cell_forces<T: Scalar>(p: &CellParams, x: &[V3<T>; 8], f: &mut [V3<T>; 8]) {
    *f = [[T::cst(0.0); 3]; 8];
    let mut axis_sum = [[T::cst(0.0); 3]; 3];
    for &(a, b, ax) in &CELL_EDGES {
        let d = sub(x[b], x[a]);
        add_to(&mut axis_sum[ax], d);
        spring(p.k_edge, p.rest_edge, d, a, b, f);
    }
    for &(a, b) in &CELL_DIAGONALS {
        let d = sub(x[b], x[a]);
        spring(p.k_diag, p.rest_diag, d, a, b, f);
    }
    finish_cell(p, x, axis_sum, f);
}

/// Potential energy of the cell's springs, volumetric term and hourglass
/// control (J).
pub(crate) fn cell_energy(p: &CellParams, x: &[V3<f64>; 8]) -> f64 {
    let mut e = 0.0;
    for &(a, b, _) in &CELL_EDGES {
        let l = dot(sub(x[b], x[a]), sub(x[b], x[a])).sqrt();
        e += 0.5 * p.k_edge * (l - p.rest_edge).powi(2);
    }
    for &(a, b) in &CELL_DIAGONALS {
        let l = dot(sub(x[b], x[a]), sub(x[b], x[a])).sqrt();
        e += 0.5 * p.k_diag * (l - p.rest_diag).powi(2);
    }
    if p.vol_lambda_h3 != 0.0 {
        let (_, jac) = deformation_gradient(x, p.grad_scale);
        e += p.vol_lambda_h3
            * if p.vol_barrier {
                barrier_energy(jac)
            } else {
                0.5 * (jac - 1.0).powi(2)
            };
    }
    if p.k_hourglass != 0.0 {
        let mut axis_sum = [[0.0; 3]; 3];
        for &(a, b, ax) in &CELL_EDGES {
            add_to(&mut axis_sum[ax], sub(x[b], x[a]));
        }
        let (axes, _) = cell_axes(&axis_sum);
        let (_, q) = hourglass_amplitudes(x, &axes);
        e += 0.5 * p.k_hourglass * dot(q, q);
    }
    e
}

/// The exact 24x24 Jacobian d f / d x of one cell: `jac[3 b + e][3 a + d]` is
/// d f_{b,e} / d x_{a,d}.
pub(crate) fn cell_jacobian(p: &CellParams, x: &[V3<f64>; 8]) -> [[f64; 24]; 24] {
    let xd: [V3<Dual<24>>; 8] =
        std::array::from_fn(|a| std::array::from_fn(|d| Dual::var(x[a][d], 3 * a + d)));
    let mut f = [[Dual::<24>::cst(0.0); 3]; 8];
    cell_forces(p, &xd, &mut f);
    std::array::from_fn(|r| f[r / 3][r % 3].g)
}

/// `L` independent `f64` lanes: the kernel evaluated on `L` cells at once, so
/// that the compiler emits SIMD (sqrt and division dominate the cost). Every
/// lane performs exactly the scalar operations, so results are bitwise equal
/// to the `f64` kernel.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lanes<const L: usize>(pub [f64; L]);

macro_rules! lanes_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const L: usize> $tr for Lanes<L> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                // Plain loops, not `array::from_fn`/`map`: their closures are
                // separate functions that the AVX2 entry point does not
                // inline, which costs calls and copies per operation.
                let mut r = [0.0; L];
                for ((r, a), b) in r.iter_mut().zip(self.0).zip(o.0) {
                    *r = a $op b;
                }
                Self(r)
            }
        }
    };
}
lanes_op!(Add, add, +);
lanes_op!(Sub, sub, -);
lanes_op!(Mul, mul, *);
lanes_op!(Div, div, /);

impl<const L: usize> Neg for Lanes<L> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        let mut r = self.0;
        for v in &mut r {
            *v = -*v;
        }
        Self(r)
    }
}
impl<const L: usize> AddAssign for Lanes<L> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<const L: usize> SubAssign for Lanes<L> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}
impl<const L: usize> Scalar for Lanes<L> {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Self([v; L])
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        let mut r = self.0;
        for v in &mut r {
            *v *= k;
        }
        Self(r)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let mut r = self.0;
        for v in &mut r {
            *v = v.sqrt();
        }
        Self(r)
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        let mut r = self.0;
        for v in &mut r {
            *v = f(*v).0;
        }
        Self(r)
    }
}

/// Cells evaluated together by [`forces_batch`] with AVX2.
pub(crate) const LANES: usize = 4;

/// Forces of consecutive cells `cells` (all with parameters `p`) at positions
/// `x`, into `out` (8 corner forces per cell), `L` cells per pass.
#[inline(always)]
fn forces_batch_body<const L: usize>(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    let groups = cells.len() / L;
    for (cg, og) in cells.chunks_exact(L).zip(out.chunks_exact_mut(8 * L)) {
        let mut xl: [V3<Lanes<L>>; 8] = [[Lanes::cst(0.0); 3]; 8];
        for (k, xk) in xl.iter_mut().enumerate() {
            for (l, cell) in cg.iter().enumerate() {
                let p = x[cell[k] as usize];
                xk[0].0[l] = p[0];
                xk[1].0[l] = p[1];
                xk[2].0[l] = p[2];
            }
        }
        let mut f = [[Lanes::cst(0.0); 3]; 8];
        cell_forces(p, &xl, &mut f);
        for l in 0..L {
            for k in 0..8 {
                og[8 * l + k] = [f[k][0].0[l], f[k][1].0[l], f[k][2].0[l]];
            }
        }
    }
    for (c, o) in cells[groups * L..]
        .iter()
        .zip(out[8 * groups * L..].chunks_exact_mut(8))
    {
        let xc: [V3<f64>; 8] = std::array::from_fn(|k| x[c[k] as usize]);
        let mut f = [[0.0; 3]; 8];
        cell_forces(p, &xc, &mut f);
        o.copy_from_slice(&f);
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn forces_batch_avx2(p: &CellParams, cells: &[[u32; 8]], x: &[[f64; 3]], out: &mut [[f64; 3]]) {
    forces_batch_body::<LANES>(p, cells, x, out);
}

/// Forces of consecutive cells sharing the parameters `p`, several cells per
/// SIMD pass (AVX2 when the CPU has it; never FMA, so results do not depend on
/// the path taken).
pub(crate) fn forces_batch(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { forces_batch_avx2(p, cells, x, out) };
            return;
        }
    }
    forces_batch_body::<LANES>(p, cells, x, out);
}
