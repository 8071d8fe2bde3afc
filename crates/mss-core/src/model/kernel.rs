//! The per-cell force kernel, written once over a scalar type so that the same
//! code gives forces (`f64`), forces of several cells at once (SIMD lanes)
//! and, in the tests, exact derivatives (forward-mode duals) against which
//! the closed-form cell Jacobian is checked.

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use hexmesh::{CELL_DIAGONALS, CELL_EDGES, CORNER_OFFSETS};

mod count;

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
    /// The barrier law's slope `phi'(J)` ([`barrier_slope`]); the number
    /// types of the force pass override it with [`fast_barrier_slope`],
    /// which needs no call per value.
    #[inline(always)]
    fn barrier_slope(self) -> Self {
        self.apply(barrier_slope)
    }
    /// `o` where `o > self`, else `self` (so a NaN `self` stays NaN), like
    /// the AVX `max` with `o` first.
    fn at_least(self, o: Self) -> Self;
    /// Whether any value held (any lane) is below `v`: the corner barrier
    /// is evaluated only for groups of cells where one corner needs it.
    fn any_below(self, v: f64) -> bool;
}

/// What [`fast_ln`] needs of a number type beyond arithmetic.
pub(crate) trait SplitExponent: Scalar {
    /// `(m, k)` with `self = m 2^k`, `m` in `[sqrt(1/2), sqrt(2))` and `k`
    /// an integer, for positive normal finite `self`.
    fn split_exponent(self) -> (Self, Self);
}

// The coefficients of the minimax polynomial of fdlibm's `log` (e_log.c):
// `R(z) ~ 2 atanh(s) / s - 2` with `z = s^2`, and ln 2 split in two so that
// `k ln2_hi` is exact.
const LN2_HI: f64 = 0.6931471803691238;
const LN2_LO: f64 = 1.9082149292705877e-10;
const LG1: f64 = 0.6666666666666735;
const LG2: f64 = 0.3999999999940942;
const LG3: f64 = 0.2857142874366239;
const LG4: f64 = 0.22222198432149784;
const LG5: f64 = 0.1818357216161805;
const LG6: f64 = 0.15313837699209373;
const LG7: f64 = 0.14798198605116586;

/// Natural logarithm of a positive normal finite value in plain arithmetic
/// (within an ulp of libm's in `f64`), so that SIMD lanes compute it
/// without a call per lane and every number type gets the same bits: the
/// argument is split as `m 2^k`, and `ln(m) = 2 atanh(s)` with
/// `s = (m - 1) / (m + 1)` from fdlibm's polynomial.
#[inline(always)]
pub(crate) fn fast_ln<T: SplitExponent>(x: T) -> T {
    let (m, k) = x.split_exponent();
    // Exact: m is within a factor 2 of 1 (Sterbenz).
    let f = m - T::cst(1.0);
    let s = f / (T::cst(2.0) + f);
    let z = s * s;
    let w = z * z;
    let odd = w * (T::cst(LG2) + w * (T::cst(LG4) + w * T::cst(LG6)));
    let even = z * (T::cst(LG1) + w * (T::cst(LG3) + w * (T::cst(LG5) + w * T::cst(LG7))));
    let r = even + odd;
    let hfsq = T::cst(0.5) * f * f;
    k * T::cst(LN2_HI) - ((hfsq - (s * (hfsq + r) + k * T::cst(LN2_LO))) - f)
}

/// [`barrier_slope`]'s value with [`fast_ln`]: `ln J / J` above the knee,
/// the straight continuation below it, without a branch (below the knee
/// `J - max(J, knee)` is the distance to the knee, above it zero).
#[inline(always)]
pub(crate) fn fast_barrier_slope<T: SplitExponent>(j: T) -> T {
    let knee = T::cst(BARRIER_KNEE);
    let above = j.at_least(knee);
    let l = BARRIER_KNEE.ln();
    let below_curvature = (1.0 - l) / (BARRIER_KNEE * BARRIER_KNEE);
    fast_ln(above) / above + (j - above).scale(below_curvature)
}

/// A floating-point number the kernel can run on: `f64`, or `f32` for the
/// single-precision force pass (constants and the volumetric law are given
/// in `f64` and rounded).
pub(crate) trait Element:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    fn from_f64(v: f64) -> Self;
    fn to_f64(self) -> f64;
    fn square_root(self) -> Self;
    /// [`SplitExponent::split_exponent`].
    fn split(self) -> (Self, Self);
}

impl Element for f64 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn square_root(self) -> Self {
        self.sqrt()
    }
    #[inline(always)]
    fn split(self) -> (Self, Self) {
        let bits = self.to_bits();
        let k = ((bits >> 52) & 0x7ff) as i32 - 1023;
        let m = f64::from_bits((bits & ((1 << 52) - 1)) | 1.0f64.to_bits());
        if m > std::f64::consts::SQRT_2 {
            (m * 0.5, f64::from(k + 1))
        } else {
            (m, f64::from(k))
        }
    }
}

impl Element for f32 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline(always)]
    fn square_root(self) -> Self {
        self.sqrt()
    }
    #[inline(always)]
    fn split(self) -> (Self, Self) {
        let bits = self.to_bits();
        let k = ((bits >> 23) & 0xff) as i32 - 127;
        let m = f32::from_bits((bits & ((1 << 23) - 1)) | 1.0f32.to_bits());
        // Both conversions are exact: |k| < 2^24.
        if m > std::f32::consts::SQRT_2 {
            (m * 0.5, (k + 1) as f32)
        } else {
            (m, k as f32)
        }
    }
}

impl<E: Element> Scalar for E {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        E::from_f64(v)
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        self * E::from_f64(k)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.square_root()
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        E::from_f64(f(self.to_f64()).0)
    }
    #[inline(always)]
    fn barrier_slope(self) -> Self {
        fast_barrier_slope(self)
    }
    #[inline(always)]
    fn at_least(self, o: Self) -> Self {
        if o > self { o } else { self }
    }
    #[inline(always)]
    fn any_below(self, v: f64) -> bool {
        self < E::from_f64(v)
    }
}

impl<E: Element> SplitExponent for E {
    #[inline(always)]
    fn split_exponent(self) -> (Self, Self) {
        self.split()
    }
}

/// Forward-mode dual number with `N` directional derivatives: the force
/// kernel evaluated on them is the tests' reference for the closed-form
/// Jacobian, and the 2D element's tangent (`crate::plane`).
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
        let mut g = self.g;
        for (g, o) in g.iter_mut().zip(o.g) {
            *g += o;
        }
        Self { v: self.v + o.v, g }
    }
}
impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        let mut g = self.g;
        for (g, o) in g.iter_mut().zip(o.g) {
            *g -= o;
        }
        Self { v: self.v - o.v, g }
    }
}
// The product rule: the derivative of a product is a sum.
#[allow(clippy::suspicious_arithmetic_impl)]
impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let mut g = self.g;
        for (g, og) in g.iter_mut().zip(o.g) {
            *g = *g * o.v + og * self.v;
        }
        Self { v: self.v * o.v, g }
    }
}
impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let v = self.v / o.v;
        let inv = 1.0 / o.v;
        let mut g = self.g;
        for (g, og) in g.iter_mut().zip(o.g) {
            *g = (*g - v * og) * inv;
        }
        Self { v, g }
    }
}
impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        let mut g = self.g;
        for g in &mut g {
            *g = -*g;
        }
        Self { v: -self.v, g }
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
        let mut g = self.g;
        for g in &mut g {
            *g *= k;
        }
        Self { v: self.v * k, g }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let d = 0.5 / s;
        let mut g = self.g;
        for g in &mut g {
            *g *= d;
        }
        Self { v: s, g }
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        let (v, d) = f(self.v);
        let mut g = self.g;
        for g in &mut g {
            *g *= d;
        }
        Self { v, g }
    }
    #[inline(always)]
    fn at_least(self, o: Self) -> Self {
        if o.v > self.v { o } else { self }
    }
    #[inline(always)]
    fn any_below(self, v: f64) -> bool {
        self.v < v
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
    /// Energy scale `kappa` (J) of the corner barrier `kappa psi(J_n)` on each
    /// of the 8 corner Jacobians ([`corner_barrier_law`]; 0 for none).
    pub corner_barrier: f64,
}

pub(crate) type V3<T> = [T; 3];

#[inline(always)]
fn sub<T: Scalar>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline(always)]
fn add<T: Scalar>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
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

/// `1 - L0 / l` of a spring of rest length `rest` along `d`: its force per
/// unit of stiffness and of `d`. Computed once per lattice edge by the force
/// pass ([`edge_stretches_batch`]) and once per diagonal by the cell kernel;
/// these are the kernel's only square roots and divisions besides the cell
/// axes.
#[inline(always)]
pub(crate) fn stretch<T: Scalar>(rest: f64, d: V3<T>) -> T {
    let l = dot(d, d).sqrt();
    T::cst(1.0) - T::cst(rest) / l
}

/// [`stretch`] of an edge resting at `rest` whose squared length is `q`,
/// for the single-precision force pass: `1 / sqrt(q)` seeded in single
/// precision ([`InverseSqrtSeed`]) and refined by one Newton step in double
/// precision, `y (3/2 - q y^2 / 2)`, which squares the seed's relative
/// error (about 1e-7) to about 1e-14; no division or square root in double
/// precision, which bound the edge pass (a quarter of the single-precision
/// force pass's time on AVX-512). The difference from [`stretch`], about
/// 1e-14 in absolute terms, is far below the single precision in which the
/// force kernel then uses the stretch (6e-8 of it).
#[inline(always)]
pub(crate) fn seeded_stretch<T: InverseSqrtSeed>(rest: f64, q: T) -> T {
    let y = q.inverse_sqrt_seed();
    let y = y * (T::cst(1.5) - q.scale(0.5) * y * y);
    T::cst(1.0) - y.scale(rest)
}

/// Adds the forces `k w d` on `a` and `-k w d` on `b` of a spring along
/// `d = x_b - x_a` with stretch `w` ([`stretch`]).
#[inline(always)]
fn spring<T: Scalar>(k: f64, w: T, d: V3<T>, a: usize, b: usize, f: &mut [V3<T>; 8]) {
    let fd = mul_s(d, w.scale(k));
    add_to(&mut f[a], fd);
    sub_from(&mut f[b], fd);
}

/// The part of the cell's forces that is not the springs' (corrections,
/// volumetric term, hourglass control), given the springs' forces already in
/// `f`.
///
/// Every one of these terms gives corner `n` a sum of cell vectors weighted
/// by the corner's signs: `s_j(n) A_j` (corrections, the volumetric term, the
/// hourglass control's tilt) and `s_j s_k(n) B_i` (the hourglass control's
/// push along its mechanism). The terms first add their vectors into the six
/// `A_j`, `B_i`, which [`add_corner_patterns`] then spreads over the corners
/// once: a third of the operations of adding each term to each corner, and
/// fewer values held at once.
#[inline(always)]
fn finish_cell<T: Scalar>(
    p: &CellParams,
    x: &[V3<T>; 8],
    axis_sum: [V3<T>; 3],
    f: &mut [V3<T>; 8],
) {
    let zero = [T::cst(0.0); 3];
    // `side[j]`: the vector corner `n` gets times `s_j(n)`; `twist[i]`: times
    // `s_j s_k(n)`, `(i, j, k)` a cyclic order.
    let mut side = [zero; 3];
    let mut twist = None;
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
        for (j, sj) in side.iter_mut().enumerate() {
            *sj = mul_s(axes[j], (sum - nf[j]).scale(q));
        }
    }
    if p.vol_lambda_h3 != 0.0 {
        // The deformation gradient's columns at the centre are the axis sums
        // (each the signed sum of the corners along its axis) over 4 h.
        let mut fcols = [zero; 3];
        for (c, m) in fcols.iter_mut().zip(&axis_sum) {
            *c = [
                m[0].scale(p.grad_scale),
                m[1].scale(p.grad_scale),
                m[2].scale(p.grad_scale),
            ];
        }
        let jac = dot(fcols[0], cross(fcols[1], fcols[2]));
        let slope = if p.vol_barrier {
            jac.barrier_slope()
        } else {
            jac - T::cst(1.0)
        };
        let coef = slope.scale(-p.vol_lambda_h3 * p.grad_scale);
        add_to(&mut side[0], mul_s(cross(fcols[1], fcols[2]), coef));
        add_to(&mut side[1], mul_s(cross(fcols[2], fcols[0]), coef));
        add_to(&mut side[2], mul_s(cross(fcols[0], fcols[1]), coef));
    }
    if let (true, Some((axes, inv_len))) = (p.k_hourglass != 0.0, &axes) {
        twist = Some(add_hourglass_forces(
            p.k_hourglass,
            hourglass_sums(x),
            axes,
            inv_len,
            &mut side,
        ));
    }
    if p.correction.is_some() || p.vol_lambda_h3 != 0.0 || twist.is_some() {
        add_corner_patterns(&side, twist.as_ref(), f);
    }
}

/// `f_n += sum_j s_j(n) side_j + sum_i s_j s_k(n) twist_i` (`(i, j, k)` a
/// cyclic order) for the 8 corners, factored as `P(s_1, s_2) + s_0 Q(s_1,
/// s_2)`: 14 vector operations without `twist`, 28 with it, where adding
/// each term to each corner takes 24 per term.
#[inline(always)]
fn add_corner_patterns<T: Scalar>(
    side: &[V3<T>; 3],
    twist: Option<&[V3<T>; 3]>,
    f: &mut [V3<T>; 8],
) {
    let plus_yz = add(side[1], side[2]);
    let minus_yz = sub(side[1], side[2]);
    // Corners in `CORNER_OFFSETS` order, each with its vector and whether it
    // is subtracted.
    match twist {
        None => {
            // P = s1 A1 + s2 A2, Q = A0.
            let (a, b) = (add(side[0], plus_yz), sub(side[0], plus_yz));
            let (c, d) = (add(side[0], minus_yz), sub(side[0], minus_yz));
            add_signed(
                f,
                [a, b, c, d, c, d, a, b],
                [true, false, false, true, true, false, false, true],
            );
        }
        Some(twist) => {
            // P = s1 A1 + s2 A2 + s1 s2 B0, Q = A0 + s2 B1 + s1 B2; `p01` is
            // minus P(0, 1).
            let p11 = add(twist[0], plus_yz);
            let p00 = sub(twist[0], plus_yz);
            let p10 = sub(minus_yz, twist[0]);
            let p01 = add(minus_yz, twist[0]);
            let plus_b = add(twist[1], twist[2]);
            let minus_b = sub(twist[1], twist[2]);
            let q11 = add(side[0], plus_b);
            let q00 = sub(side[0], plus_b);
            let q10 = sub(side[0], minus_b);
            let q01 = add(side[0], minus_b);
            add_signed(
                f,
                [
                    sub(p00, q00),
                    add(p00, q00),
                    add(p10, q10),
                    sub(p10, q10),
                    add(p01, q01),
                    sub(q01, p01),
                    add(p11, q11),
                    sub(p11, q11),
                ],
                [false, false, false, false, true, false, false, false],
            );
        }
    }
}

