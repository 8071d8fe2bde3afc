//! A number type that counts the operations done on it: the force kernel
//! run on it once says how many additions, multiplications, divisions and
//! square roots one SIMD lane performs per cell, the figure against which
//! the pass's time is set beside the machine's arithmetic rate
//! ([`crate::Model::force_operations`]).

use std::cell::Cell;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use super::{InverseSqrtSeed, Scalar, SplitExponent};
use crate::model::ForceOperations;

thread_local! {
    static COUNTS: Cell<ForceOperations> = const { Cell::new(ForceOperations::ZERO) };
}

/// Adds one operation of the kind `pick` selects to this thread's counts.
fn tally(pick: fn(&mut ForceOperations) -> &mut u64) {
    COUNTS.with(|c| {
        let mut counts = c.get();
        *pick(&mut counts) += 1;
        c.set(counts);
    });
}

/// Runs `f` and returns the operations it did on [`Counted`] values (on
/// this thread).
pub(crate) fn count(f: impl FnOnce()) -> ForceOperations {
    COUNTS.with(|c| c.set(ForceOperations::ZERO));
    f();
    COUNTS.with(|c| c.get())
}

/// An `f64` whose every operation is counted. Constants (`cst`) are not:
/// the SIMD paths hold them in registers or read them as operands.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Counted(pub f64);

macro_rules! counted_binary {
    ($trait:ident, $method:ident, $op:tt, $kind:ident) => {
        impl $trait for Counted {
            type Output = Self;
            fn $method(self, o: Self) -> Self {
                tally(|c| &mut c.$kind);
                Counted(self.0 $op o.0)
            }
        }
    };
}
counted_binary!(Add, add, +, add);
counted_binary!(Sub, sub, -, add);
counted_binary!(Mul, mul, *, mul);
counted_binary!(Div, div, /, div);

impl Neg for Counted {
    type Output = Self;
    fn neg(self) -> Self {
        tally(|c| &mut c.other);
        Counted(-self.0)
    }
}
impl AddAssign for Counted {
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl SubAssign for Counted {
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}

impl Scalar for Counted {
    fn cst(v: f64) -> Self {
        Counted(v)
    }
    fn scale(self, k: f64) -> Self {
        self * Counted(k)
    }
    fn sqrt(self) -> Self {
        tally(|c| &mut c.sqrt);
        Counted(self.0.sqrt())
    }
    fn apply(self, f: fn(f64) -> (f64, f64)) -> Self {
        tally(|c| &mut c.other);
        Counted(f(self.0).0)
    }
    // As the SIMD types do: the logarithm in plain arithmetic.
    fn barrier_slope(self) -> Self {
        super::fast_barrier_slope(self)
    }
    fn at_least(self, o: Self) -> Self {
        tally(|c| &mut c.other);
        if o.0 > self.0 { o } else { self }
    }
    fn any_below(self, v: f64) -> bool {
        tally(|c| &mut c.other);
        self.0 < v
    }
}

impl SplitExponent for Counted {
    fn split_exponent(self) -> (Self, Self) {
        // The SIMD split: a shift, a subtraction and an `or` in integer lanes,
        // a comparison and a blend for the mantissas above sqrt(2), and the
        // exponent's conversion to floating point.
        for _ in 0..6 {
            tally(|c| &mut c.other);
        }
        let (m, k) = <f64 as super::Element>::split(self.0);
        (Counted(m), Counted(k))
    }
}

impl InverseSqrtSeed for Counted {
    fn inverse_sqrt_seed(self) -> Self {
        // A single-precision square root and division, and the two
        // conversions.
        tally(|c| &mut c.sqrt);
        tally(|c| &mut c.div);
        tally(|c| &mut c.other);
        tally(|c| &mut c.other);
        Counted(1.0 / self.0.sqrt())
    }
}
