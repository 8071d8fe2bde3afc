//! The machine's rate of vector arithmetic on one core, in the kernel's
//! vector width: the arithmetic bound of the force pass
//! ([`mss_core::Model::force_operations`] over these rates).

use std::time::Instant;

/// Lane operations per second: additions and multiplications (the
/// adders' and multipliers' pipelined rate, independent chains) and
/// square roots and divisions (their unit's rate).
#[derive(Clone, Copy, Debug)]
pub struct ArithRate {
    /// Additions and multiplications per second, counted per lane.
    pub pipelined: f64,
    /// Square roots and divisions per second, counted per lane.
    pub divide: f64,
}

/// [`ArithRate`] of `f64` lanes on the widest vectors the force pass uses
/// on this CPU (AVX-512: 8 lanes; AVX2: 4), `None` elsewhere.
pub fn f64_rate() -> Option<ArithRate> {
    #[cfg(target_arch = "x86_64")]
    {
        let avx512 = std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512dq")
            && std::arch::is_x86_feature_detected!("avx512vl");
        if avx512 {
            // SAFETY: the CPU has AVX-512F.
            return Some(unsafe { x86::rate_avx512() });
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return Some(unsafe { x86::rate_avx2() });
        }
    }
    None
}

/// `ops` over the shortest of five timings of `f`: noise only adds time.
fn fastest_rate(ops: f64, mut f: impl FnMut()) -> f64 {
    (0..5)
        .map(|_| {
            let t = Instant::now();
            f();
            ops / t.elapsed().as_secs_f64()
        })
        .fold(0.0, f64::max)
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{ArithRate, fastest_rate};
    use std::arch::x86_64::*;
    use std::hint::black_box;

    const ROUNDS: usize = 1 << 20;

    macro_rules! rate {
        ($name:ident, $feature:literal, $t:ty, $lanes:literal, $set1:ident, $add:ident, $mul:ident, $sqrt:ident, $div:ident) => {
            #[target_feature(enable = $feature)]
            pub unsafe fn $name() -> ArithRate {
                let pipelined = fastest_rate((12 * ROUNDS * $lanes) as f64, || {
                    let c = $set1(black_box(1e-12));
                    let m = $set1(black_box(0.999_999_9));
                    let mut v: [$t; 12] = std::array::from_fn(|i| $set1(1.0 + i as f64));
                    for _ in 0..ROUNDS {
                        for a in &mut v[..6] {
                            *a = $add(*a, c);
                        }
                        for a in &mut v[6..] {
                            *a = $mul(*a, m);
                        }
                    }
                    black_box(v);
                });
                let divide = fastest_rate((8 * ROUNDS / 4 * $lanes) as f64, || {
                    let d = $set1(black_box(1.000_000_1));
                    let mut v: [$t; 8] = std::array::from_fn(|i| $set1(1.0 + i as f64));
                    for _ in 0..ROUNDS / 4 {
                        for a in &mut v[..4] {
                            *a = $sqrt(*a);
                        }
                        for a in &mut v[4..] {
                            *a = $div(*a, d);
                        }
                    }
                    black_box(v);
                });
                ArithRate { pipelined, divide }
            }
        };
    }
    rate!(
        rate_avx512,
        "avx512f",
        __m512d,
        8,
        _mm512_set1_pd,
        _mm512_add_pd,
        _mm512_mul_pd,
        _mm512_sqrt_pd,
        _mm512_div_pd
    );
    rate!(
        rate_avx2,
        "avx2",
        __m256d,
        4,
        _mm256_set1_pd,
        _mm256_add_pd,
        _mm256_mul_pd,
        _mm256_sqrt_pd,
        _mm256_div_pd
    );
}