/// `f_n += v_n`, or `-= v_n` where `minus[n]`.
#[inline(always)]
fn add_signed<T: Scalar>(f: &mut [V3<T>; 8], v: [V3<T>; 8], minus: [bool; 8]) {
    for ((fn_, vn), minus) in f.iter_mut().zip(v).zip(minus) {
        if minus {
            sub_from(fn_, vn);
        } else {
            add_to(fn_, vn);
        }
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
#[cfg(test)]
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

/// [`barrier_slope`] with [`fast_ln`] and without a branch: `(phi'(J),
/// phi''(J))` from one logarithm (below the knee `max(J, knee)` is the knee,
/// where `(1 - ln J) / J^2` is the continuation's constant curvature).
#[inline(always)]
fn fast_barrier_slope_and_curvature<T: SplitExponent>(j: T) -> (T, T) {
    let knee = T::cst(BARRIER_KNEE);
    let above = j.at_least(knee);
    let l = fast_ln(above);
    let below_curvature = (1.0 - BARRIER_KNEE.ln()) / (BARRIER_KNEE * BARRIER_KNEE);
    (
        l / above + (j - above).scale(below_curvature),
        (T::cst(1.0) - l) / (above * above),
    )
}

/// What the explicit step's checks need of a cell ([`cell_survey`]).
#[derive(Clone, Copy)]
pub(crate) struct CellSurvey<T> {
    /// `J = det F` at the centre (`<= 0`: inverted).
    pub jac: T,
    /// [`volumetric_growth`] (with [`fast_ln`]), when asked for.
    pub volumetric_growth: T,
    /// The smallest corner Jacobian ([`corner_jacobians`]), when asked for.
    pub lowest_corner: T,
}

/// The centre Jacobian of a cell of parameters `p` at `x`, and when asked
/// for the volumetric term's stiffness growth and the lowest corner
/// Jacobian: written once over the number type, so that SIMD lanes and the
/// scalar path give the same bits (no fused operations, [`fast_ln`]).
#[inline(always)]
pub(crate) fn cell_survey<T: SplitExponent>(
    p: &CellParams,
    x: &[V3<T>; 8],
    growth: bool,
    corners: bool,
) -> CellSurvey<T> {
    let (cols, jac) = deformation_gradient(x, p.grad_scale);
    let mut volumetric_growth = T::cst(1.0);
    if growth {
        let (slope, curvature) = if p.vol_barrier {
            fast_barrier_slope_and_curvature(jac)
        } else {
            (jac - T::cst(1.0), T::cst(1.0))
        };
        let mut cof2 = T::cst(0.0);
        for j in 0..3 {
            let c = cross(cols[(j + 1) % 3], cols[(j + 2) % 3]);
            cof2 += dot(c, c);
        }
        let f2 = dot(cols[0], cols[0]) + dot(cols[1], cols[1]) + dot(cols[2], cols[2]);
        let magnitude = slope.at_least(-slope);
        volumetric_growth = curvature * cof2 / T::cst(3.0) + magnitude * (f2 / T::cst(3.0)).sqrt();
    }
    let mut lowest_corner = T::cst(f64::INFINITY);
    if corners {
        let inv_h3 = 1.0 / (p.rest_edge * p.rest_edge * p.rest_edge);
        let (_, corner) = corner_jacobians(x, inv_h3);
        // The minimum as a maximum of negatives: `Scalar` has only the one.
        let mut negated = -corner[0];
        for &c in &corner[1..] {
            negated = negated.at_least(-c);
        }
        lowest_corner = -negated;
    }
    CellSurvey {
        jac,
        volumetric_growth,
        lowest_corner,
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

/// The cell's axis sums `m_i`: the sum of its four edge vectors along axis
/// `i` (docs/model.md step 2).
#[inline(always)]
fn axis_sums(x: &[V3<f64>; 8]) -> [V3<f64>; 3] {
    let mut axis_sum = [[0.0; 3]; 3];
    for &(a, b, ax) in &CELL_EDGES {
        add_to(&mut axis_sum[ax], sub(x[b], x[a]));
    }
    axis_sum
}

/// `d a / d m = (I - a a^T) / |m|` of an axis `a = m / |m|`, given `a` and
/// `1 / |m|`.
#[inline(always)]
fn axis_derivative(a: V3<f64>, inv_len: f64) -> [[f64; 3]; 3] {
    std::array::from_fn(|e| {
        std::array::from_fn(|d| (if e == d { 1.0 } else { 0.0 } - a[e] * a[d]) * inv_len)
    })
}

/// The current cell axes `a_i` (normalized `axis_sum[i]`, docs/model.md step 2)
/// and `1 / |axis_sum[i]|`.
#[inline(always)]
fn cell_axes<T: Scalar>(axis_sum: &[V3<T>; 3]) -> ([V3<T>; 3], [T; 3]) {
    let mut len = [T::cst(0.0); 3];
    for (l, m) in len.iter_mut().zip(axis_sum) {
        *l = dot(*m, *m).sqrt();
    }
    let inv = inverses3(len);
    let mut axes = [[T::cst(0.0); 3]; 3];
    for i in 0..3 {
        axes[i] = mul_s(axis_sum[i], inv[i]);
    }
    (axes, inv)
}

/// `1 / l_i` of three lengths with one division. Square roots and divisions
/// share one unit of the core, which limits the kernel; a product of cell
/// lengths stays far inside the range of `f64` (it would leave it only for
/// cells below 1e-70 m), and the result is within a few ulps of `1 / l_i`.
#[inline(always)]
pub(crate) fn inverses3<T: Scalar>(l: [T; 3]) -> [T; 3] {
    let p12 = l[1] * l[2];
    let r = T::cst(1.0) / (l[0] * p12);
    [p12 * r, l[0] * l[2] * r, l[0] * l[1] * r]
}

/// `1 / l_i` of four lengths with one division (see [`inverses3`]).
#[inline(always)]
fn inverses4<T: Scalar>(l: [T; 4]) -> [T; 4] {
    let p01 = l[0] * l[1];
    let p23 = l[2] * l[3];
    let r = T::cst(1.0) / (p01 * p23);
    let (r01, r23) = (p23 * r, p01 * r);
    [l[1] * r01, l[0] * r01, l[3] * r23, l[2] * r23]
}

/// `8 g_i = sum_n s_j s_k(n) x_n`, the hourglass vectors' sums, from the
/// four edges along `j` (each the difference of two corners of equal `s_k`,
/// signed by it): half the operations of summing the corners, and in the
/// force kernel the springs' edge vectors.
#[inline(always)]
fn hourglass_sums<T: Scalar>(x: &[V3<T>; 8]) -> [V3<T>; 3] {
    let edge = |e: usize| {
        let (a, b, _) = CELL_EDGES[e];
        sub(x[b], x[a])
    };
    // Edges 4-7 run along y at z = 0, 0, 1, 1; 8-11 along z at x = 0, 1, 1,
    // 0; 0-3 along x at y = 0, 1, 0, 1.
    [
        sub(add(edge(6), edge(7)), add(edge(4), edge(5))),
        sub(add(edge(9), edge(10)), add(edge(8), edge(11))),
        sub(add(edge(1), edge(3)), add(edge(0), edge(2))),
    ]
}

/// The hourglass vectors `g_i = 1/8 sum_n s_j s_k(n) x_n` and amplitudes
/// `q_i = a_i . g_i` of the cell along its current axes `a_i`, given
/// `8 g_i` ([`hourglass_sums`]). `g_i` vanishes for every affine motion and
/// rotates with the cell, so `q_i` is zero for any homogeneous strain
/// (tension results stay exact) and invariant under rigid motions.
#[inline(always)]
fn hourglass_amplitudes<T: Scalar>(sums: [V3<T>; 3], axes: &[V3<T>; 3]) -> ([V3<T>; 3], [T; 3]) {
    let mut g = [[T::cst(0.0); 3]; 3];
    let mut q = [T::cst(0.0); 3];
    for i in 0..3 {
        let gi = sums[i];
        g[i] = [gi[0].scale(0.125), gi[1].scale(0.125), gi[2].scale(0.125)];
        q[i] = dot(axes[i], g[i]);
    }
    (g, q)
}

/// Forces of the hourglass energy `W = k/2 sum_i q_i^2`, `f_n = -dW/dx_n`,
/// including the derivative of the current axis (so the forces are exactly
/// conservative): `dq_i/dx_n = s_j s_k(n) / 8 a_i + s_i(n) (g_i - q_i a_i) / |m_i|`.
/// Adds the `s_i(n)` parts to `side[i]` and returns the `s_j s_k(n)` parts
/// (for [`add_corner_patterns`]).
#[inline(always)]
fn add_hourglass_forces<T: Scalar>(
    k: f64,
    sums: [V3<T>; 3],
    axes: &[V3<T>; 3],
    inv_len: &[T; 3],
    side: &mut [V3<T>; 3],
) -> [V3<T>; 3] {
    let (g, q) = hourglass_amplitudes(sums, axes);
    let mut twist = [[T::cst(0.0); 3]; 3];
    for i in 0..3 {
        let kq = q[i].scale(-k);
        twist[i] = mul_s(axes[i], kq.scale(0.125));
        let tilt = mul_s(sub(g[i], mul_s(axes[i], q[i])), kq * inv_len[i]);
        add_to(&mut side[i], tilt);
    }
    twist
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
    let mut edge_stretch = [T::cst(0.0); 12];
    for (w, &(a, b, _)) in edge_stretch.iter_mut().zip(&CELL_EDGES) {
        *w = stretch(p.rest_edge, sub(x[b], x[a]));
    }
    cell_forces_with_edges(p, x, &edge_stretch, f);
}

/// [`cell_forces`] given the stretches of the cell's 12 edges (in
/// [`CELL_EDGES`] order), which the cells around an edge share: the force
/// pass computes them once per lattice edge. Bitwise the same forces.
#[inline(always)]
pub(crate) fn cell_forces_with_edges<T: Scalar>(
    p: &CellParams,
    x: &[V3<T>; 8],
    edge_stretch: &[T; 12],
    f: &mut [V3<T>; 8],
) {
    // The corner barrier is asked first: it acts on few cells, and its
    // forces, when it does, recompute what they need from `x`. Asked at the
    // end, its edge vectors kept the corners and the springs' edge vectors
    // live through the whole kernel (register spills).
    let barrier = p.corner_barrier != 0.0 && corner_barrier_acts(p, x);
    *f = [[T::cst(0.0); 3]; 8];
    let mut axis_sum = [[T::cst(0.0); 3]; 3];
    // Written out edge by edge rather than as a loop over `CELL_EDGES`: the
    // loop was kept rolled, its corner indices loaded at run time, and every
    // force sum went through memory with a dependency between iterations.
    macro_rules! edge {
        ($e:literal) => {{
            let (a, b, ax) = CELL_EDGES[$e];
            let d = sub(x[b], x[a]);
            add_to(&mut axis_sum[ax], d);
            spring(p.k_edge, edge_stretch[$e], d, a, b, f);
        }};
    }
    edge!(0);
    edge!(1);
    edge!(2);
    edge!(3);
    edge!(4);
    edge!(5);
    edge!(6);
    edge!(7);
    edge!(8);
    edge!(9);
    edge!(10);
    edge!(11);
    // Loops, not `array::map`, here and below: see `finish_cell`.
    let mut diagonals = [[T::cst(0.0); 3]; 4];
    let mut len = [T::cst(0.0); 4];
    for ((d, l), &(a, b)) in diagonals.iter_mut().zip(&mut len).zip(&CELL_DIAGONALS) {
        *d = sub(x[b], x[a]);
        *l = dot(*d, *d).sqrt();
    }
    let inv = inverses4(len);
    for ((&(a, b), d), inv) in CELL_DIAGONALS.iter().zip(diagonals).zip(inv) {
        let w = T::cst(1.0) - inv.scale(p.rest_diag);
        spring(p.k_diag, w, d, a, b, f);
    }
    finish_cell(p, x, axis_sum, f);
    if barrier {
        add_corner_barrier_forces(p, x, f);
    }
}

/// Below this corner volume ratio the corner barrier acts
/// ([`corner_barrier_law`]); above it the barrier is exactly zero, so no
/// small or moderate strain sees it.
pub(crate) const CORNER_BARRIER_START: f64 = 0.2;

/// The corner barrier's strength: its energy at `J_n = 0` in units of
/// `kappa` ([`corner_barrier_law`]).
pub(crate) const CORNER_BARRIER_DEPTH: f64 = 2.0;

/// The cell's edges at each corner, along x, y and z (indices into
/// [`CELL_EDGES`], whose edge vectors all point along `+x`, `+y`, `+z`): the
/// trilinear map's gradient at corner `n` has these edge vectors over `h` as
/// its columns.
pub(crate) const CORNER_EDGE_IDS: [[usize; 3]; 8] = [
    [0, 4, 8],
    [0, 5, 9],
    [1, 5, 10],
    [1, 4, 11],
    [2, 6, 8],
    [2, 7, 9],
    [3, 7, 10],
    [3, 6, 11],
];

/// The corner barrier's law `psi(J) = D ((S - J) / S)^3` below
/// `S` = [`CORNER_BARRIER_START`], zero above it (with zero slope and
/// curvature at `S`: twice continuously differentiable), `D` =
/// [`CORNER_BARRIER_DEPTH`]: `(psi, psi', psi'')`. A polynomial rather than
/// a law that is infinite at `J = 0`: its stiffness grows only linearly
/// with depth, which an explicit step can follow through an impact, while
/// its push (`-3 D / S` at `J = 0`, as steep as the centre's barrier near
/// its knee) keeps quasi-static scenes unfolded (docs/robustness.md).
pub(crate) fn corner_barrier_law(j: f64) -> (f64, f64, f64) {
    const S: f64 = CORNER_BARRIER_START;
    const D: f64 = CORNER_BARRIER_DEPTH;
    let u = (S - j).max(0.0) / S;
    (D * u * u * u, -3.0 * D * u * u / S, 6.0 * D * u / (S * S))
}

/// `psi'` of [`corner_barrier_law`] without a branch (as
/// [`fast_barrier_slope`]): every number type computes the same operations.
#[inline(always)]
fn corner_barrier_slope<T: Scalar>(j: T) -> T {
    const S: f64 = CORNER_BARRIER_START;
    let u = (T::cst(S) - j).at_least(T::cst(0.0));
    -(u * u).scale(3.0 * CORNER_BARRIER_DEPTH / (S * S * S))
}

/// The 12 edge vectors of a cell ([`CELL_EDGES`] order) and its 8 corner
/// Jacobians `J_n = det(e_x, e_y, e_z) / h^3` (the trilinear map's
/// determinant at each corner, 1 at rest), given `1 / h^3`.
#[inline(always)]
pub(crate) fn corner_jacobians<T: Scalar>(x: &[V3<T>; 8], inv_h3: f64) -> ([V3<T>; 12], [T; 8]) {
    let mut edges = [[T::cst(0.0); 3]; 12];
    for (e, &(a, b, _)) in edges.iter_mut().zip(&CELL_EDGES) {
        *e = sub(x[b], x[a]);
    }
    let mut jac = [T::cst(0.0); 8];
    for (j, ids) in jac.iter_mut().zip(&CORNER_EDGE_IDS) {
        let [ex, ey, ez] = ids.map(|i| edges[i]);
        *j = dot(ex, cross(ey, ez)).scale(inv_h3);
    }
    (edges, jac)
}

/// Whether any corner of the cells (any lane) is below the corner barrier's
/// start: elsewhere its forces are exactly zero.
#[inline(always)]
fn corner_barrier_acts<T: Scalar>(p: &CellParams, x: &[V3<T>; 8]) -> bool {
    let inv_h3 = 1.0 / (p.rest_edge * p.rest_edge * p.rest_edge);
    let (_, jac) = corner_jacobians(x, inv_h3);
    jac.iter().any(|j| j.any_below(CORNER_BARRIER_START))
}

/// Adds the forces of the corner barrier `kappa sum_n psi(J_n)`: the
/// one-point volumetric term sees only the centre, where a cell can keep a
/// healthy volume while a corner folds through (docs/robustness.md). Called
/// only for groups of cells where a corner is below the barrier's start
/// ([`corner_barrier_acts`]): elsewhere it adds exact zeros.
#[inline(always)]
fn add_corner_barrier_forces<T: Scalar>(p: &CellParams, x: &[V3<T>; 8], f: &mut [V3<T>; 8]) {
    let inv_h3 = 1.0 / (p.rest_edge * p.rest_edge * p.rest_edge);
    let (edges, jac) = corner_jacobians(x, inv_h3);
    for (j, ids) in jac.iter().zip(&CORNER_EDGE_IDS) {
        let coef = corner_barrier_slope(*j).scale(-p.corner_barrier * inv_h3);
        let [ex, ey, ez] = ids.map(|i| edges[i]);
        let cof = [cross(ey, ez), cross(ez, ex), cross(ex, ey)];
        for (&e, c) in ids.iter().zip(cof) {
            let (a, b, _) = CELL_EDGES[e];
            let fc = mul_s(c, coef);
            add_to(&mut f[b], fc);
            sub_from(&mut f[a], fc);
        }
    }
}

/// Adds the corner barrier's part of the cell Jacobian (minus its Hessian):
/// per corner `kappa (psi'' g g^T + psi' d^2 J_n / de^2)` with `g` the
/// gradient of `J_n` with respect to its three edge vectors, mapped to the
/// edges' end nodes.
fn add_corner_barrier_jacobian(p: &CellParams, x: &[V3<f64>; 8], jac: &mut [[f64; 24]; 24]) {
    let inv_h3 = 1.0 / (p.rest_edge * p.rest_edge * p.rest_edge);
    let (edges, corner_jac) = corner_jacobians(x, inv_h3);
    for (&j, ids) in corner_jac.iter().zip(&CORNER_EDGE_IDS) {
        if j >= CORNER_BARRIER_START {
            continue;
        }
        let (_, slope, curvature) = corner_barrier_law(j);
        let e = ids.map(|i| edges[i]);
        let grad =
            [cross(e[1], e[2]), cross(e[2], e[0]), cross(e[0], e[1])].map(|c| mul_s(c, inv_h3));
        for (a, &ea) in ids.iter().enumerate() {
            for (b, &eb) in ids.iter().enumerate() {
                let mut block: [[f64; 3]; 3] = std::array::from_fn(|r| {
                    std::array::from_fn(|c| curvature * grad[a][r] * grad[b][c])
                });
                // J_n = det(e) / h^3.
                let second = det_second_derivative(&e, a, b);
                for (row, srow) in block.iter_mut().zip(second) {
                    for (v, sv) in row.iter_mut().zip(srow) {
                        *v += slope * sv * inv_h3;
                    }
                }
                // Edge `ea` runs from node `a0` to `a1`: d e / d x_a1 = I, d e / d x_a0 = -I.
                let (a0, a1, _) = CELL_EDGES[ea];
                let (b0, b1, _) = CELL_EDGES[eb];
                let k = -p.corner_barrier;
                add_block(jac, a1, b1, k, &block);
                add_block(jac, a0, b0, k, &block);
                add_block(jac, a1, b0, -k, &block);
                add_block(jac, a0, b1, -k, &block);
            }
        }
    }
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
        let (axes, _) = cell_axes(&axis_sums(x));
        let (_, q) = hourglass_amplitudes(hourglass_sums(x), &axes);
        e += 0.5 * p.k_hourglass * dot(q, q);
    }
    if p.corner_barrier != 0.0 {
        let (_, jac) = corner_jacobians(x, 1.0 / p.rest_edge.powi(3));
        e += p.corner_barrier * jac.iter().map(|&j| corner_barrier_law(j).0).sum::<f64>();
    }
    e
}

/// The exact 24x24 Jacobian d f / d x of one cell: `jac[3 b + e][3 a + d]` is
/// d f_{b,e} / d x_{a,d}.
///
/// Written out term by term ([`cell_jacobian_closed_form`]): about 2.5 times
/// cheaper than dual numbers through the force kernel, which the tests use
/// as its reference.
pub(crate) fn cell_jacobian(p: &CellParams, x: &[V3<f64>; 8]) -> [[f64; 24]; 24] {
    cell_jacobian_closed_form(p, x)
}

/// `jac[n][m] += k M`, the 3x3 block of node `n`'s force against node `m`.
#[inline(always)]
fn add_block(jac: &mut [[f64; 24]; 24], n: usize, m: usize, k: f64, block: &[[f64; 3]; 3]) {
    for (e, row) in block.iter().enumerate() {
        for (d, v) in row.iter().enumerate() {
            jac[3 * n + e][3 * m + d] += k * v;
        }
    }
}

/// `d^2 det / (dc_j dc_k)` of the determinant of the columns `c`: zero for
/// `j = k`, else `-eps_jkl [c_l]x`.
fn det_second_derivative(cols: &[V3<f64>; 3], j: usize, k: usize) -> [[f64; 3]; 3] {
    if j == k {
        return [[0.0; 3]; 3];
    }
    let l = 3 - j - k;
    let eps = if (j + 1) % 3 == k { 1.0 } else { -1.0 };
    let sk = skew(cols[l]);
    std::array::from_fn(|e| std::array::from_fn(|d| -eps * sk[e][d]))
}

/// The skew matrix `[v]x` (`[v]x w = v x w`).
#[inline(always)]
fn skew(v: V3<f64>) -> [[f64; 3]; 3] {
    [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]
}

/// The cell Jacobian: minus the Hessian of the energy (springs, volumetric
/// term, hourglass control) plus the derivative of the correction forces,
/// which have no energy ([`add_correction_jacobian`]).
///
/// - A spring of direction `d`, length `l` and rest length `L` has the block
///   `k ((1 - L/l) I + (L/l) d d^T / l^2)` between its ends.
/// - The volumetric energy `lambda h^3 phi(J)` has the Hessian
///   `lambda h^3 (phi'' b b^T + phi' d^2J/dx^2)` with `b = dJ/dx`, where
///   `d^2 J / (df_j df_k) = -eps_jkl [f_l]x` for the columns `f` of `F`.
/// - The hourglass energy `k/2 sum_i q_i^2` with `q_i = m_i . g_i / |m_i|`
///   (`m_i` the axis sum, `g_i` the hourglass vector, both linear in `x`) has
///   the Hessian `k sum_i (grad q_i grad q_i^T + q_i d^2 q_i / dx^2)`, where
///   `d^2 q / dm dg = P / |m|` and `d^2 q / dm^2 = -(u w^T + w u^T + q P) / |m|^2`
///   with `u = m / |m|`, `P = I - u u^T` and `w = P g`.
pub(crate) fn cell_jacobian_closed_form(p: &CellParams, x: &[V3<f64>; 8]) -> [[f64; 24]; 24] {
    let mut jac = [[0.0; 24]; 24];
    // The springs' forces, for the corrections (built from them).
    let mut spring_forces = [[0.0; 3]; 8];
    let mut spring_block = |k: f64, rest: f64, a: usize, b: usize| {
        let d = sub(x[b], x[a]);
        if p.correction.is_some() {
            spring(k, stretch(rest, d), d, a, b, &mut spring_forces);
        }
        let l2 = dot(d, d);
        let l = l2.sqrt();
        let along = rest / (l * l2);
        let iso = 1.0 - rest / l;
        let block: [[f64; 3]; 3] = std::array::from_fn(|e| {
            std::array::from_fn(|c| k * (along * d[e] * d[c] + if e == c { iso } else { 0.0 }))
        });
        add_block(&mut jac, a, b, 1.0, &block);
        add_block(&mut jac, b, a, 1.0, &block);
        add_block(&mut jac, a, a, -1.0, &block);
        add_block(&mut jac, b, b, -1.0, &block);
    };
    for &(a, b, _) in &CELL_EDGES {
        spring_block(p.k_edge, p.rest_edge, a, b);
    }
    for &(a, b) in &CELL_DIAGONALS {
        spring_block(p.k_diag, p.rest_diag, a, b);
    }
    // The current axes and their derivatives serve both the corrections and
    // the hourglass control.
    let axes = (p.correction.is_some() || p.k_hourglass != 0.0).then(|| {
        let (axes, inv_len) = cell_axes(&axis_sums(x));
        let turn: [[[f64; 3]; 3]; 3] =
            std::array::from_fn(|i| axis_derivative(axes[i], inv_len[i]));
        (axes, inv_len, turn)
    });
    if let (Some(corr), Some((axes, _, turn))) = (&p.correction, &axes) {
        add_correction_jacobian(corr, &spring_forces, axes, turn, &mut jac);
    }
    if p.vol_lambda_h3 != 0.0 {
        let (cols, det) = deformation_gradient(x, p.grad_scale);
        let (slope, curvature) = if p.vol_barrier {
            barrier_slope(det)
        } else {
            (det - 1.0, 1.0)
        };
        let cof = [
            cross(cols[1], cols[2]),
            cross(cols[2], cols[0]),
            cross(cols[0], cols[1]),
        ];
        let gs = p.grad_scale;
        // dJ/dx_n = gs sum_j s_nj cof_j.
        let grad: [V3<f64>; 8] = std::array::from_fn(|n| {
            let mut g = [0.0; 3];
            for (j, c) in cof.iter().enumerate() {
                let s = corner_sign(n, j) * gs;
                g = [g[0] + s * c[0], g[1] + s * c[1], g[2] + s * c[2]];
            }
            g
        });
        let h: [[[[f64; 3]; 3]; 3]; 3] =
            std::array::from_fn(|j| std::array::from_fn(|k| det_second_derivative(&cols, j, k)));
        let lam = p.vol_lambda_h3;
        for n in 0..8 {
            for m in 0..8 {
                let mut block = [[0.0; 3]; 3];
                for (j, hj) in h.iter().enumerate() {
                    for (k, hjk) in hj.iter().enumerate() {
                        if j == k {
                            continue;
                        }
                        let w = corner_sign(n, j) * corner_sign(m, k) * gs * gs * slope;
                        for e in 0..3 {
                            for d in 0..3 {
                                block[e][d] += w * hjk[e][d];
                            }
                        }
                    }
                }
                for e in 0..3 {
                    for d in 0..3 {
                        block[e][d] += curvature * grad[n][e] * grad[m][d];
                    }
                }
                add_block(&mut jac, n, m, -lam, &block);
            }
        }
    }
    if let (true, Some((axes, inv_len, turn))) = (p.k_hourglass != 0.0, &axes) {
        let (g, q) = hourglass_amplitudes(hourglass_sums(x), axes);
        for i in 0..3 {
            let u = axes[i];
            let il = inv_len[i];
            let w = sub(g[i], mul_s(u, q[i]));
            // d^2 q / dm dg = P / |m| (the axis derivative) and d^2 q / dm^2.
            let qmg = &turn[i];
            let qmm: [[f64; 3]; 3] = std::array::from_fn(|e| {
                std::array::from_fn(|d| {
                    -(u[e] * w[d] + w[e] * u[d]) * il * il - q[i] * qmg[e][d] * il
                })
            });
            // m_i = sum_n s_i(n) x_n (every corner ends one of the four edges
            // along i), g_i = 1/8 sum_n s_j s_k(n) x_n.
            let side = |n: usize| corner_sign(n, i);
            let hg = |n: usize| 0.125 * hourglass_sign(n, i);
            let grad_q: [V3<f64>; 8] = std::array::from_fn(|n| {
                let (a, b) = (side(n) * il, hg(n));
                [
                    a * w[0] + b * u[0],
                    a * w[1] + b * u[1],
                    a * w[2] + b * u[2],
                ]
            });
            for n in 0..8 {
                for m in 0..8 {
                    let (sn, sm, hn, hm) = (side(n), side(m), hg(n), hg(m));
                    let block: [[f64; 3]; 3] = std::array::from_fn(|e| {
                        std::array::from_fn(|d| {
                            grad_q[n][e] * grad_q[m][d]
                                + q[i] * (sn * sm * qmm[e][d] + (sn * hm + hn * sm) * qmg[e][d])
                        })
                    });
                    add_block(&mut jac, n, m, -p.k_hourglass, &block);
                }
            }
        }
    }
    if p.corner_barrier != 0.0 {
        add_corner_barrier_jacobian(p, x, &mut jac);
    }
    jac
}

/// Adds the derivative of the correction forces to `jac`, which holds the
/// springs' Jacobian (the corrections are built from the springs' forces
/// `f`), given the current axes and their derivatives `dproj`
/// ([`axis_derivative`]).
///
/// The correction on node `n` is `sum_j s_j(n) beta_j a_j` with
/// `beta = C t`, `C = -(c/4) (1 1^T - I) M^-1` and `t_i = a_i . S_i / 2`,
/// `S_i` the springs' forces summed with sign `-s_i` over the corners. Its
/// derivative needs `da_j/dx_m = s_j(m) P_j / |m_j|` and `dS_i/dx_m`, a signed
/// sum of the springs' blocks.
// Node, axis and component indices run over several arrays at once.
#[allow(clippy::needless_range_loop)]
fn add_correction_jacobian(
    corr: &Correction,
    f: &[V3<f64>; 8],
    axes: &[V3<f64>; 3],
    dproj: &[[[f64; 3]; 3]; 3],
    jac: &mut [[f64; 24]; 24],
) {
    let mut sums = [[0.0; 3]; 3];
    for (i, si) in sums.iter_mut().enumerate() {
        for (n, fn_) in f.iter().enumerate() {
            let w = -corner_sign(n, i);
            *si = [si[0] + w * fn_[0], si[1] + w * fn_[1], si[2] + w * fn_[2]];
        }
    }
    let t: [f64; 3] = std::array::from_fn(|i| 0.5 * dot(axes[i], sums[i]));
    let q = -corr.c / 4.0;
    let m = &corr.minv;
    // C = q (1 1^T - I) M^-1: beta_j = q sum_{i != j} (M^-1 t)_i.
    let cmat: [[f64; 3]; 3] = std::array::from_fn(|j| {
        std::array::from_fn(|k| q * (0..3).filter(|&i| i != j).map(|i| m[i][k]).sum::<f64>())
    });
    let beta: [f64; 3] = std::array::from_fn(|j| dot(cmat[j], t));
    // grad_t[i][mm] = d t_i / d x_mm.
    let mut grad_t = [[[0.0; 3]; 8]; 3];
    for i in 0..3 {
        let ps: V3<f64> = std::array::from_fn(|e| dot(dproj[i][e], sums[i]));
        for (mm, g) in grad_t[i].iter_mut().enumerate() {
            let sm = corner_sign(mm, i);
            let mut acc = [sm * ps[0], sm * ps[1], sm * ps[2]];
            for n in 0..8 {
                let w = -corner_sign(n, i);
                for d in 0..3 {
                    let col: f64 = (0..3)
                        .map(|e| jac[3 * n + e][3 * mm + d] * axes[i][e])
                        .sum();
                    acc[d] += w * col;
                }
            }
            *g = [0.5 * acc[0], 0.5 * acc[1], 0.5 * acc[2]];
        }
    }
    let grad_beta: [[V3<f64>; 8]; 3] = std::array::from_fn(|j| {
        std::array::from_fn(|mm| {
            std::array::from_fn(|d| (0..3).map(|i| cmat[j][i] * grad_t[i][mm][d]).sum())
        })
    });
    for n in 0..8 {
        for mm in 0..8 {
            let mut block = [[0.0; 3]; 3];
            for j in 0..3 {
                let sn = corner_sign(n, j);
                let turn = beta[j] * corner_sign(mm, j);
                for (e, row) in block.iter_mut().enumerate() {
                    for (d, v) in row.iter_mut().enumerate() {
                        *v += sn * (axes[j][e] * grad_beta[j][mm][d] + turn * dproj[j][e][d]);
                    }
                }
            }
            add_block(jac, n, mm, 1.0, &block);
        }
    }
}

/// [`cell_jacobian`] by forward-mode dual numbers through the force kernel:
/// exact for every model, the reference of the closed form.
#[cfg(test)]
pub(crate) fn cell_jacobian_dual(p: &CellParams, x: &[V3<f64>; 8]) -> [[f64; 24]; 24] {
    let xd: [V3<Dual<24>>; 8] =
        std::array::from_fn(|a| std::array::from_fn(|d| Dual::var(x[a][d], 3 * a + d)));
    let mut f = [[Dual::<24>::cst(0.0); 3]; 8];
    cell_forces(p, &xd, &mut f);
    std::array::from_fn(|r| f[r / 3][r % 3].g)
}

/// `L` independent lanes of `E`: the kernel evaluated on `L` cells at once
/// on the portable path. Every lane performs exactly the scalar operations,
/// so results are bitwise equal to the scalar kernel and to the AVX2 one.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lanes<E, const L: usize>(pub [E; L]);

macro_rules! lanes_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<E: Element, const L: usize> $tr for Lanes<E, L> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                // Plain loops, not `array::from_fn`/`map`: their closures are
                // separate functions that are not always inlined.
                let mut r = self.0;
                for (r, (a, b)) in r.iter_mut().zip(self.0.into_iter().zip(o.0)) {
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

impl<E: Element, const L: usize> Neg for Lanes<E, L> {
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
impl<E: Element, const L: usize> AddAssign for Lanes<E, L> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<E: Element, const L: usize> SubAssign for Lanes<E, L> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}
impl<E: Element, const L: usize> Scalar for Lanes<E, L> {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Self([E::from_f64(v); L])
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        self * Self::cst(k)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let mut r = self.0;
        for v in &mut r {
            *v = v.square_root();
        }
        Self(r)
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        let mut r = self.0;
        for v in &mut r {
            *v = E::from_f64(f(v.to_f64()).0);
        }
        Self(r)
    }
    #[inline(always)]
    fn barrier_slope(self) -> Self {
        fast_barrier_slope(self)
    }
    #[inline(always)]
    fn at_least(self, o: Self) -> Self {
        let mut r = self.0;
        for (r, (a, b)) in r.iter_mut().zip(self.0.into_iter().zip(o.0)) {
            *r = if b > a { b } else { a };
        }
        Self(r)
    }
    #[inline(always)]
    fn any_below(self, v: f64) -> bool {
        let v = E::from_f64(v);
        self.0.iter().any(|&a| a < v)
    }
}

impl<E: Element, const L: usize> SplitExponent for Lanes<E, L> {
    #[inline(always)]
    fn split_exponent(self) -> (Self, Self) {
        let (mut m, mut k) = (self.0, self.0);
        for ((m, k), v) in m.iter_mut().zip(&mut k).zip(self.0) {
            (*m, *k) = v.split();
        }
        (Self(m), Self(k))
    }
}

/// A scalar type holding several cells' values: [`Lanes`] on the portable
/// path, explicit AVX2 vectors on x86_64.
pub(crate) trait Pack: Scalar {
    /// Cells per value.
    const WIDTH: usize;
    /// The value of cell `l`.
    fn lane(self, l: usize) -> f64;
    /// The pack whose cell `l` holds `f(l)`.
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self;
    /// Cell by cell, `if_greater` where `other > self`, else `otherwise`
    /// (the choice [`Scalar::at_least`] makes, applied to other values).
    fn pick_where_greater(self, other: Self, if_greater: Self, otherwise: Self) -> Self;
}

/// What the single-precision force pass's edge stretches need of a number
/// type ([`seeded_stretch`]).
pub(crate) trait InverseSqrtSeed: Scalar {
    /// `1 / sqrt(self)` in single precision, per value: `self` rounded to
    /// `f32`, its square root, one over it, back to `f64` (every step
    /// rounded as IEEE says, so every number type gives the same bits).
    fn inverse_sqrt_seed(self) -> Self;
}

impl InverseSqrtSeed for f64 {
    #[inline(always)]
    fn inverse_sqrt_seed(self) -> Self {
        f64::from(1.0f32 / (self as f32).sqrt())
    }
}

impl<E: Element, const L: usize> InverseSqrtSeed for Lanes<E, L> {
    #[inline(always)]
    fn inverse_sqrt_seed(self) -> Self {
        let mut out = self;
        for v in &mut out.0 {
            *v = E::from_f64(v.to_f64().inverse_sqrt_seed());
        }
        out
    }
}

impl<E: Element, const L: usize> Pack for Lanes<E, L> {
    const WIDTH: usize = L;
    #[inline(always)]
    fn lane(self, l: usize) -> f64 {
        self.0[l].to_f64()
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        Self(std::array::from_fn(|l| E::from_f64(f(l))))
    }
    #[inline(always)]
    fn pick_where_greater(self, other: Self, if_greater: Self, otherwise: Self) -> Self {
        Self(std::array::from_fn(|l| {
            if other.0[l] > self.0[l] {
                if_greater.0[l]
            } else {
                otherwise.0[l]
            }
        }))
    }
}

/// A dual number with one direction over a pack of cells' values: the force
/// kernel evaluated on it gives the tangent's action on a vector for
/// [`Pack::WIDTH`] cells per pass ([`tangent_action_batch`]). Every operation
/// is [`Dual`]'s, in the same order, so each lane has the bits of the scalar
/// dual, except the barrier's law, which uses [`fast_ln`] as the force pass
/// does (within an ulp of libm's).
#[derive(Clone, Copy)]
pub(crate) struct PackDual<P> {
    v: P,
    g: P,
}

impl<P: Pack> Add for PackDual<P> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self {
            v: self.v + o.v,
            g: self.g + o.g,
        }
    }
}
impl<P: Pack> Sub for PackDual<P> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self {
            v: self.v - o.v,
            g: self.g - o.g,
        }
    }
}
// The product rule: the derivative of a product is a sum.
#[allow(clippy::suspicious_arithmetic_impl)]
impl<P: Pack> Mul for PackDual<P> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Self {
            v: self.v * o.v,
            g: self.g * o.v + o.g * self.v,
        }
    }
}
impl<P: Pack> Div for PackDual<P> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let v = self.v / o.v;
        let inv = P::cst(1.0) / o.v;
        Self {
            v,
            g: (self.g - v * o.g) * inv,
        }
    }
}
impl<P: Pack> Neg for PackDual<P> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self {
            v: -self.v,
            g: -self.g,
        }
    }
}
impl<P: Pack> AddAssign for PackDual<P> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<P: Pack> SubAssign for PackDual<P> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}
impl<P: Pack + SplitExponent> Scalar for PackDual<P> {
    #[inline(always)]
    fn cst(v: f64) -> Self {
        Self {
            v: P::cst(v),
            g: P::cst(0.0),
        }
    }
    #[inline(always)]
    fn scale(self, k: f64) -> Self {
        Self {
            v: self.v.scale(k),
            g: self.g.scale(k),
        }
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let d = P::cst(0.5) / s;
        Self {
            v: s,
            g: self.g * d,
        }
    }
    #[inline(always)]
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        let v = P::from_fn(|l| f(self.v.lane(l)).0);
        let d = P::from_fn(|l| f(self.v.lane(l)).1);
        Self { v, g: self.g * d }
    }
    #[inline(always)]
    fn barrier_slope(self) -> Self {
        // phi''(J) = (1 - ln J) / J^2 above the knee; below it the straight
        // continuation's slope, which is that expression at the knee.
        let above = self.v.at_least(P::cst(BARRIER_KNEE));
        let d = (P::cst(1.0) - fast_ln(above)) / (above * above);
        Self {
            v: fast_barrier_slope(self.v),
            g: self.g * d,
        }
    }
    #[inline(always)]
    fn at_least(self, o: Self) -> Self {
        Self {
            v: self.v.at_least(o.v),
            g: self.v.pick_where_greater(o.v, o.g, self.g),
        }
    }
    #[inline(always)]
    fn any_below(self, v: f64) -> bool {
        self.v.any_below(v)
    }
}

/// Cells evaluated together by [`forces_batch`] with AVX2.
pub(crate) const LANES: usize = 4;

/// The lattice edges whose stretch the pass over cells computes: the three
/// at each cell's corner 0 (`+x`, `+y`, `+z` from it), stored at that corner's
/// node. Every other edge is a leftover of the model ([`crate::Model`]'s edge
/// list), on the lattice's `+` faces.
pub(crate) const CORNER_EDGES: [(usize, usize); 3] = [(1, 0), (3, 1), (4, 2)];

/// The stretches ([`stretch`]) of the edges at corner 0 of each cell of
/// `cells`, `L` cells per pass, into `out` (one `[x, y, z]` per cell); the
/// lanes are filled by `gather` (corners 0, 1, 3 and 4 of `L` cells).
#[inline(always)]
fn edge_stretches_body<P: Pack + InverseSqrtSeed, const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
    gather: impl Fn(&[[u32; 8]], &[[f64; 3]]) -> [V3<P>; 4],
) {
    let groups = cells.len() / P::WIDTH;
    for (cg, og) in cells
        .chunks_exact(P::WIDTH)
        .zip(out.chunks_exact_mut(P::WIDTH))
    {
        let [origin, ends @ ..] = gather(cg, x);
        let w = corner_stretches::<_, SEED>(rest, origin, ends);
        for (l, o) in og.iter_mut().enumerate() {
            *o = [w[0].lane(l), w[1].lane(l), w[2].lane(l)];
        }
    }
    for (c, o) in cells[groups * P::WIDTH..]
        .iter()
        .zip(&mut out[groups * P::WIDTH..])
    {
        let mut ends = [[0.0; 3]; 3];
        for (e, &(corner, _)) in ends.iter_mut().zip(&CORNER_EDGES) {
            *e = x[c[corner] as usize];
        }
        *o = corner_stretches::<_, SEED>(rest, x[c[0] as usize], ends);
    }
}

/// The stretches of the three edges from `origin` to `ends` (along x, y, z),
/// with one division for the three ([`inverses3`]).
#[inline(always)]
fn corner_stretches<T: InverseSqrtSeed, const SEED: bool>(
    rest: f64,
    origin: V3<T>,
    ends: [V3<T>; 3],
) -> [T; 3] {
    if SEED {
        let mut w = [T::cst(0.0); 3];
        for (w, e) in w.iter_mut().zip(ends) {
            let d = sub(e, origin);
            *w = seeded_stretch(rest, dot(d, d));
        }
        return w;
    }
    let mut len = [T::cst(0.0); 3];
    for (l, e) in len.iter_mut().zip(ends) {
        let d = sub(e, origin);
        *l = dot(d, d).sqrt();
    }
    let mut w = inverses3(len);
    for w in &mut w {
        *w = T::cst(1.0) - w.scale(rest);
    }
    w
}

/// [`crate::Model::force_operations`] for cells of parameters `p`:
/// `seeded` for the single-precision pass, whose edges are stretched by
/// [`seeded_stretch`] and whose corners are taken relative to corner 0 in
/// `f64` (21 subtractions), narrowed (21 conversions) and whose forces are
/// widened (24).
pub(crate) fn force_operations(p: &CellParams, seeded: bool) -> crate::model::ForceOperations {
    use count::Counted;
    let mut ops = count::count(|| {
        let x: [V3<Counted>; 8] =
            std::array::from_fn(|n| CORNER_OFFSETS[n].map(|o| Counted(f64::from(o) * p.rest_edge)));
        let ends = [x[1], x[3], x[4]];
        let w = if seeded {
            corner_stretches::<_, true>(p.rest_edge, x[0], ends)
        } else {
            corner_stretches::<_, false>(p.rest_edge, x[0], ends)
        };
        let edge_stretch = [w[0]; 12];
        let mut f = [[Counted(0.0); 3]; 8];
        cell_forces_with_edges(p, &x, &edge_stretch, &mut f);
    });
    // The corner forces added into the node sums.
    ops.add += 24;
    if seeded {
        ops.add += 21;
        ops.other += 21 + 24;
    }
    ops
}

/// A cell's 8 corners, in order.
const ALL_CORNERS: [usize; 8] = [0, 1, 2, 3, 4, 5, 6, 7];

/// Corner 0 of a cell and the ends of its edges along x, y and z.
const EDGE_ENDS: [usize; 4] = [0, 1, 3, 4];

/// Corners 0, 1, 3 and 4 of `L` cells: the ends of their corner-0 edges.
#[inline(always)]
fn gather_edge_ends<const L: usize>(cells: &[[u32; 8]], x: &[[f64; 3]]) -> [V3<Lanes<f64, L>>; 4] {
    let mut xl: [V3<Lanes<f64, L>>; 4] = [[Lanes::cst(0.0); 3]; 4];
    for (&k, xk) in EDGE_ENDS.iter().zip(xl.iter_mut()) {
        for (l, cell) in cells.iter().enumerate() {
            let p = x[cell[k] as usize];
            xk[0].0[l] = p[0];
            xk[1].0[l] = p[1];
            xk[2].0[l] = p[2];
        }
    }
    xl
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn edge_stretches_avx2<const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    // The closure inherits this function's AVX2, so may call the AVX2
    // helpers safely.
    edge_stretches_body::<_, SEED>(rest, cells, x, out, |c, x| {
        // SAFETY: this closure runs inside an AVX2 function.
        unsafe { avx2::gather4(c, x, EDGE_ENDS) }
    });
}

/// [`edge_stretches_avx2`] eight cells per pass in AVX-512 registers, the
/// cells after the last whole eight four per pass (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
fn edge_stretches_avx512<const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    let whole = cells.len() / 8 * 8;
    let (out_head, out_tail) = out.split_at_mut(whole);
    // SAFETY (the closure): it runs inside this AVX-512 function.
    edge_stretches_body::<_, SEED>(rest, &cells[..whole], x, out_head, |c, x| unsafe {
        avx2::gather8_f64(c, x, EDGE_ENDS)
    });
    edge_stretches_avx2::<SEED>(rest, &cells[whole..], x, out_tail);
}

/// `out[i]` = the [`stretch`] of an edge along `d[i]` resting at `rest[i]`,
/// the same operations per edge as [`stretch`] (so the same bits), several
/// edges per SIMD operation where the CPU has AVX-512: the force pass's
/// edges on the lattice's `+` faces, which no cell has at its corner 0.
pub(crate) fn stretches<const SEED: bool>(rest: &[f64], d: &[[f64; 3]], out: &mut [f64]) {
    assert!(rest.len() == d.len() && d.len() == out.len());
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU has AVX-512F, DQ and VL (checked just above).
            unsafe { stretches_avx512::<SEED>(rest, d, out) };
            return;
        }
    }
    stretches_body::<SEED>(rest, d, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn stretches_avx512<const SEED: bool>(rest: &[f64], d: &[[f64; 3]], out: &mut [f64]) {
    stretches_body::<SEED>(rest, d, out);
}

#[inline(always)]
fn stretches_body<const SEED: bool>(rest: &[f64], d: &[[f64; 3]], out: &mut [f64]) {
    for ((o, d), rest) in out.iter_mut().zip(d).zip(rest) {
        *o = if SEED {
            seeded_stretch(*rest, dot(*d, *d))
        } else {
            stretch(*rest, *d)
        };
    }
}

/// [`edge_stretches_batch`] written straight into the edge stretches by node
/// `nodes` (each cell's at its corner 0), where the CPU runs the AVX-512
/// pass (returns false, having done nothing, where it does not): eight
/// cells in one row ([`avx2::in_one_row`]) load their four corners as runs
/// of nodes and store their 24 stretches as one run, instead of gathering
/// each corner and writing each lane's stretches apart. The same bits.
///
/// # Safety
/// `nodes` points to one `[f64; 3]` per node of `x`, and no other thread
/// accesses those of the corners 0 of `cells` meanwhile.
pub(crate) unsafe fn edge_stretches_into_nodes<const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    buf: &mut [[f64; 3]],
    nodes: *mut [f64; 3],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU has AVX-512F, DQ and VL (checked); `nodes` is
            // this function's contract.
            unsafe { edge_stretches_into_nodes_avx512::<SEED>(rest, cells, x, buf, nodes) };
            return true;
        }
    }
    let _ = (rest, cells, x, buf, nodes);
    false
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn edge_stretches_into_nodes_avx512<const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    buf: &mut [[f64; 3]],
    nodes: *mut [f64; 3],
) {
    use std::arch::x86_64::_mm512_storeu_pd;
    assert!(buf.len() >= cells.len());
    let write = |cells: &[[u32; 8]], w: &[[f64; 3]]| {
        for (cell, w) in cells.iter().zip(w) {
            // SAFETY: the caller's contract; corner 0 is a node of `x`.
            unsafe { *nodes.add(cell[0] as usize) = *w };
        }
    };
    let whole = cells.len() / 8 * 8;
    for group in cells[..whole].chunks_exact(8) {
        // SAFETY: this function runs with AVX-512; in a row, corner `k`'s
        // eight nodes are `group[0][k]` on (nodes of `x`), and corner 0's
        // are these cells' alone (the caller's contract).
        unsafe {
            if avx2::in_one_row(group) {
                let c0 = group[0];
                assert!(c0.iter().all(|&n| n as usize + 8 <= x.len()));
                let run = |k: usize| avx2::components(x.as_ptr().add(c0[k] as usize).cast());
                let [origin, ends @ ..] = EDGE_ENDS.map(run);
                let w = avx2::interleave(&corner_stretches::<_, SEED>(rest, origin, ends));
                let o = nodes.add(c0[0] as usize).cast::<f64>();
                _mm512_storeu_pd(o, w[0]);
                _mm512_storeu_pd(o.add(8), w[1]);
                _mm512_storeu_pd(o.add(16), w[2]);
            } else {
                edge_stretches_avx512::<SEED>(rest, group, x, &mut buf[..8]);
                write(group, &buf[..8]);
            }
        }
    }
    let tail = &cells[whole..];
    if !tail.is_empty() {
        let w = &mut buf[..tail.len()];
        edge_stretches_avx2::<SEED>(rest, tail, x, w);
        write(tail, w);
    }
}

/// [`edge_stretches_batch`] one cell at a time, without SIMD: the same
/// operations per cell, so the same bits.
pub(crate) fn edge_stretches_scalar<const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    edge_stretches_body::<_, SEED>(rest, cells, x, out, gather_edge_ends::<1>);
}

/// The stretches of the edges at corner 0 of consecutive cells whose edges
/// rest at `rest`, several cells per SIMD pass (AVX2 when the CPU has it):
/// bitwise what [`cell_forces`] computes for the same edges.
pub(crate) fn edge_stretches_batch<const SEED: bool>(
    rest: f64,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    out: &mut [[f64; 3]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, DQ and VL (checked just
            // above), and with them AVX2.
            unsafe { edge_stretches_avx512::<SEED>(rest, cells, x, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { edge_stretches_avx2::<SEED>(rest, cells, x, out) };
            return;
        }
    }
    edge_stretches_body::<_, SEED>(rest, cells, x, out, gather_edge_ends::<LANES>);
}

/// Gathers the 8 corners of `L` cells into lanes (portable path).
#[inline(always)]
fn gather_corners<const L: usize>(cells: &[[u32; 8]], x: &[[f64; 3]]) -> [V3<Lanes<f64, L>>; 8] {
    let mut xl: [V3<Lanes<f64, L>>; 8] = [[Lanes::cst(0.0); 3]; 8];
    for (k, xk) in xl.iter_mut().enumerate() {
        for (l, cell) in cells.iter().enumerate() {
            let p = x[cell[k] as usize];
            xk[0].0[l] = p[0];
            xk[1].0[l] = p[1];
            xk[2].0[l] = p[2];
        }
    }
    xl
}

/// The stretches of the 12 edges of `L` cells (in [`CELL_EDGES`] order) from
/// the lattice's edge stretches by node, rounded to `E` (portable path).
#[inline(always)]
fn gather_edges<E: Element, const L: usize>(
    cells: &[[u32; 8]],
    edges: &[[f64; 3]],
) -> [Lanes<E, L>; 12] {
    let mut wl = [Lanes::cst(0.0); 12];
    for (w, &(a, _, ax)) in wl.iter_mut().zip(&CELL_EDGES) {
        for (l, cell) in cells.iter().enumerate() {
            w.0[l] = E::from_f64(edges[cell[a] as usize][ax]);
        }
    }
    wl
}

/// The corners an edge of a cell starts from (all but corner 6), and where
/// each corner is in that list.
const EDGE_STARTS: [usize; 7] = [0, 1, 2, 3, 4, 5, 7];
const EDGE_START_INDEX: [usize; 8] = [0, 1, 2, 3, 4, 5, 99, 6];

/// The forces of one cell of parameters `p` given the lattice's edge
/// stretches by node: what the batched kernel computes for it.
pub(crate) fn cell_forces_from_edges(
    p: &CellParams,
    cell: &[u32; 8],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
) -> [[f64; 3]; 8] {
    let xc: [V3<f64>; 8] = std::array::from_fn(|k| x[cell[k] as usize]);
    let w: [f64; 12] = std::array::from_fn(|e| {
        let (a, _, ax) = CELL_EDGES[e];
        edges[cell[a] as usize][ax]
    });
    let mut f = [[0.0; 3]; 8];
    cell_forces_with_edges(p, &xc, &w, &mut f);
    f
}

/// Writes the lanes' corner forces out cell by cell as `f64`, `out[8 l + k]`
/// for corner `k` of cell `l` (portable path).
#[inline(always)]
fn scatter_corners<E: Element, const L: usize>(f: &[V3<Lanes<E, L>>; 8], out: &mut [[f64; 4]]) {
    for l in 0..L {
        for k in 0..8 {
            let c = |d: usize| f[k][d].0[l].to_f64();
            out[8 * l + k] = [c(0), c(1), c(2), 0.0];
        }
    }
}

/// The same data movement as [`gather_corners`] and [`scatter_corners`] for
/// four cells with AVX2 shuffles: a corner of the four cells is four 32-byte
/// loads and a 4 x 4 transpose instead of twelve scalar loads and stores
/// through memory, which were most of the kernel's time.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{Pack, Scalar, SplitExponent, V3};
    use std::arch::x86_64::*;
    use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

    /// Defines one AVX register type of `$n` lanes of `$e`, with every
    /// operation an explicit AVX instruction: written as plain loops over
    /// arrays ([`super::Lanes`]), the compiler vectorized some passes across
    /// the wrong dimension (the three edges of a node, in 2-wide halves,
    /// with shuffles) and left others scalar.
    ///
    /// Values of these types are made only inside this module's
    /// `#[target_feature(enable = "avx2")]` functions, reached only after
    /// the CPU was checked: that is what makes the intrinsics sound (each
    /// operation is inlined into those functions).
    macro_rules! avx_vector {
        (
            $(#[$doc:meta])* $name:ident($reg:ty, $e:ty, $n:literal),
            add $add:ident, sub $sub:ident, mul $mul:ident, div $div:ident,
            xor $xor:ident, set1 $set1:ident, sqrt $sqrt:ident,
            load $load:ident, store $store:ident, max $max:ident, split $split:ident,
            cmp $cmp:ident, movemask $movemask:ident, blend $blend:ident
        ) => {
            $(#[$doc])*
            #[derive(Clone, Copy)]
            pub(super) struct $name($reg);

            avx_vector!(@binary $name, Add, add, $add);
            avx_vector!(@binary $name, Sub, sub, $sub);
            avx_vector!(@binary $name, Mul, mul, $mul);
            avx_vector!(@binary $name, Div, div, $div);

            impl Neg for $name {
                type Output = Self;
                #[inline(always)]
                fn neg(self) -> Self {
                    // Flips the sign bit, as scalar negation does (0 - x
                    // would turn +0 into +0 instead of -0).
                    // SAFETY: AVX is available (see `avx_vector`).
                    Self(unsafe { $xor(self.0, $set1(-0.0)) })
                }
            }
            impl AddAssign for $name {
                #[inline(always)]
                fn add_assign(&mut self, o: Self) {
                    *self = *self + o;
                }
            }
            impl SubAssign for $name {
                #[inline(always)]
                fn sub_assign(&mut self, o: Self) {
                    *self = *self - o;
                }
            }
            impl $name {
                #[inline(always)]
                fn to_array(self) -> [$e; $n] {
                    let mut r = [0.0; $n];
                    // SAFETY: AVX is available (see `avx_vector`); `r`
                    // holds one register's worth of lanes.
                    unsafe { $store(r.as_mut_ptr(), self.0) };
                    r
                }
            }
            impl Scalar for $name {
                #[inline(always)]
                fn cst(v: f64) -> Self {
                    // SAFETY: AVX is available (see `avx_vector`).
                    Self(unsafe { $set1(v as $e) })
                }
                #[inline(always)]
                fn scale(self, k: f64) -> Self {
                    self * Self::cst(k)
                }
                #[inline(always)]
                fn sqrt(self) -> Self {
                    // SAFETY: AVX is available (see `avx_vector`).
                    Self(unsafe { $sqrt(self.0) })
                }
                #[inline(always)]
                fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
                    let mut r = self.to_array();
                    for v in &mut r {
                        *v = f(f64::from(*v)).0 as $e;
                    }
                    // SAFETY: AVX is available (see `avx_vector`); `r`
                    // holds one register's worth of lanes.
                    Self(unsafe { $load(r.as_ptr()) })
                }
                #[inline(always)]
                fn barrier_slope(self) -> Self {
                    super::fast_barrier_slope(self)
                }
                #[inline(always)]
                fn at_least(self, o: Self) -> Self {
                    // SAFETY: AVX is available (see `avx_vector`).
                    Self(unsafe { $max(o.0, self.0) })
                }
                #[inline(always)]
                fn any_below(self, v: f64) -> bool {
                    // SAFETY: AVX is available (see `avx_vector`).
                    unsafe { $movemask($cmp::<_CMP_LT_OQ>(self.0, $set1(v as $e))) != 0 }
                }
            }
            impl SplitExponent for $name {
                #[inline(always)]
                fn split_exponent(self) -> (Self, Self) {
                    // SAFETY: AVX2 is available (see `avx_vector`).
                    let (m, k) = unsafe { $split(self.0) };
                    (Self(m), Self(k))
                }
            }
            impl Pack for $name {
                const WIDTH: usize = $n;
                #[inline(always)]
                fn lane(self, l: usize) -> f64 {
                    f64::from(self.to_array()[l])
                }
                #[inline(always)]
                fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                    let r: [$e; $n] = std::array::from_fn(|l| f(l) as $e);
                    // SAFETY: AVX is available (see `avx_vector`); `r`
                    // holds one register's worth of lanes.
                    Self(unsafe { $load(r.as_ptr()) })
                }
                #[inline(always)]
                fn pick_where_greater(self, other: Self, if_greater: Self, otherwise: Self) -> Self {
                    // SAFETY: AVX is available (see `avx_vector`).
                    Self(unsafe {
                        $blend(otherwise.0, if_greater.0, $cmp::<_CMP_GT_OQ>(other.0, self.0))
                    })
                }
            }
        };
        (@binary $name:ident, $tr:ident, $f:ident, $intr:ident) => {
            impl $tr for $name {
                type Output = Self;
                #[inline(always)]
                fn $f(self, o: Self) -> Self {
                    // SAFETY: AVX is available (see `avx_vector`).
                    Self(unsafe { $intr(self.0, o.0) })
                }
            }
        };
    }

    avx_vector!(
        /// Four cells' values in double precision, one AVX register.
        F64x4(__m256d, f64, 4),
        add _mm256_add_pd, sub _mm256_sub_pd, mul _mm256_mul_pd, div _mm256_div_pd,
        xor _mm256_xor_pd, set1 _mm256_set1_pd, sqrt _mm256_sqrt_pd,
        load _mm256_loadu_pd, store _mm256_storeu_pd, max _mm256_max_pd, split split_f64x4,
        cmp _mm256_cmp_pd, movemask _mm256_movemask_pd, blend _mm256_blendv_pd
    );
    avx_vector!(
        /// Eight cells' values in single precision, one AVX register.
        F32x8(__m256, f32, 8),
        add _mm256_add_ps, sub _mm256_sub_ps, mul _mm256_mul_ps, div _mm256_div_ps,
        xor _mm256_xor_ps, set1 _mm256_set1_ps, sqrt _mm256_sqrt_ps,
        load _mm256_loadu_ps, store _mm256_storeu_ps, max _mm256_max_ps, split split_f32x8,
        cmp _mm256_cmp_ps, movemask _mm256_movemask_ps, blend _mm256_blendv_ps
    );

    avx_vector!(
        /// Eight cells' values in double precision, one AVX-512 register
        /// (made only inside functions that enable AVX-512F and DQ).
        F64x8(__m512d, f64, 8),
        add _mm512_add_pd, sub _mm512_sub_pd, mul _mm512_mul_pd, div _mm512_div_pd,
        xor _mm512_xor_pd, set1 _mm512_set1_pd, sqrt _mm512_sqrt_pd,
        load _mm512_loadu_pd, store _mm512_storeu_pd, max _mm512_max_pd, split split_f64x8,
        cmp cmp_f64x8, movemask mask_bits, blend blend_f64x8
    );

    avx_vector!(
        /// Sixteen cells' values in single precision, one AVX-512 register
        /// (made only inside functions that enable AVX-512F and DQ).
        F32x16(__m512, f32, 16),
        add _mm512_add_ps, sub _mm512_sub_ps, mul _mm512_mul_ps, div _mm512_div_ps,
        xor _mm512_xor_ps, set1 _mm512_set1_ps, sqrt _mm512_sqrt_ps,
        load _mm512_loadu_ps, store _mm512_storeu_ps, max _mm512_max_ps, split split_f32x16,
        cmp cmp_f32x16, movemask mask_bits16, blend blend_f32x16
    );

    // The inverse square root's seed: four or eight lanes converted to
    // single precision, their root and reciprocal taken there (a quarter of
    // the double-precision root's cost per lane on AVX-512), and widened.
    impl super::InverseSqrtSeed for F64x4 {
        #[inline(always)]
        fn inverse_sqrt_seed(self) -> Self {
            // SAFETY: AVX is available (see `avx_vector`).
            unsafe {
                let root = _mm_sqrt_ps(_mm256_cvtpd_ps(self.0));
                Self(_mm256_cvtps_pd(_mm_div_ps(_mm_set1_ps(1.0), root)))
            }
        }
    }

    impl super::InverseSqrtSeed for F64x8 {
        #[inline(always)]
        fn inverse_sqrt_seed(self) -> Self {
            // SAFETY: AVX-512F is available (F64x8 is made only where it is).
            unsafe {
                let root = _mm256_sqrt_ps(_mm512_cvtpd_ps(self.0));
                Self(_mm512_cvtps_pd(_mm256_div_ps(_mm256_set1_ps(1.0), root)))
            }
        }
    }

    /// An AVX-512 register made of two AVX2 ones: the moves of its cells
    /// in and out are those of each half's cells.
    trait Doubled: Copy {
        /// The half register.
        type Half: Copy;
        /// The register whose low lanes are `lo`'s, its high lanes `hi`'s.
        ///
        /// # Safety
        /// AVX-512F and DQ are available.
        unsafe fn join(lo: Self::Half, hi: Self::Half) -> Self;
        /// The low and the high half.
        ///
        /// # Safety
        /// AVX-512F and DQ are available.
        unsafe fn halves(self) -> (Self::Half, Self::Half);
    }

    impl Doubled for F64x8 {
        type Half = F64x4;
        #[inline(always)]
        unsafe fn join(lo: F64x4, hi: F64x4) -> Self {
            // SAFETY: the caller runs where AVX-512F is available.
            unsafe { F64x8(_mm512_insertf64x4::<1>(_mm512_castpd256_pd512(lo.0), hi.0)) }
        }
        #[inline(always)]
        unsafe fn halves(self) -> (F64x4, F64x4) {
            // SAFETY: the caller runs where AVX-512F is available.
            unsafe {
                (
                    F64x4(_mm512_castpd512_pd256(self.0)),
                    F64x4(_mm512_extractf64x4_pd::<1>(self.0)),
                )
            }
        }
    }

    impl Doubled for F32x16 {
        type Half = F32x8;
        #[inline(always)]
        unsafe fn join(lo: F32x8, hi: F32x8) -> Self {
            // SAFETY: the caller runs where AVX-512F and DQ are available.
            unsafe { F32x16(_mm512_insertf32x8::<1>(_mm512_castps256_ps512(lo.0), hi.0)) }
        }
        #[inline(always)]
        unsafe fn halves(self) -> (F32x8, F32x8) {
            // SAFETY: the caller runs where AVX-512F and DQ are available.
            unsafe {
                (
                    F32x8(_mm512_castps512_ps256(self.0)),
                    F32x8(_mm512_extractf32x8_ps::<1>(self.0)),
                )
            }
        }
    }

    // The moves below take and give halves rather than calling a gather
    // or scatter passed in: a closure made outside a `target_feature`
    // function does not inherit its instruction sets, and the intrinsics
    // in it became calls (three times slower).

    /// The corners of a doubled register's cells from those of each half.
    #[inline(always)]
    unsafe fn join_corners<D: Doubled, const K: usize>(
        lo: [V3<D::Half>; K],
        hi: [V3<D::Half>; K],
    ) -> [V3<D>; K] {
        // SAFETY: the caller runs where AVX-512F and DQ are available.
        unsafe {
            let mut xl = [[D::join(lo[0][0], hi[0][0]); 3]; K];
            for (k, xk) in xl.iter_mut().enumerate() {
                for (c, v) in xk.iter_mut().enumerate() {
                    *v = D::join(lo[k][c], hi[k][c]);
                }
            }
            xl
        }
    }

    /// The 12 edge stretches of a doubled register's cells from those of
    /// each half.
    #[inline(always)]
    unsafe fn join_edges<D: Doubled>(lo: [D::Half; 12], hi: [D::Half; 12]) -> [D; 12] {
        // SAFETY: the caller runs where AVX-512F and DQ are available.
        unsafe {
            let mut w = [D::join(lo[0], hi[0]); 12];
            for ((w, lo), hi) in w.iter_mut().zip(lo).zip(hi) {
                *w = D::join(lo, hi);
            }
            w
        }
    }

    /// Corner vectors of a doubled register's cells as those of each half.
    #[inline(always)]
    unsafe fn split_corners<D: Doubled>(f: &[V3<D>; 8]) -> [[V3<D::Half>; 8]; 2] {
        // SAFETY: the caller runs where AVX-512F and DQ are available.
        unsafe {
            let first = f[0][0].halves().0;
            let (mut lo, mut hi) = ([[first; 3]; 8], [[first; 3]; 8]);
            for k in 0..8 {
                for c in 0..3 {
                    (lo[k][c], hi[k][c]) = f[k][c].halves();
                }
            }
            [lo, hi]
        }
    }

    /// Corners `corners` of eight cells in `f64`: [`gather4`] of each half.
    #[inline(always)]
    pub(super) unsafe fn gather8_f64<const K: usize>(
        cells: &[[u32; 8]],
        x: &[[f64; 3]],
        corners: [usize; K],
    ) -> [V3<F64x8>; K] {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe {
            join_corners::<F64x8, K>(
                gather4(&cells[..4], x, corners),
                gather4(&cells[4..], x, corners),
            )
        }
    }

    /// The 12 edge stretches of eight cells in `f64`: [`gather_edges4`] of
    /// each half.
    #[inline(always)]
    pub(super) unsafe fn gather_edges8_f64(cells: &[[u32; 8]], edges: &[[f64; 3]]) -> [F64x8; 12] {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe {
            join_edges::<F64x8>(
                gather_edges4(&cells[..4], edges),
                gather_edges4(&cells[4..], edges),
            )
        }
    }

    /// Corner forces of eight cells in `f64`: [`scatter4`] of each half.
    #[inline(always)]
    pub(super) unsafe fn scatter8_f64(f: &[V3<F64x8>; 8], out: &mut [[f64; 4]]) {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe {
            let [lo, hi] = split_corners(f);
            let (first, second) = out.split_at_mut(32);
            scatter4(&lo, first);
            scatter4(&hi, second);
        }
    }

    /// [`gather8_relative`] of sixteen cells: each half.
    #[inline(always)]
    pub(super) unsafe fn gather16_relative(cells: &[[u32; 8]], x: &[[f64; 3]]) -> [V3<F32x16>; 8] {
        // SAFETY: the caller runs where AVX-512F and DQ are available.
        unsafe {
            join_corners::<F32x16, 8>(
                gather8_relative(&cells[..8], x),
                gather8_relative(&cells[8..], x),
            )
        }
    }

    /// [`gather_edges8`] of sixteen cells: each half.
    #[inline(always)]
    pub(super) unsafe fn gather_edges16(cells: &[[u32; 8]], edges: &[[f64; 3]]) -> [F32x16; 12] {
        // SAFETY: the caller runs where AVX-512F and DQ are available.
        unsafe {
            join_edges::<F32x16>(
                gather_edges8(&cells[..8], edges),
                gather_edges8(&cells[8..], edges),
            )
        }
    }

    /// Corner forces of sixteen cells: [`scatter8`] of each half.
    #[inline(always)]
    pub(super) unsafe fn scatter16(f: &[V3<F32x16>; 8], out: &mut [[f64; 4]]) {
        // SAFETY: the caller runs where AVX-512F and DQ are available.
        unsafe {
            let [lo, hi] = split_corners(f);
            let (first, second) = out.split_at_mut(64);
            scatter8(&lo, first);
            scatter8(&hi, second);
        }
    }

    /// AVX-512's comparison of sixteen `f32`, into a mask register.
    #[inline(always)]
    unsafe fn cmp_f32x16<const P: i32>(a: __m512, b: __m512) -> __mmask16 {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe { _mm512_cmp_ps_mask::<P>(a, b) }
    }

    /// The mask's bits (AVX2's `movemask` of a comparison).
    #[inline(always)]
    unsafe fn mask_bits16(m: __mmask16) -> i32 {
        i32::from(m)
    }

    /// `b` where `m` is set, else `a`.
    #[inline(always)]
    unsafe fn blend_f32x16(a: __m512, b: __m512, m: __mmask16) -> __m512 {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe { _mm512_mask_blend_ps(m, a, b) }
    }

    /// [`split_f32x8`] on sixteen lanes: the same operations, so the same
    /// bits.
    #[inline(always)]
    unsafe fn split_f32x16(x: __m512) -> (__m512, __m512) {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe {
            let bits = _mm512_castps_si512(x);
            let biased = _mm512_and_si512(_mm512_srli_epi32::<23>(bits), _mm512_set1_epi32(0xff));
            let k = _mm512_sub_ps(_mm512_cvtepi32_ps(biased), _mm512_set1_ps(127.0));
            let mantissa = _mm512_and_si512(bits, _mm512_set1_epi32((1 << 23) - 1));
            let m = _mm512_castsi512_ps(_mm512_or_si512(
                mantissa,
                _mm512_castps_si512(_mm512_set1_ps(1.0)),
            ));
            let big = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(m, _mm512_set1_ps(std::f32::consts::SQRT_2));
            let m = _mm512_mask_blend_ps(big, m, _mm512_mul_ps(m, _mm512_set1_ps(0.5)));
            let k = _mm512_add_ps(k, _mm512_maskz_mov_ps(big, _mm512_set1_ps(1.0)));
            (m, k)
        }
    }

    /// AVX-512's comparison, into a mask register.
    #[inline(always)]
    unsafe fn cmp_f64x8<const P: i32>(a: __m512d, b: __m512d) -> __mmask8 {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe { _mm512_cmp_pd_mask::<P>(a, b) }
    }

    /// The mask's bits (AVX2's `movemask` of a comparison).
    #[inline(always)]
    unsafe fn mask_bits(m: __mmask8) -> i32 {
        i32::from(m)
    }

    /// `b` where `m` is set, else `a` (AVX2's `blendv` with a mask
    /// register).
    #[inline(always)]
    unsafe fn blend_f64x8(a: __m512d, b: __m512d, m: __mmask8) -> __m512d {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe { _mm512_mask_blend_pd(m, a, b) }
    }

    /// [`split_f64x4`] on eight lanes: the same operations, so the same
    /// bits.
    #[inline(always)]
    unsafe fn split_f64x8(x: __m512d) -> (__m512d, __m512d) {
        const TWO_52: f64 = 4_503_599_627_370_496.0;
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe {
            let bits = _mm512_castpd_si512(x);
            let biased = _mm512_and_si512(_mm512_srli_epi64::<52>(bits), _mm512_set1_epi64(0x7ff));
            let with_two_52 = _mm512_or_si512(biased, _mm512_castpd_si512(_mm512_set1_pd(TWO_52)));
            let k = _mm512_sub_pd(
                _mm512_castsi512_pd(with_two_52),
                _mm512_set1_pd(TWO_52 + 1023.0),
            );
            let mantissa = _mm512_and_si512(bits, _mm512_set1_epi64((1 << 52) - 1));
            let m = _mm512_castsi512_pd(_mm512_or_si512(
                mantissa,
                _mm512_castpd_si512(_mm512_set1_pd(1.0)),
            ));
            let big = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(m, _mm512_set1_pd(std::f64::consts::SQRT_2));
            let m = _mm512_mask_blend_pd(big, m, _mm512_mul_pd(m, _mm512_set1_pd(0.5)));
            let one_where_big = _mm512_maskz_mov_pd(big, _mm512_set1_pd(1.0));
            let k = _mm512_add_pd(k, one_where_big);
            (m, k)
        }
    }

    /// [`SplitExponent::split_exponent`] of four `f64`, with the same bits
    /// as the scalar one: the biased exponent is moved into the mantissa of
    /// `2^52` (exact), the mantissa given the exponent of 1.
    #[inline(always)]
    unsafe fn split_f64x4(x: __m256d) -> (__m256d, __m256d) {
        const TWO_52: f64 = 4_503_599_627_370_496.0;
        // SAFETY: the caller runs where AVX2 is available.
        unsafe {
            let bits = _mm256_castpd_si256(x);
            let biased = _mm256_and_si256(_mm256_srli_epi64::<52>(bits), _mm256_set1_epi64x(0x7ff));
            let with_two_52 = _mm256_or_si256(biased, _mm256_castpd_si256(_mm256_set1_pd(TWO_52)));
            let k = _mm256_sub_pd(
                _mm256_castsi256_pd(with_two_52),
                _mm256_set1_pd(TWO_52 + 1023.0),
            );
            let mantissa = _mm256_and_si256(bits, _mm256_set1_epi64x((1 << 52) - 1));
            let m = _mm256_castsi256_pd(_mm256_or_si256(
                mantissa,
                _mm256_castpd_si256(_mm256_set1_pd(1.0)),
            ));
            let big = _mm256_cmp_pd::<_CMP_GT_OQ>(m, _mm256_set1_pd(std::f64::consts::SQRT_2));
            let m = _mm256_blendv_pd(m, _mm256_mul_pd(m, _mm256_set1_pd(0.5)), big);
            let k = _mm256_add_pd(k, _mm256_and_pd(big, _mm256_set1_pd(1.0)));
            (m, k)
        }
    }

    /// [`SplitExponent::split_exponent`] of eight `f32` (the exponent
    /// converted from a 32-bit integer, exact).
    #[inline(always)]
    unsafe fn split_f32x8(x: __m256) -> (__m256, __m256) {
        // SAFETY: the caller runs where AVX2 is available.
        unsafe {
            let bits = _mm256_castps_si256(x);
            let biased = _mm256_and_si256(_mm256_srli_epi32::<23>(bits), _mm256_set1_epi32(0xff));
            let k = _mm256_sub_ps(_mm256_cvtepi32_ps(biased), _mm256_set1_ps(127.0));
            let mantissa = _mm256_and_si256(bits, _mm256_set1_epi32((1 << 23) - 1));
            let m = _mm256_castsi256_ps(_mm256_or_si256(
                mantissa,
                _mm256_castps_si256(_mm256_set1_ps(1.0)),
            ));
            let big = _mm256_cmp_ps::<_CMP_GT_OQ>(m, _mm256_set1_ps(std::f32::consts::SQRT_2));
            let m = _mm256_blendv_ps(m, _mm256_mul_ps(m, _mm256_set1_ps(0.5)), big);
            let k = _mm256_add_ps(k, _mm256_and_ps(big, _mm256_set1_ps(1.0)));
            (m, k)
        }
    }

    /// Two halves of four `f64` lanes rounded into eight `f32` lanes.
    #[inline(always)]
    unsafe fn narrow(lo: __m256d, hi: __m256d) -> F32x8 {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe { F32x8(_mm256_set_m128(_mm256_cvtpd_ps(hi), _mm256_cvtpd_ps(lo))) }
    }

    /// The 8 corners of eight cells relative to each cell's corner 0, in
    /// `f32` (differences taken in `f64`).
    #[inline(always)]
    pub(super) unsafe fn gather8_relative(cells: &[[u32; 8]], x: &[[f64; 3]]) -> [V3<F32x8>; 8] {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            let lo = gather4(&cells[..4], x, super::ALL_CORNERS);
            let hi = gather4(&cells[4..], x, super::ALL_CORNERS);
            let zero = F32x8(_mm256_setzero_ps());
            let mut xl = [[zero; 3]; 8];
            for (k, xk) in xl.iter_mut().enumerate() {
                for (c, v) in xk.iter_mut().enumerate() {
                    *v = narrow(
                        _mm256_sub_pd(lo[k][c].0, lo[0][c].0),
                        _mm256_sub_pd(hi[k][c].0, hi[0][c].0),
                    );
                }
            }
            xl
        }
    }

    /// The 12 edge stretches of eight cells, in `f32`.
    #[inline(always)]
    pub(super) unsafe fn gather_edges8(cells: &[[u32; 8]], edges: &[[f64; 3]]) -> [F32x8; 12] {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            let lo = gather_edges4(&cells[..4], edges);
            let hi = gather_edges4(&cells[4..], edges);
            let mut w = [F32x8(_mm256_setzero_ps()); 12];
            for ((w, lo), hi) in w.iter_mut().zip(lo).zip(hi) {
                *w = narrow(lo.0, hi.0);
            }
            w
        }
    }

    /// Corner forces of eight cells out of `f32` vectors, as `f64`.
    #[inline(always)]
    pub(super) unsafe fn scatter8(f: &[V3<F32x8>; 8], out: &mut [[f64; 4]]) {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            assert!(out.len() >= 64);
            let zero = F64x4(_mm256_setzero_pd());
            let (mut lo, mut hi) = ([[zero; 3]; 8], [[zero; 3]; 8]);
            for k in 0..8 {
                for c in 0..3 {
                    let v = f[k][c].0;
                    lo[k][c] = F64x4(_mm256_cvtps_pd(_mm256_castps256_ps128(v)));
                    hi[k][c] = F64x4(_mm256_cvtps_pd(_mm256_extractf128_ps(v, 1)));
                }
            }
            let (first, second) = out.split_at_mut(32);
            scatter4(&lo, first);
            scatter4(&hi, second);
        }
    }

    /// Whether eight cells lie side by side along x in one row of the
    /// lattice, numbered like their nodes: cell `l`'s corner `k` is cell
    /// 0's plus `l`, and each `+x` corner follows its `-x` corner. Their
    /// corners then form four runs of nine consecutive nodes ([`row_corners`],
    /// [`add_rows`]).
    #[inline(always)]
    pub(super) unsafe fn in_one_row(cells: &[[u32; 8]]) -> bool {
        // SAFETY: the caller runs where AVX2 is available; `cells` holds
        // eight cells of 8 u32 (32 bytes each), asserted.
        unsafe {
            assert!(cells.len() >= 8);
            let c0 = cells[0];
            if c0[1] != c0[0] + 1 || c0[2] != c0[3] + 1 || c0[5] != c0[4] + 1 || c0[6] != c0[7] + 1
            {
                return false;
            }
            let first = _mm256_loadu_si256(cells.as_ptr().cast());
            let mut all = -1i32;
            for (l, cell) in cells.iter().enumerate().take(8).skip(1) {
                let want = _mm256_add_epi32(first, _mm256_set1_epi32(l as i32));
                let got = _mm256_loadu_si256(cell.as_ptr().cast());
                all &= _mm256_movemask_epi8(_mm256_cmpeq_epi32(got, want));
            }
            all == -1
        }
    }

    /// Component `C` of eight consecutive nodes' `[f64; 3]` from `p`, as the
    /// lanes of one register (three loads, two permutations).
    #[inline(always)]
    unsafe fn component<const C: usize>(p: *const f64) -> __m512d {
        // SAFETY: the caller runs where AVX-512F is available, and `p`
        // points to 24 readable f64 (this function's contract).
        unsafe {
            let (a, b, c) = (
                _mm512_loadu_pd(p),
                _mm512_loadu_pd(p.add(8)),
                _mm512_loadu_pd(p.add(16)),
            );
            // Element 3 l + C of the 24 for lane l: from `a` and `b` first
            // (indices 8-15 pick `b`), then the last lanes from `c`.
            let (first, second) = match C {
                0 => (
                    _mm512_setr_epi64(0, 3, 6, 9, 12, 15, 0, 0),
                    _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 10, 13),
                ),
                1 => (
                    _mm512_setr_epi64(1, 4, 7, 10, 13, 0, 0, 0),
                    _mm512_setr_epi64(0, 1, 2, 3, 4, 8, 11, 14),
                ),
                _ => (
                    _mm512_setr_epi64(2, 5, 8, 11, 14, 0, 0, 0),
                    _mm512_setr_epi64(0, 1, 2, 3, 4, 9, 12, 15),
                ),
            };
            _mm512_permutex2var_pd(_mm512_permutex2var_pd(a, first, b), second, c)
        }
    }

    /// The three components of eight consecutive nodes from `p`.
    #[inline(always)]
    pub(super) unsafe fn components(p: *const f64) -> V3<F64x8> {
        // SAFETY: this function's contract is `component`'s.
        unsafe {
            [
                F64x8(component::<0>(p)),
                F64x8(component::<1>(p)),
                F64x8(component::<2>(p)),
            ]
        }
    }

    /// The corners of eight cells that lie in one row ([`in_one_row`]): the
    /// same values as [`gather8_f64`], loaded as runs of nodes.
    #[inline(always)]
    pub(super) unsafe fn row_corners(cells: &[[u32; 8]], x: &[[f64; 3]]) -> [V3<F64x8>; 8] {
        // SAFETY: the caller runs where AVX-512F is available and checked
        // `in_one_row(cells)`: each corner's nodes are the nine from its
        // cell 0's, which exist (cell 7's corners are nodes of `x`),
        // asserted.
        unsafe {
            let c0 = cells[0];
            assert!(c0.iter().all(|&n| n as usize + 8 <= x.len()));
            let run = |n: u32| x.as_ptr().add(n as usize).cast::<f64>();
            let mut xl = [[F64x8(_mm512_setzero_pd()); 3]; 8];
            for (k, xk) in xl.iter_mut().enumerate() {
                *xk = components(run(c0[k]));
            }
            xl
        }
    }

    /// The 12 edge stretches of eight cells in one row: the same values as
    /// [`gather_edges8_f64`].
    #[inline(always)]
    pub(super) unsafe fn row_edges(cells: &[[u32; 8]], edges: &[[f64; 3]]) -> [F64x8; 12] {
        // SAFETY: as `row_corners`.
        unsafe {
            let c0 = cells[0];
            assert!(c0.iter().all(|&n| n as usize + 8 <= edges.len()));
            let run = |k: usize| edges.as_ptr().add(c0[k] as usize).cast::<f64>();
            // Edge e runs from corner CELL_EDGES[e].0 along CELL_EDGES[e].2.
            [
                F64x8(component::<0>(run(0))),
                F64x8(component::<0>(run(3))),
                F64x8(component::<0>(run(4))),
                F64x8(component::<0>(run(7))),
                F64x8(component::<1>(run(0))),
                F64x8(component::<1>(run(1))),
                F64x8(component::<1>(run(4))),
                F64x8(component::<1>(run(5))),
                F64x8(component::<2>(run(0))),
                F64x8(component::<2>(run(1))),
                F64x8(component::<2>(run(2))),
                F64x8(component::<2>(run(3))),
            ]
        }
    }

    /// Eight lanes of `[x, y, z]` as 24 consecutive f64 (three registers).
    #[inline(always)]
    pub(super) unsafe fn interleave(v: &V3<F64x8>) -> [__m512d; 3] {
        // SAFETY: the caller runs where AVX-512F is available.
        unsafe {
            let (x, y, z) = (v[0].0, v[1].0, v[2].0);
            let xy0 = _mm512_permutex2var_pd(x, _mm512_setr_epi64(0, 8, 0, 1, 9, 0, 2, 10), y);
            let xy1 = _mm512_permutex2var_pd(x, _mm512_setr_epi64(0, 3, 11, 0, 4, 12, 0, 5), y);
            let xy2 = _mm512_permutex2var_pd(x, _mm512_setr_epi64(13, 0, 6, 14, 0, 7, 15, 0), y);
            [
                _mm512_permutex2var_pd(xy0, _mm512_setr_epi64(0, 1, 8, 3, 4, 9, 6, 7), z),
                _mm512_permutex2var_pd(xy1, _mm512_setr_epi64(10, 1, 2, 11, 4, 5, 12, 7), z),
                _mm512_permutex2var_pd(xy2, _mm512_setr_epi64(0, 13, 2, 3, 14, 5, 6, 15), z),
            ]
        }
    }

    /// Adds the corner forces of eight cells in one row ([`in_one_row`])
    /// into the node sums `nodes`, each node's two contributions of the
    /// row in cell order (the `+x` corner of the cell before, then the `-x`
    /// corner of the cell after), as the cell-by-cell sums add them: the
    /// same bits.
    ///
    /// # Safety
    /// AVX-512F is available; `nodes` points to one `[f64; 3]` per node of
    /// the lattice, and no other thread accesses those of these cells
    /// meanwhile.
    #[inline(always)]
    pub(super) unsafe fn add_rows(f: &[V3<F64x8>; 8], cells: &[[u32; 8]], nodes: *mut [f64; 3]) {
        // SAFETY: the function's contract; each run of nine nodes lies in
        // `nodes` (they are nodes of the lattice, `in_one_row`), the masked
        // load and store touch only the ninth node's three values.
        unsafe {
            let zero = _mm512_setzero_pd();
            let shift = |hi: __m512d, lo: __m512d| {
                // Lanes 5-7 of `lo`, then lanes 0-4 of `hi`: the `+x`
                // corners' values moved one node (three f64) along.
                _mm512_castsi512_pd(_mm512_alignr_epi64::<5>(
                    _mm512_castpd_si512(hi),
                    _mm512_castpd_si512(lo),
                ))
            };
            let c0 = cells[0];
            for (minus, plus) in [(0, 1), (3, 2), (4, 5), (7, 6)] {
                let p = nodes.add(c0[minus] as usize).cast::<f64>();
                let l = interleave(&f[minus]);
                let r = interleave(&f[plus]);
                let s = [
                    shift(r[0], zero),
                    shift(r[1], r[0]),
                    shift(r[2], r[1]),
                    shift(zero, r[2]),
                ];
                let d0 =
                    _mm512_mask_add_pd(_mm512_loadu_pd(p), 0b1111_1000, _mm512_loadu_pd(p), s[0]);
                let d1 = _mm512_add_pd(_mm512_loadu_pd(p.add(8)), s[1]);
                let d2 = _mm512_add_pd(_mm512_loadu_pd(p.add(16)), s[2]);
                let d3 = _mm512_add_pd(_mm512_maskz_loadu_pd(0b111, p.add(24)), s[3]);
                _mm512_storeu_pd(p, _mm512_add_pd(d0, l[0]));
                _mm512_storeu_pd(p.add(8), _mm512_add_pd(d1, l[1]));
                _mm512_storeu_pd(p.add(16), _mm512_add_pd(d2, l[2]));
                _mm512_mask_storeu_pd(p.add(24), 0b111, d3);
            }
        }
    }

    /// The corners of eight cells relative to each one's corner 0, in
    /// `f32`: loaded as runs of nodes when they lie in one row
    /// ([`row_corners`]), gathered otherwise ([`gather8_relative`]). The
    /// same operations per lane either way (the difference in `f64`, then
    /// rounded), so the same values.
    #[inline(always)]
    unsafe fn relative8(cells: &[[u32; 8]], x: &[[f64; 3]], in_row: bool) -> [V3<F32x8>; 8] {
        // SAFETY: the caller runs where AVX-512F and DQ are available and
        // says whether the cells lie in one row (`row_corners`' contract).
        unsafe {
            if !in_row {
                return gather8_relative(cells, x);
            }
            let xl = row_corners(cells, x);
            let mut rel = [[F32x8(_mm256_setzero_ps()); 3]; 8];
            for (r, xk) in rel.iter_mut().zip(&xl) {
                for c in 0..3 {
                    r[c] = F32x8(_mm512_cvtpd_ps(_mm512_sub_pd(xk[c].0, xl[0][c].0)));
                }
            }
            rel
        }
    }

    /// The 12 edge stretches of eight cells in `f32`, as runs when they lie
    /// in one row: the values of [`gather_edges8`].
    #[inline(always)]
    unsafe fn edges8(cells: &[[u32; 8]], edges: &[[f64; 3]], in_row: bool) -> [F32x8; 12] {
        // SAFETY: as `relative8`.
        unsafe {
            if !in_row {
                return gather_edges8(cells, edges);
            }
            // Loops, not `map`: a closure would not inherit this
            // function's instruction sets.
            let wide = row_edges(cells, edges);
            let mut w = [F32x8(_mm256_setzero_ps()); 12];
            for (w, wide) in w.iter_mut().zip(wide) {
                *w = F32x8(_mm512_cvtpd_ps(wide.0));
            }
            w
        }
    }

    /// The corners and edge stretches of sixteen cells in `f32`, each half
    /// of eight loaded as runs where it lies in one row ([`in_one_row`],
    /// said by `rows`): the values of [`gather16_relative`] and
    /// [`gather_edges16`].
    #[inline(always)]
    pub(super) unsafe fn cells16(
        cells: &[[u32; 8]],
        x: &[[f64; 3]],
        edges: &[[f64; 3]],
        rows: [bool; 2],
    ) -> ([V3<F32x16>; 8], [F32x16; 12]) {
        // SAFETY: the caller runs where AVX-512F and DQ are available;
        // `rows` says `in_one_row` of each half.
        unsafe {
            let (a, b) = cells.split_at(8);
            (
                join_corners::<F32x16, 8>(relative8(a, x, rows[0]), relative8(b, x, rows[1])),
                join_edges::<F32x16>(edges8(a, edges, rows[0]), edges8(b, edges, rows[1])),
            )
        }
    }

    /// Adds the corner forces of sixteen cells into the node sums, half
    /// after half (so in cell order): a half in one row by its runs of
    /// nodes ([`add_rows`], after widening to `f64`), another through
    /// `buf` cell by cell, as [`scatter16`] and the cell-by-cell sums
    /// would add it. The same bits.
    ///
    /// # Safety
    /// AVX-512F and DQ are available; `rows` says `in_one_row` of each
    /// half; `nodes` is [`add_rows`]' contract.
    #[inline(always)]
    pub(super) unsafe fn add16(
        f: &[V3<F32x16>; 8],
        cells: &[[u32; 8]],
        rows: [bool; 2],
        buf: &mut [[f64; 4]],
        nodes: *mut [f64; 3],
    ) {
        // SAFETY: the function's contract.
        unsafe {
            let halves = split_corners(f);
            for ((half, cells), in_row) in halves.iter().zip(cells.chunks_exact(8)).zip(rows) {
                if in_row {
                    let mut wide = [[F64x8(_mm512_setzero_pd()); 3]; 8];
                    for (w, h) in wide.iter_mut().zip(half) {
                        for c in 0..3 {
                            w[c] = F64x8(_mm512_cvtps_pd(h[c].0));
                        }
                    }
                    add_rows(&wide, cells, nodes);
                } else {
                    scatter8(half, &mut buf[..64]);
                    super::super::add_cells(cells, &buf[..64], nodes.cast());
                }
            }
        }
    }

    /// `[x, y, z, *]` of node `i` (the fourth value is the next node's `x`,
    /// or 0 for the last node, which has no next).
    #[inline(always)]
    unsafe fn load_node(x: &[[f64; 3]], i: usize) -> __m256d {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            if i + 1 < x.len() {
                // SAFETY: nodes i and i + 1 exist, so the 32 bytes from node i
                // lie within `x`.
                _mm256_loadu_pd(x.as_ptr().add(i).cast::<f64>())
            } else {
                let p = x[i];
                _mm256_set_pd(0.0, p[2], p[1], p[0])
            }
        }
    }

    /// Corners `corners` of four cells into vectors: lane `l` of coordinate
    /// `c` of entry `i` is `x[cells[l][corners[i]]][c]`. Four 32-byte loads
    /// and a 4 x 4 transpose per corner, instead of twelve scalar loads and
    /// inserts.
    #[inline(always)]
    pub(super) unsafe fn gather4<const K: usize>(
        cells: &[[u32; 8]],
        x: &[[f64; 3]],
        corners: [usize; K],
    ) -> [V3<F64x4>; K] {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            let zero = F64x4(_mm256_setzero_pd());
            let mut xl = [[zero; 3]; K];
            for (&k, xk) in corners.iter().zip(xl.iter_mut()) {
                let r = [
                    load_node(x, cells[0][k] as usize),
                    load_node(x, cells[1][k] as usize),
                    load_node(x, cells[2][k] as usize),
                    load_node(x, cells[3][k] as usize),
                ];
                let t0 = _mm256_unpacklo_pd(r[0], r[1]); // x0 x1 z0 z1
                let t1 = _mm256_unpackhi_pd(r[0], r[1]); // y0 y1 * *
                let t2 = _mm256_unpacklo_pd(r[2], r[3]); // x2 x3 z2 z3
                let t3 = _mm256_unpackhi_pd(r[2], r[3]); // y2 y3 * *
                xk[0] = F64x4(_mm256_permute2f128_pd(t0, t2, 0x20));
                xk[1] = F64x4(_mm256_permute2f128_pd(t1, t3, 0x20));
                xk[2] = F64x4(_mm256_permute2f128_pd(t0, t2, 0x31));
            }
            xl
        }
    }

    /// The stretches of the 12 edges of four cells from the edge stretches
    /// by node, gathered like positions (7 corners, one transpose each).
    #[inline(always)]
    pub(super) unsafe fn gather_edges4(cells: &[[u32; 8]], edges: &[[f64; 3]]) -> [F64x4; 12] {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            let starts = gather4(cells, edges, super::EDGE_STARTS);
            let mut w = [F64x4(_mm256_setzero_pd()); 12];
            for (w, &(a, _, ax)) in w.iter_mut().zip(&super::CELL_EDGES) {
                *w = starts[super::EDGE_START_INDEX[a]][ax];
            }
            w
        }
    }

    /// Corner forces of four cells out of vectors, `out[8 l + k] = [fx, fy,
    /// fz, 0]` of corner `k` of cell `l`.
    #[inline(always)]
    pub(super) unsafe fn scatter4(f: &[V3<F64x4>; 8], out: &mut [[f64; 4]]) {
        // SAFETY: the caller runs where AVX2 is available (this function's
        // contract); memory accesses are justified where they are made.
        unsafe {
            assert!(out.len() >= 32);
            let zero = _mm256_setzero_pd();
            for (k, fk) in f.iter().enumerate() {
                let (fx, fy, fz) = (fk[0].0, fk[1].0, fk[2].0);
                let t0 = _mm256_unpacklo_pd(fx, fy); // x0 y0 x2 y2
                let t1 = _mm256_unpackhi_pd(fx, fy); // x1 y1 x3 y3
                let t2 = _mm256_unpacklo_pd(fz, zero); // z0 0 z2 0
                let t3 = _mm256_unpackhi_pd(fz, zero); // z1 0 z3 0
                let rows = [
                    _mm256_permute2f128_pd(t0, t2, 0x20),
                    _mm256_permute2f128_pd(t1, t3, 0x20),
                    _mm256_permute2f128_pd(t0, t2, 0x31),
                    _mm256_permute2f128_pd(t1, t3, 0x31),
                ];
                for (l, row) in rows.into_iter().enumerate() {
                    // SAFETY: `8 l + k < 32 <= out.len()`, and each entry holds 4 f64.
                    _mm256_storeu_pd(out[8 * l + k].as_mut_ptr(), row);
                }
            }
        }
    }
}

/// Forces of consecutive cells `cells` (all with parameters `p`) at positions
/// `x`, given the lattice's edge stretches by node (`edges[n][axis]` for the
/// edge from node `n` along `+axis`), into `out` (8 corner forces per cell,
/// `[fx, fy, fz, 0]`), `P::WIDTH` cells per pass, the packs filled and
/// emptied by `moves`.
#[inline(always)]
fn forces_batch_body<P: Pack, G, W, S>(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
    moves: Moves<G, W, S>,
) where
    G: Fn(&[[u32; 8]], &[[f64; 3]]) -> [V3<P>; 8],
    W: Fn(&[[u32; 8]], &[[f64; 3]]) -> [P; 12],
    S: Fn(&[V3<P>; 8], &mut [[f64; 4]]),
{
    let Moves {
        gather,
        gather_edges: gather_w,
        scatter,
    } = moves;
    let width = P::WIDTH;
    let groups = cells.len() / width;
    for (cg, og) in cells
        .chunks_exact(width)
        .zip(out.chunks_exact_mut(8 * width))
    {
        let xl = gather(cg, x);
        let wl = gather_w(cg, edges);
        let mut f = [[P::cst(0.0); 3]; 8];
        cell_forces_with_edges(p, &xl, &wl, &mut f);
        scatter(&f, og);
    }
    let rest = &cells[groups * width..];
    let Some(last) = rest.last() else {
        return;
    };
    // The cells after the last whole pack take one more pack, its spare
    // lanes filled with copies of the last cell: a lane computes what the
    // one-cell kernel does (the same operations, so the same bits), and a
    // cell taken alone costs five to six lanes (measured in `f32`).
    assert!(width <= MAX_PACK_WIDTH, "a pack of {width} cells");
    let mut padded = [*last; MAX_PACK_WIDTH];
    padded[..rest.len()].copy_from_slice(rest);
    let padded = &padded[..width];
    let mut f = [[P::cst(0.0); 3]; 8];
    cell_forces_with_edges(p, &gather(padded, x), &gather_w(padded, edges), &mut f);
    let mut spill = [[0.0; 4]; 8 * MAX_PACK_WIDTH];
    scatter(&f, &mut spill[..8 * width]);
    out[8 * groups * width..].copy_from_slice(&spill[..8 * rest.len()]);
}

/// The widest pack of [`forces_batch_body`] (sixteen `f32` of AVX-512).
const MAX_PACK_WIDTH: usize = 16;

/// How the batched kernel moves a batch's values into packs and out:
/// corners, edge stretches, corner forces.
struct Moves<G, W, S> {
    gather: G,
    gather_edges: W,
    scatter: S,
}

/// [`forces_batch_avx2`] eight cells per pass in AVX-512 registers (twice
/// the cells per instruction, and 32 registers instead of 16), the cells
/// after the last whole eight four per pass: every lane performs the same
/// operations as on the other paths, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
fn forces_batch_avx512(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    let whole = cells.len() / 8 * 8;
    let (head, tail) = (&cells[..whole], &cells[whole..]);
    let (out_head, out_tail) = out.split_at_mut(8 * whole);
    forces_batch_body(
        p,
        head,
        x,
        edges,
        out_head,
        // SAFETY (each closure): they run inside this AVX-512 function.
        Moves {
            gather: |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe {
                avx2::gather8_f64(c, x, ALL_CORNERS)
            },
            gather_edges: |c: &[[u32; 8]], e: &[[f64; 3]]| unsafe { avx2::gather_edges8_f64(c, e) },
            scatter: |f: &[V3<avx2::F64x8>; 8], o: &mut [[f64; 4]]| unsafe {
                avx2::scatter8_f64(f, o)
            },
        },
    );
    forces_batch_avx2(p, tail, x, edges, out_tail);
}

/// [`forces_batch`] (or [`forces_batch_f32`], by `precision`) and the node
/// sums of its cells in one pass, where the CPU runs the AVX-512 pass
/// (returns false, having done nothing, where it does not): eight cells
/// that lie in one row of the lattice ([`avx2::in_one_row`], most cells of
/// a block or of a voxelized body's inside) load their corners and edge
/// stretches as runs of consecutive nodes and add their corner forces into
/// the node sums directly, instead of gathering each corner and writing 8
/// corner forces per cell to be added one by one; other cells go through
/// `buf` and are added cell by cell. Every node gets its contributions in
/// cell order either way, so the sums are bitwise those of the cell-by-cell
/// pass.
///
/// # Safety
/// `nodes` points to one `[f64; 3]` per node of `x`, and no other thread
/// accesses those of the nodes of `cells` meanwhile.
pub(crate) unsafe fn forces_batch_into_nodes(
    precision: super::Precision,
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    buf: &mut [[f64; 4]],
    nodes: *mut [f64; 3],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU has AVX-512F, DQ and VL (checked); `nodes` is
            // this function's contract.
            unsafe {
                match precision {
                    super::Precision::F64 => {
                        forces_into_nodes_avx512(p, cells, x, edges, buf, nodes);
                    }
                    super::Precision::F32 => {
                        forces_into_nodes_f32_avx512(p, cells, x, edges, buf, nodes);
                    }
                }
            }
            return true;
        }
    }
    let _ = (precision, p, cells, x, edges, buf, nodes);
    false
}

/// [`forces_into_nodes_avx512`] in single precision, sixteen cells per pass
/// (each half of eight in one row or not, [`avx2::cells16`]), the cells
/// after the last whole sixteen through [`forces_batch_f32_avx2`]: the
/// values of [`forces_batch_f32_avx512`], added in cell order.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn forces_into_nodes_f32_avx512(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    buf: &mut [[f64; 4]],
    nodes: *mut [f64; 3],
) {
    assert!(buf.len() >= 8 * cells.len());
    let whole = cells.len() / 16 * 16;
    for group in cells[..whole].chunks_exact(16) {
        let mut f = [[avx2::F32x16::cst(0.0); 3]; 8];
        // SAFETY: this function runs with AVX-512 (its target features);
        // `rows` is what `cells16` and `add16` are told; `nodes` is the
        // caller's contract.
        unsafe {
            let rows = [avx2::in_one_row(&group[..8]), avx2::in_one_row(&group[8..])];
            let (xl, wl) = avx2::cells16(group, x, edges, rows);
            cell_forces_with_edges(p, &xl, &wl, &mut f);
            avx2::add16(&f, group, rows, buf, nodes);
        }
    }
    // SAFETY: the caller's contract; this function runs with AVX2.
    unsafe {
        add_cells_through(&cells[whole..], buf, nodes, |c, o| {
            forces_batch_f32_avx2(p, c, x, edges, o);
        });
    }
}

/// Adds the forces of `cells`, written into `buf` by `batch`, into the node
/// sums cell by cell: the cells after a row pass's last whole group.
///
/// # Safety
/// As [`forces_batch_into_nodes`] (`nodes`).
#[inline(always)]
unsafe fn add_cells_through(
    cells: &[[u32; 8]],
    buf: &mut [[f64; 4]],
    nodes: *mut [f64; 3],
    batch: impl FnOnce(&[[u32; 8]], &mut [[f64; 4]]),
) {
    if cells.is_empty() {
        return;
    }
    let out = &mut buf[..8 * cells.len()];
    batch(cells, out);
    // SAFETY: the caller's contract.
    unsafe { super::add_cells(cells, out, nodes.cast()) };
}

/// The AVX-512 `f64` pass of [`forces_batch_into_nodes`]: eight cells per
/// pass, by runs where they lie in one row, the rest through `buf`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
unsafe fn forces_into_nodes_avx512(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    buf: &mut [[f64; 4]],
    nodes: *mut [f64; 3],
) {
    assert!(buf.len() >= 8 * cells.len());
    let whole = cells.len() / 8 * 8;
    for group in cells[..whole].chunks_exact(8) {
        let mut f = [[avx2::F64x8::cst(0.0); 3]; 8];
        // SAFETY: this function runs with AVX-512 (its target features);
        // `nodes` is the caller's contract.
        unsafe {
            if avx2::in_one_row(group) {
                let xl = avx2::row_corners(group, x);
                let wl = avx2::row_edges(group, edges);
                cell_forces_with_edges(p, &xl, &wl, &mut f);
                avx2::add_rows(&f, group, nodes);
            } else {
                let xl = avx2::gather8_f64(group, x, ALL_CORNERS);
                let wl = avx2::gather_edges8_f64(group, edges);
                cell_forces_with_edges(p, &xl, &wl, &mut f);
                avx2::scatter8_f64(&f, &mut buf[..64]);
                super::add_cells(group, &buf[..64], nodes.cast());
            }
        }
    }
    // SAFETY: the caller's contract; this function runs with AVX2.
    unsafe {
        add_cells_through(&cells[whole..], buf, nodes, |c, o| {
            forces_batch_avx2(p, c, x, edges, o);
        });
    }
}

/// Whether this CPU runs the AVX-512 force pass ([`forces_batch_avx512`]):
/// it has AVX-512F, DQ and VL. That includes AMD's Zen 4, which executes
/// 512-bit operations as two 256-bit halves: an early 8-lane variant was
/// slower there, but the AVX-512 paths as they are now (node sums added by
/// rows, edge pass by rows, 16-lane `f32`) take the 64^3 `paper` step from
/// 26 to 12 ms on a Zen 4 EPYC (docs/solvers.md). Every dispatch of a
/// batch of cells asks, so the three answers are combined once and kept.
#[cfg(target_arch = "x86_64")]
pub(crate) fn has_avx512() -> bool {
    static AVX512: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVX512.get_or_init(|| {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512dq")
            && std::arch::is_x86_feature_detected!("avx512vl")
    })
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn forces_batch_avx2(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    forces_batch_body(
        p,
        cells,
        x,
        edges,
        out,
        // SAFETY (each closure): they run inside this AVX2 function.
        Moves {
            gather: |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe { avx2::gather4(c, x, ALL_CORNERS) },
            gather_edges: |c: &[[u32; 8]], e: &[[f64; 3]]| unsafe { avx2::gather_edges4(c, e) },
            scatter: |f: &[V3<avx2::F64x4>; 8], o: &mut [[f64; 4]]| unsafe { avx2::scatter4(f, o) },
        },
    );
}

/// Forces of consecutive cells sharing the parameters `p`, given the
/// lattice's edge stretches by node ([`edge_stretches_batch`] and the
/// model's leftover edges), several cells per SIMD pass (AVX2 when the CPU
/// has it; never FMA, so results do not depend on the path taken), into
/// `out` as `[fx, fy, fz, 0]` per corner, cell by cell.
pub(crate) fn forces_batch(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, DQ and VL (checked just
            // above), and with them AVX2.
            unsafe { forces_batch_avx512(p, cells, x, edges, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { forces_batch_avx2(p, cells, x, edges, out) };
            return;
        }
    }
    forces_batch_body(
        p,
        cells,
        x,
        edges,
        out,
        Moves {
            gather: gather_corners::<LANES>,
            gather_edges: gather_edges::<f64, LANES>,
            scatter: scatter_corners::<f64, LANES>,
        },
    );
}

/// The tangent's action on `v` of one cell of parameters `p` at positions
/// `x`: the force kernel on a scalar dual number along `v`.
pub(crate) fn cell_tangent_action(
    p: &CellParams,
    cell: &[u32; 8],
    x: &[[f64; 3]],
    v: &[[f64; 3]],
) -> [[f64; 3]; 8] {
    let xd: [V3<Dual<1>>; 8] = std::array::from_fn(|a| {
        let (p, q) = (x[cell[a] as usize], v[cell[a] as usize]);
        std::array::from_fn(|d| Dual { v: p[d], g: [q[d]] })
    });
    let mut f = [[Dual::<1>::cst(0.0); 3]; 8];
    cell_forces(p, &xd, &mut f);
    f.map(|fa| fa.map(|c| c.g[0]))
}

/// The body of [`tangent_action_batch`]: `P::WIDTH` cells per pass, their
/// corners and directions gathered by `gather`, the products written out by
/// `scatter`; the cells after the last whole pack go through
/// [`cell_tangent_action`].
#[inline(always)]
fn tangent_action_body<P: Pack + SplitExponent, G, S>(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
    gather: G,
    scatter: S,
) where
    G: Fn(&[[u32; 8]], &[[f64; 3]]) -> [V3<P>; 8],
    S: Fn(&[V3<P>; 8], &mut [[f64; 4]]),
{
    let width = P::WIDTH;
    let groups = cells.len() / width;
    for (cg, og) in cells
        .chunks_exact(width)
        .zip(out.chunks_exact_mut(8 * width))
    {
        let (xl, vl) = (gather(cg, x), gather(cg, v));
        let xd: [V3<PackDual<P>>; 8] = std::array::from_fn(|a| {
            std::array::from_fn(|d| PackDual {
                v: xl[a][d],
                g: vl[a][d],
            })
        });
        let mut f = [[PackDual::<P>::cst(0.0); 3]; 8];
        cell_forces(p, &xd, &mut f);
        scatter(&f.map(|fa| fa.map(|c| c.g)), og);
    }
    for (c, o) in cells[groups * width..]
        .iter()
        .zip(out[8 * groups * width..].chunks_exact_mut(8))
    {
        for (o, f) in o.iter_mut().zip(cell_tangent_action(p, c, x, v)) {
            *o = [f[0], f[1], f[2], 0.0];
        }
    }
}

/// [`tangent_action_avx2`] eight cells per pass in AVX-512 registers, the
/// cells after the last whole eight four per pass (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
fn tangent_action_avx512(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    let whole = cells.len() / 8 * 8;
    let (out_head, out_tail) = out.split_at_mut(8 * whole);
    tangent_action_body(
        p,
        &cells[..whole],
        x,
        v,
        out_head,
        // SAFETY (both closures): they run inside this AVX-512 function.
        |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe { avx2::gather8_f64(c, x, ALL_CORNERS) },
        |f: &[V3<avx2::F64x8>; 8], o: &mut [[f64; 4]]| unsafe { avx2::scatter8_f64(f, o) },
    );
    tangent_action_avx2(p, &cells[whole..], x, v, out_tail);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn tangent_action_avx2(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    tangent_action_body(
        p,
        cells,
        x,
        v,
        out,
        // SAFETY (both closures): they run inside this AVX2 function.
        |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe { avx2::gather4(c, x, ALL_CORNERS) },
        |f: &[V3<avx2::F64x4>; 8], o: &mut [[f64; 4]]| unsafe { avx2::scatter4(f, o) },
    );
}

/// The tangent's action on `v` (the directional derivative of the internal
/// forces at `x`) of consecutive cells sharing the parameters `p`, several
/// cells per SIMD pass on dual numbers ([`PackDual`]; AVX2 when the CPU has
/// it, never FMA), into `out` as `[fx, fy, fz, 0]` per corner, cell by cell.
/// The same values as the scalar dual kernel to round-off (bitwise but for
/// the barrier's logarithm), whatever path is taken.
pub(crate) fn tangent_action_batch(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    v: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, DQ and VL (checked just
            // above), and with them AVX2.
            unsafe { tangent_action_avx512(p, cells, x, v, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { tangent_action_avx2(p, cells, x, v, out) };
            return;
        }
    }
    tangent_action_body(
        p,
        cells,
        x,
        v,
        out,
        gather_corners::<LANES>,
        scatter_corners::<f64, LANES>,
    );
}

/// The body of [`survey_batch`]: `P::WIDTH` cells per pass, their corners
/// gathered by `gather`; the cells after the last whole pack on `f64`.
#[inline(always)]
fn survey_body<P: Pack + SplitExponent, G>(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    (growth, corners): (bool, bool),
    out: &mut [CellSurvey<f64>],
    gather: G,
) where
    G: Fn(&[[u32; 8]], &[[f64; 3]]) -> [V3<P>; 8],
{
    let width = P::WIDTH;
    let groups = cells.len() / width;
    for (cg, og) in cells.chunks_exact(width).zip(out.chunks_exact_mut(width)) {
        let s = cell_survey(p, &gather(cg, x), growth, corners);
        for (l, o) in og.iter_mut().enumerate() {
            *o = CellSurvey {
                jac: s.jac.lane(l),
                volumetric_growth: s.volumetric_growth.lane(l),
                lowest_corner: s.lowest_corner.lane(l),
            };
        }
    }
    for (c, o) in cells[groups * width..]
        .iter()
        .zip(&mut out[groups * width..])
    {
        let xc: [V3<f64>; 8] = std::array::from_fn(|k| x[c[k] as usize]);
        *o = cell_survey(p, &xc, growth, corners);
    }
}

/// [`survey_avx2`] eight cells per pass in AVX-512 registers, the cells
/// after the last whole eight four per pass (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
fn survey_avx512(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    parts: (bool, bool),
    out: &mut [CellSurvey<f64>],
) {
    let whole = cells.len() / 8 * 8;
    let (out_head, out_tail) = out.split_at_mut(whole);
    // SAFETY (the closure): it runs inside this AVX-512 function.
    survey_body(
        p,
        &cells[..whole],
        x,
        parts,
        out_head,
        // Cells in one row load their corners as runs of nodes (the same
        // values as gathered: 24 vector loads for the eight corners, where
        // the gather reads 64 nodes one by one).
        |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe {
            if avx2::in_one_row(c) {
                avx2::row_corners(c, x)
            } else {
                avx2::gather8_f64(c, x, ALL_CORNERS)
            }
        },
    );
    survey_avx2(p, &cells[whole..], x, parts, out_tail);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn survey_avx2(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    parts: (bool, bool),
    out: &mut [CellSurvey<f64>],
) {
    // SAFETY (the closure): it runs inside this AVX2 function.
    survey_body(
        p,
        cells,
        x,
        parts,
        out,
        |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe { avx2::gather4(c, x, ALL_CORNERS) },
    );
}

/// [`cell_survey`] of consecutive cells sharing the parameters `p` at `x`
/// (`parts`: the growth, the corners), several cells per SIMD pass (AVX2
/// when the CPU has it), into `out`, one per cell: the same bits on every
/// path.
pub(crate) fn survey_batch(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    parts: (bool, bool),
    out: &mut [CellSurvey<f64>],
) {
    assert_eq!(cells.len(), out.len(), "one survey per cell");
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, DQ and VL (checked just
            // above), and with them AVX2.
            unsafe { survey_avx512(p, cells, x, parts, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { survey_avx2(p, cells, x, parts, out) };
            return;
        }
    }
    survey_body(p, cells, x, parts, out, gather_corners::<LANES>);
}

/// Cells evaluated together by [`forces_batch_f32`] (AVX2 holds 8 `f32`).
pub(crate) const LANES_F32: usize = 8;

/// [`cell_forces_from_edges`] in single precision: the corners relative to
/// corner 0 and the edge stretches are rounded to `f32` (differences taken
/// in `f64` first, so that a cell far from the origin loses nothing to its
/// placement), the kernel runs in `f32`, and the forces come back as `f64`.
/// Every term of the kernel depends on differences of positions only.
pub(crate) fn cell_forces_from_edges_f32(
    p: &CellParams,
    cell: &[u32; 8],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
) -> [[f64; 3]; 8] {
    let origin = x[cell[0] as usize];
    let mut xc = [[0.0f32; 3]; 8];
    for (xk, &v) in xc.iter_mut().zip(cell) {
        let p = x[v as usize];
        *xk = [
            (p[0] - origin[0]) as f32,
            (p[1] - origin[1]) as f32,
            (p[2] - origin[2]) as f32,
        ];
    }
    let mut w = [0.0f32; 12];
    for (w, &(a, _, ax)) in w.iter_mut().zip(&CELL_EDGES) {
        *w = edges[cell[a] as usize][ax] as f32;
    }
    let mut f = [[0.0f32; 3]; 8];
    cell_forces_with_edges(p, &xc, &w, &mut f);
    let mut out = [[0.0; 3]; 8];
    for (o, f) in out.iter_mut().zip(f) {
        *o = [f64::from(f[0]), f64::from(f[1]), f64::from(f[2])];
    }
    out
}

/// The corners of `L` cells relative to their corner 0, in `f32` lanes
/// (portable path of [`forces_batch_f32`]).
#[inline(always)]
fn gather_corners_f32<const L: usize>(
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
) -> [V3<Lanes<f32, L>>; 8] {
    let mut xl: [V3<Lanes<f32, L>>; 8] = [[Lanes::cst(0.0); 3]; 8];
    for (k, xk) in xl.iter_mut().enumerate() {
        for (l, cell) in cells.iter().enumerate() {
            let (p, o) = (x[cell[k] as usize], x[cell[0] as usize]);
            for c in 0..3 {
                xk[c].0[l] = (p[c] - o[c]) as f32;
            }
        }
    }
    xl
}

/// [`forces_batch_f32_avx2`] sixteen cells per pass in AVX-512 registers,
/// the cells after the last whole sixteen eight at a time (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512dq,avx512vl")]
fn forces_batch_f32_avx512(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    let whole = cells.len() / 16 * 16;
    let (out_head, out_tail) = out.split_at_mut(8 * whole);
    forces_batch_body(
        p,
        &cells[..whole],
        x,
        edges,
        out_head,
        // SAFETY (each closure): they run inside this AVX-512 function.
        Moves {
            gather: |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe { avx2::gather16_relative(c, x) },
            gather_edges: |c: &[[u32; 8]], e: &[[f64; 3]]| unsafe { avx2::gather_edges16(c, e) },
            scatter: |f: &[V3<avx2::F32x16>; 8], o: &mut [[f64; 4]]| unsafe {
                avx2::scatter16(f, o)
            },
        },
    );
    forces_batch_f32_avx2(p, &cells[whole..], x, edges, out_tail);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn forces_batch_f32_avx2(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    forces_batch_body(
        p,
        cells,
        x,
        edges,
        out,
        // SAFETY (each closure): they run inside this AVX2 function.
        Moves {
            gather: |c: &[[u32; 8]], x: &[[f64; 3]]| unsafe { avx2::gather8_relative(c, x) },
            gather_edges: |c: &[[u32; 8]], e: &[[f64; 3]]| unsafe { avx2::gather_edges8(c, e) },
            scatter: |f: &[V3<avx2::F32x8>; 8], o: &mut [[f64; 4]]| unsafe { avx2::scatter8(f, o) },
        },
    );
}

/// [`forces_batch`] in single precision ([`cell_forces_from_edges_f32`]),
/// 8 cells per AVX2 pass; the portable path performs the same operations
/// per lane, so the same bits.
pub(crate) fn forces_batch_f32(
    p: &CellParams,
    cells: &[[u32; 8]],
    x: &[[f64; 3]],
    edges: &[[f64; 3]],
    out: &mut [[f64; 4]],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if has_avx512() {
            // SAFETY: the CPU supports AVX-512F, DQ and VL (checked just
            // above), and with them AVX2.
            unsafe { forces_batch_f32_avx512(p, cells, x, edges, out) };
            return;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            unsafe { forces_batch_f32_avx2(p, cells, x, edges, out) };
            return;
        }
    }
    forces_batch_body(
        p,
        cells,
        x,
        edges,
        out,
        Moves {
            gather: gather_corners_f32::<LANES_F32>,
            gather_edges: gather_edges::<f32, LANES_F32>,
            scatter: scatter_corners::<f32, LANES_F32>,
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::noise;

    /// The factored spreading of the corner patterns against adding each
    /// pattern to each corner by its signs, with and without the hourglass
    /// part, on random vectors: equal within rounding.
    #[test]
    fn corner_patterns_are_the_signed_sums_over_corners() {
        let mut seed = 11;
        for with_twist in [false, true] {
            for _ in 0..200 {
                let mut vec3 = || [0; 3].map(|_: i32| noise(&mut seed));
                let side = [vec3(), vec3(), vec3()];
                let twist = [vec3(), vec3(), vec3()];
                let start: [V3<f64>; 8] = std::array::from_fn(|_| vec3());
                let mut f = start;
                add_corner_patterns(&side, with_twist.then_some(&twist), &mut f);
                for n in 0..8 {
                    for c in 0..3 {
                        let mut want = start[n][c];
                        for j in 0..3 {
                            want += corner_sign(n, j) * side[j][c];
                            if with_twist {
                                want += hourglass_sign(n, j) * twist[j][c];
                            }
                        }
                        assert!(
                            (f[n][c] - want).abs() < 1e-14,
                            "corner {n}: {} vs {want}",
                            f[n][c]
                        );
                    }
                }
            }
        }
    }

    /// The hourglass vectors summed from edges are the corners' signed sums
    /// `1/8 sum_n s_j s_k(n) x_n`, and vanish for affine positions.
    #[test]
    fn hourglass_vectors_from_edges_are_the_corner_sums() {
        let mut seed = 5;
        let axes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for _ in 0..200 {
            let x: [V3<f64>; 8] = std::array::from_fn(|_| [0; 3].map(|_: i32| noise(&mut seed)));
            let (g, _) = hourglass_amplitudes(hourglass_sums(&x), &axes);
            for (i, gi) in g.iter().enumerate() {
                for (c, gic) in gi.iter().enumerate() {
                    let want: f64 = (0..8).map(|n| 0.125 * hourglass_sign(n, i) * x[n][c]).sum();
                    assert!((gic - want).abs() < 1e-14, "g_{i}: {gic} vs {want}");
                }
            }
        }
        let affine: [V3<f64>; 8] = std::array::from_fn(|n| {
            let o = CORNER_OFFSETS[n].map(f64::from);
            [
                1.0 + 2.0 * o[0] + 0.3 * o[1],
                -0.5 * o[2] + o[0],
                0.7 * o[1] + 1.1 * o[2],
            ]
        });
        let (g, q) = hourglass_amplitudes(hourglass_sums(&affine), &axes);
        assert!(
            g.iter().flatten().chain(&q).all(|v| v.abs() < 1e-15),
            "{g:?}"
        );
    }

    /// The force pass's logarithm against libm's: within 2 ulp in `f64`
    /// over the whole normal range and densely around 1, where the barrier
    /// works; within 2 ulp of `f32` in single precision.
    #[test]
    fn fast_ln_is_within_two_ulp_of_libm() {
        let mut seed = 7;
        let mut values: Vec<f64> = (0..20_000).map(|_| 1.0 + 0.5 * noise(&mut seed)).collect();
        values.extend((0..20_000).map(|_| 10f64.powf(300.0 * noise(&mut seed))));
        values.extend([
            1.0,
            BARRIER_KNEE,
            std::f64::consts::SQRT_2,
            2.0,
            0.5,
            f64::MIN_POSITIVE,
            f64::MAX,
        ]);
        for x in values {
            let (fast, exact) = (fast_ln(x), x.ln());
            assert!(
                (fast - exact).abs() <= 2.0 * f64::EPSILON * exact.abs(),
                "ln {x:e}: {fast:e} vs {exact:e}"
            );
            let x32 = x as f32;
            if x32.is_normal() {
                let (fast, exact) = (fast_ln(x32), f64::from(x32).ln());
                assert!(
                    (f64::from(fast) - exact).abs()
                        <= 2.0 * f64::from(f32::EPSILON) * exact.abs().max(1e-30),
                    "ln {x32:e} in f32: {fast:e} vs {exact:e}"
                );
            }
        }
    }

    /// The branch-free barrier slope equals the law's, on both sides of the
    /// knee, to round-off.
    #[test]
    fn fast_barrier_slope_follows_the_law_through_the_knee() {
        for j in [
            -0.5,
            0.0,
            0.05,
            0.0999,
            BARRIER_KNEE,
            0.1001,
            0.5,
            0.9,
            1.0,
            1.3,
            4.0,
        ] {
            let (fast, exact) = (fast_barrier_slope(j), barrier_slope(j).0);
            assert!(
                (fast - exact).abs() <= 1e-14 * exact.abs().max(1.0),
                "J = {j}: {fast} vs {exact}"
            );
        }
        assert!(fast_barrier_slope(f64::NAN).is_nan());
    }

    fn params(vol_lambda_h3: f64, vol_barrier: bool, k_hourglass: f64) -> CellParams {
        let h = 0.01;
        CellParams {
            k_edge: 3.0,
            k_diag: 1.5,
            rest_edge: h,
            rest_diag: h * 3f64.sqrt(),
            correction: None,
            vol_lambda_h3,
            vol_barrier,
            grad_scale: 1.0 / (4.0 * h),
            k_hourglass,
            corner_barrier: 0.0,
        }
    }

    /// `p` with the corner barrier at a strength comparable to its springs'.
    fn with_corner_barrier(p: CellParams) -> CellParams {
        CellParams {
            corner_barrier: 4e-4,
            ..p
        }
    }

    fn with_correction(p: CellParams, c: f64) -> CellParams {
        CellParams {
            correction: Correction::new(c),
            ..p
        }
    }

    /// The closed-form Hessian agrees with dual numbers through the force
    /// kernel, for every term alone and together, on cells distorted up to
    /// half their edge (some inverted past the barrier's knee).
    #[test]
    fn closed_form_jacobian_matches_dual_numbers() {
        let h = 0.01;
        let mut seed = 7;
        let sets = [
            params(0.0, false, 0.0),
            params(0.02, false, 0.0),
            params(0.02, true, 0.0),
            params(0.0, false, 40.0),
            params(0.02, true, 40.0),
            with_correction(params(0.0, false, 0.0), 0.1),
            with_correction(params(0.0, false, 0.0), -0.5),
            with_correction(params(0.02, true, 40.0), -0.5),
            with_correction(params(0.02, false, 0.0), 0.4),
            with_corner_barrier(params(0.0, false, 0.0)),
            with_corner_barrier(with_correction(params(0.02, true, 40.0), -0.5)),
        ];
        // Corners seen in the barrier's range and folded.
        let (mut in_barrier, mut past_knee) = (0, 0);
        for amplitude in [0.0f64, 0.05, 0.2, 0.5] {
            for trial in 0..20 {
                // Some cells with one corner pushed in along the diagonal by
                // `push` h: its Jacobian is 1 - 3 push (0.4 to -0.5).
                let (pushed, push) = (trial % 8, [0.0, 0.2, 0.25, 0.32, 0.5][trial % 5]);
                let x: [V3<f64>; 8] = std::array::from_fn(|n| {
                    std::array::from_fn(|d| {
                        let o = CORNER_OFFSETS[n][d] as f64;
                        let inward = if n == pushed {
                            push * (1.0 - 2.0 * o)
                        } else {
                            0.0
                        };
                        // Pushed cells get little noise, others the amplitude.
                        let a = if push > 0.0 {
                            amplitude.min(0.05)
                        } else {
                            amplitude
                        };
                        (o + inward + a * noise(&mut seed)) * h
                    })
                });
                for j in corner_jacobians(&x, 1.0 / (h * h * h)).1 {
                    in_barrier += usize::from(j < CORNER_BARRIER_START);
                    past_knee += usize::from(j < 0.0);
                }
                for p in &sets {
                    let closed = cell_jacobian_closed_form(p, &x);
                    let dual = cell_jacobian_dual(p, &x);
                    let scale = dual.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
                    for (rc, rd) in closed.iter().zip(&dual) {
                        for (c, d) in rc.iter().zip(rd) {
                            assert!(
                                (c - d).abs() <= 1e-11 * scale,
                                "{p:?} at amplitude {amplitude}: {c} vs {d}"
                            );
                        }
                    }
                }
            }
        }
        assert!(in_barrier > 10 && past_knee > 5, "{in_barrier} {past_knee}");
    }

    /// The tangent's action on packs of cells (the portable lanes and, where
    /// the CPU has it, AVX2) is the scalar dual kernel's, cell by cell, to
    /// round-off (the barrier's logarithm is the force pass's), for every
    /// term, on cells distorted past the barrier's knee and into the corner
    /// barrier, with a batch whose cell count is not a multiple of the pack.
    #[test]
    fn packed_tangent_action_is_the_scalar_duals() {
        let h = 0.01;
        let mut seed = 11;
        // 7 cells: one pack of 4 and a tail of 3, each cell its own 8
        // nodes, some with a corner pushed deep in.
        let cells: Vec<[u32; 8]> = (0..7u32)
            .map(|c| std::array::from_fn(|k| 8 * c + k as u32))
            .collect();
        let x: Vec<[f64; 3]> = (0..56)
            .map(|i| {
                let (cell, n) = (i / 8, i % 8);
                let push = if n == cell % 8 {
                    [0.0, 0.25, 0.32, 0.5][cell % 4]
                } else {
                    0.0
                };
                std::array::from_fn(|d| {
                    let o = CORNER_OFFSETS[n][d] as f64;
                    (o + push * (1.0 - 2.0 * o) + 0.05 * noise(&mut seed) + 3.0 * cell as f64) * h
                })
            })
            .collect();
        let v: Vec<[f64; 3]> = (0..56)
            .map(|_| std::array::from_fn(|_| noise(&mut seed)))
            .collect();
        let sets = [
            params(0.0, false, 0.0),
            params(0.02, true, 40.0),
            with_correction(params(0.02, false, 0.0), 0.4),
            with_corner_barrier(with_correction(params(0.02, true, 40.0), -0.5)),
        ];
        for p in &sets {
            let scalar: Vec<[f64; 3]> = cells
                .iter()
                .flat_map(|c| cell_tangent_action(p, c, &x, &v))
                .collect();
            let scale = scalar.iter().flatten().fold(0.0f64, |m, a| m.max(a.abs()));
            let check = |packed: &[[f64; 4]], path: &str| {
                for (k, (a, b)) in packed.iter().zip(&scalar).enumerate() {
                    for d in 0..3 {
                        assert!(
                            (a[d] - b[d]).abs() <= 1e-13 * scale,
                            "{path}, {p:?}, corner {k}: {} vs {}",
                            a[d],
                            b[d]
                        );
                    }
                    assert_eq!(a[3], 0.0);
                }
            };
            let mut out = vec![[0.0; 4]; 8 * cells.len()];
            tangent_action_body(
                p,
                &cells,
                &x,
                &v,
                &mut out,
                gather_corners::<LANES>,
                scatter_corners::<f64, LANES>,
            );
            check(&out, "portable");
            let mut out = vec![[0.0; 4]; 8 * cells.len()];
            tangent_action_batch(p, &cells, &x, &v, &mut out);
            check(&out, "dispatched");
        }
    }

    /// A one-cell force kernel ([`cell_forces_from_edges`] and its `f32` twin).
    type OneCell = fn(&CellParams, &[u32; 8], &[[f64; 3]], &[[f64; 3]]) -> [[f64; 3]; 8];

    /// Every instruction set's force pass and tangent action give the
    /// portable lanes' bits, cell by cell: AVX2 (4 cells per pass) and
    /// AVX-512 (8 per pass, the rest 4 at a time), where this CPU has them,
    /// and so does the `f32` force pass (8 and 16 per pass), for every
    /// term, on 37 cells (two sixteens, a four and a tail of one) distorted
    /// into the corner barrier; and the portable lanes give the one-cell
    /// kernels' bits, those of the cells after the last whole pack too
    /// (computed in a pack padded with copies of the last cell).
    #[test]
    fn every_instruction_set_gives_the_portable_bits() {
        let h = 0.01;
        let mut seed = 3;
        let n = 37;
        let cells: Vec<[u32; 8]> = (0..n as u32)
            .map(|c| std::array::from_fn(|k| 8 * c + k as u32))
            .collect();
        let x: Vec<[f64; 3]> = (0..8 * n)
            .map(|i| {
                let (cell, k) = (i / 8, i % 8);
                let push = if k == cell % 8 {
                    [0.0, 0.25, 0.32, 0.5][cell % 4]
                } else {
                    0.0
                };
                std::array::from_fn(|d| {
                    let o = CORNER_OFFSETS[k][d] as f64;
                    (o + push * (1.0 - 2.0 * o) + 0.05 * noise(&mut seed) + 3.0 * cell as f64) * h
                })
            })
            .collect();
        let v: Vec<[f64; 3]> = (0..8 * n)
            .map(|_| std::array::from_fn(|_| noise(&mut seed)))
            .collect();
        // Each cell has nodes of its own: every edge's stretch is stored at
        // its start node, along its axis.
        let mut edges = vec![[0.0; 3]; 8 * n];
        for c in &cells {
            for &(a, b, ax) in &CELL_EDGES {
                let (xa, xb) = (x[c[a] as usize], x[c[b] as usize]);
                edges[c[a] as usize][ax] = stretch(h, sub(xb, xa));
            }
        }
        let sets = [
            params(0.0, false, 0.0),
            params(0.02, true, 40.0),
            with_correction(params(0.02, false, 0.0), 0.4),
            with_corner_barrier(with_correction(params(0.02, true, 40.0), -0.5)),
        ];
        let bits =
            |o: &[[f64; 4]]| -> Vec<u64> { o.iter().flatten().map(|v| v.to_bits()).collect() };
        for p in &sets {
            let mut portable = vec![[0.0; 4]; 8 * n];
            forces_batch_body(
                p,
                &cells,
                &x,
                &edges,
                &mut portable,
                Moves {
                    gather: gather_corners::<LANES>,
                    gather_edges: gather_edges::<f64, LANES>,
                    scatter: scatter_corners::<f64, LANES>,
                },
            );
            let mut portable_tangent = vec![[0.0; 4]; 8 * n];
            tangent_action_body(
                p,
                &cells,
                &x,
                &v,
                &mut portable_tangent,
                gather_corners::<LANES>,
                scatter_corners::<f64, LANES>,
            );
            let mut portable_f32 = vec![[0.0; 4]; 8 * n];
            forces_batch_body(
                p,
                &cells,
                &x,
                &edges,
                &mut portable_f32,
                Moves {
                    gather: gather_corners_f32::<LANES_F32>,
                    gather_edges: gather_edges::<f32, LANES_F32>,
                    scatter: scatter_corners::<f32, LANES_F32>,
                },
            );
            // Every cell, those of the last pack's spare lanes too, is what
            // the one-cell kernel gives.
            let cell_by_cell = |kernel: OneCell| -> Vec<u64> {
                cells
                    .iter()
                    .flat_map(|c| kernel(p, c, &x, &edges))
                    .flat_map(|f| [f[0], f[1], f[2], 0.0])
                    .map(f64::to_bits)
                    .collect()
            };
            assert_eq!(
                bits(&portable),
                cell_by_cell(cell_forces_from_edges),
                "{p:?}"
            );
            assert_eq!(
                bits(&portable_f32),
                cell_by_cell(cell_forces_from_edges_f32),
                "{p:?}"
            );
            let mut paths = 0;
            #[cfg(target_arch = "x86_64")]
            {
                let mut out = vec![[0.0; 4]; 8 * n];
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU supports AVX2 (checked just above).
                    unsafe { forces_batch_avx2(p, &cells, &x, &edges, &mut out) };
                    assert_eq!(bits(&out), bits(&portable), "AVX2 forces, {p:?}");
                    unsafe { tangent_action_avx2(p, &cells, &x, &v, &mut out) };
                    assert_eq!(bits(&out), bits(&portable_tangent), "AVX2 tangent, {p:?}");
                    unsafe { forces_batch_f32_avx2(p, &cells, &x, &edges, &mut out) };
                    assert_eq!(bits(&out), bits(&portable_f32), "AVX2 f32 forces, {p:?}");
                    paths += 1;
                }
                if has_avx512() {
                    // SAFETY: the CPU supports AVX-512F, DQ and VL.
                    unsafe { forces_batch_avx512(p, &cells, &x, &edges, &mut out) };
                    assert_eq!(bits(&out), bits(&portable), "AVX-512 forces, {p:?}");
                    unsafe { tangent_action_avx512(p, &cells, &x, &v, &mut out) };
                    assert_eq!(
                        bits(&out),
                        bits(&portable_tangent),
                        "AVX-512 tangent, {p:?}"
                    );
                    unsafe { forces_batch_f32_avx512(p, &cells, &x, &edges, &mut out) };
                    assert_eq!(bits(&out), bits(&portable_f32), "AVX-512 f32 forces, {p:?}");
                    paths += 1;
                }
            }
            // The values are forces: the corner barrier pushed.
            assert!(portable.iter().flatten().any(|f| f.abs() > 0.0), "{paths}");
        }
        // The edge pass: the scalar path's bits on every path, and the
        // stretches the cells' edges above were given to round-off (one
        // division for three edges there, one per edge in `stretch`).
        let ebits =
            |o: &[[f64; 3]]| -> Vec<u64> { o.iter().flatten().map(|v| v.to_bits()).collect() };
        let mut expected = vec![[0.0; 3]; n];
        edge_stretches_scalar::<false>(h, &cells, &x, &mut expected);
        for (c, w) in cells.iter().zip(&expected) {
            for (ax, w) in w.iter().enumerate() {
                let exact = edges[c[0] as usize][ax];
                assert!(
                    (w - exact).abs() <= 1e-14 * (1.0 + exact.abs()),
                    "{w} {exact}"
                );
            }
        }
        // The single-precision pass's seeded stretches: the exact stretch
        // to the Newton step's 1e-14, far closer than the single precision
        // (6e-8 of the stretch) the kernel then uses.
        let mut seeded = vec![[0.0; 3]; n];
        edge_stretches_scalar::<true>(h, &cells, &x, &mut seeded);
        let mut worst = 0.0f64;
        for (c, w) in cells.iter().zip(&seeded) {
            for (ax, w) in w.iter().enumerate() {
                let exact = edges[c[0] as usize][ax];
                worst = worst.max((w - exact).abs());
            }
        }
        assert!(worst <= 1e-13, "seeded stretches off by {worst:e}");
        assert_ne!(
            ebits(&seeded),
            ebits(&expected),
            "the seeded pass is another"
        );
        /// Every path of the edge pass gives the scalar path's bits.
        fn same_on_every_path<const SEED: bool>(
            h: f64,
            cells: &[[u32; 8]],
            x: &[[f64; 3]],
            scalar: &[[f64; 3]],
        ) {
            let ebits =
                |o: &[[f64; 3]]| -> Vec<u64> { o.iter().flatten().map(|v| v.to_bits()).collect() };
            let mut out = vec![[0.0; 3]; cells.len()];
            edge_stretches_body::<_, SEED>(h, cells, x, &mut out, gather_edge_ends::<LANES>);
            assert_eq!(ebits(&out), ebits(scalar), "portable edge pass, {SEED}");
            edge_stretches_batch::<SEED>(h, cells, x, &mut out);
            assert_eq!(ebits(&out), ebits(scalar), "dispatched edge pass, {SEED}");
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU supports AVX2 (checked just above).
                    unsafe { edge_stretches_avx2::<SEED>(h, cells, x, &mut out) };
                    assert_eq!(ebits(&out), ebits(scalar), "AVX2 edge pass, {SEED}");
                }
                if has_avx512() {
                    // SAFETY: the CPU supports AVX-512F, DQ and VL.
                    unsafe { edge_stretches_avx512::<SEED>(h, cells, x, &mut out) };
                    assert_eq!(ebits(&out), ebits(scalar), "AVX-512 edge pass, {SEED}");
                }
            }
        }
        same_on_every_path::<false>(h, &cells, &x, &expected);
        same_on_every_path::<true>(h, &cells, &x, &seeded);
        let d: Vec<[f64; 3]> = cells
            .iter()
            .flat_map(|c| CORNER_EDGES.map(|(end, _)| sub(x[c[end] as usize], x[c[0] as usize])))
            .collect();
        let rests = vec![h; d.len()];
        let mut w = vec![0.0; d.len()];
        stretches::<true>(&rests, &d, &mut w);
        let flat: Vec<f64> = seeded.iter().flatten().copied().collect();
        assert!(
            w.iter().zip(&flat).all(|(a, b)| a.to_bits() == b.to_bits()),
            "leftover edges"
        );
    }

    /// The explicit step's cell survey, on packs (portable lanes, the
    /// dispatched path) and on one `f64` at a time, gives the same bits for
    /// every cell, and agrees with the exact formulas: the centre Jacobian
    /// of the deformation gradient, the volumetric growth with libm's
    /// logarithm (to round-off, also past the barrier's knee and inverted),
    /// the smallest of the 8 corner Jacobians.
    #[test]
    fn cell_survey_is_the_same_on_every_path_and_agrees_with_the_formulas() {
        let h = 0.01;
        let mut seed = 5;
        // 11 cells: two packs of 4 and a tail of 3, each with its own nodes,
        // some squeezed at a corner (J_n 0.4 to -0.5), some inverted whole.
        let cells: Vec<[u32; 8]> = (0..11u32)
            .map(|c| std::array::from_fn(|k| 8 * c + k as u32))
            .collect();
        let x: Vec<[f64; 3]> = (0..88)
            .map(|i| {
                let (cell, n) = (i / 8, i % 8);
                let push = if n == cell % 8 {
                    [0.0, 0.2, 0.32, 0.5][cell % 4]
                } else {
                    0.0
                };
                std::array::from_fn(|d| {
                    let mut o = CORNER_OFFSETS[n][d] as f64;
                    if cell == 9 && d == 2 {
                        // Upside down: J = -1.
                        o = 1.0 - o;
                    }
                    (o + push * (1.0 - 2.0 * o) + 0.05 * noise(&mut seed) + 3.0 * cell as f64) * h
                })
            })
            .collect();
        let blank = CellSurvey {
            jac: 0.0,
            volumetric_growth: 0.0,
            lowest_corner: 0.0,
        };
        let inv_h3 = 1.0 / (h * h * h);
        for p in [params(0.02, true, 40.0), params(0.02, false, 0.0)] {
            let p = with_corner_barrier(p);
            let mut portable = vec![blank; cells.len()];
            survey_body(
                &p,
                &cells,
                &x,
                (true, true),
                &mut portable,
                gather_corners::<LANES>,
            );
            let mut dispatched = vec![blank; cells.len()];
            survey_batch(&p, &cells, &x, (true, true), &mut dispatched);
            let mut lowest_seen = f64::INFINITY;
            for (k, c) in cells.iter().enumerate() {
                let xc: [V3<f64>; 8] = std::array::from_fn(|n| x[c[n] as usize]);
                let one = cell_survey(&p, &xc, true, true);
                for s in [portable[k], dispatched[k]] {
                    assert_eq!(s.jac.to_bits(), one.jac.to_bits(), "cell {k}");
                    assert_eq!(
                        s.volumetric_growth.to_bits(),
                        one.volumetric_growth.to_bits(),
                        "cell {k}"
                    );
                    assert_eq!(
                        s.lowest_corner.to_bits(),
                        one.lowest_corner.to_bits(),
                        "cell {k}"
                    );
                }
                assert_eq!(one.jac, deformation_gradient(&xc, p.grad_scale).1);
                let exact = volumetric_growth(&p, &xc);
                assert!(
                    (one.volumetric_growth - exact).abs() <= 1e-13 * exact.abs(),
                    "cell {k}: {} vs {exact}",
                    one.volumetric_growth
                );
                let corner = corner_jacobians(&xc, inv_h3).1;
                assert_eq!(
                    one.lowest_corner,
                    corner.into_iter().fold(f64::INFINITY, f64::min)
                );
                lowest_seen = lowest_seen.min(one.lowest_corner);
            }
            assert!(lowest_seen < 0.0 && portable[9].jac < 0.0, "{lowest_seen}");
        }
    }

    /// The corner barrier's law: zero from its start on, its slope and
    /// curvature the derivatives of its energy (continuous through the
    /// start), and the branch-free slope of every number type the same as
    /// the law's.
    #[test]
    fn corner_barrier_law_is_smooth_and_its_slope_consistent() {
        let s = CORNER_BARRIER_START;
        assert_eq!(corner_barrier_law(s), (0.0, 0.0, 0.0));
        assert_eq!(corner_barrier_law(2.0), (0.0, 0.0, 0.0));
        assert_eq!(corner_barrier_law(0.0).0, CORNER_BARRIER_DEPTH);
        let eps = 1e-6;
        for j in [-0.5, -0.01, 0.0, 0.01, 0.1, 0.15, s - 1e-3] {
            let (e, slope, curvature) = corner_barrier_law(j);
            assert!(e > 0.0 && slope < 0.0 && curvature > 0.0, "{j}");
            let de = (corner_barrier_law(j + eps).0 - corner_barrier_law(j - eps).0) / (2.0 * eps);
            let ds = (corner_barrier_law(j + eps).1 - corner_barrier_law(j - eps).1) / (2.0 * eps);
            assert!(
                (de - slope).abs() <= 1e-6 * slope.abs().max(1.0),
                "{j}: {de} {slope}"
            );
            assert!(
                (ds - curvature).abs() <= 1e-5 * curvature.max(1.0),
                "{j}: {ds} {curvature}"
            );
            let fast = corner_barrier_slope(j);
            assert!(
                (fast - slope).abs() <= 1e-13 * slope.abs(),
                "{j}: {fast} {slope}"
            );
            let lanes = corner_barrier_slope(Lanes::<f64, 4>([j; 4]));
            assert_eq!(lanes.0.map(f64::to_bits), [fast.to_bits(); 4]);
        }
        // Continuous through the start (value, slope and curvature).
        let (la, lb) = (corner_barrier_law(s - 1e-9), corner_barrier_law(s + 1e-9));
        assert!(la.0 < 1e-20 && la.1.abs() < 1e-12 && la.2 < 1e-5, "{la:?}");
        assert_eq!(lb, (0.0, 0.0, 0.0));
    }
}
