//! The velocity kick and the drift of the explicit step over a chunk of
//! nodes: straight passes over a few arrays, which run at the speed of the
//! loads when they are vectorized. On AVX-512 a kick takes eight nodes per
//! pass (their 24 components in three registers, each node's mass and step
//! spread over its three components by a permutation); every lane performs
//! the operations of the node-by-node kick in the same order, so the same
//! bits.

use crate::Vec3;

/// One chunk's share of a kick.
pub(super) struct ChunkKick<'a> {
    /// The conservative force per node.
    pub f: &'a [Vec3],
    /// The lumped mass per node (for mass damping).
    pub masses: &'a [f64],
    /// `h / m` per node.
    pub scale: &'a [f64],
    /// Held components per node (bit `c` for component `c`).
    pub held: &'a [u8],
    /// Mass damping (1/s).
    pub alpha: f64,
}

impl ChunkKick<'_> {
    /// `v += F (h / m)` on the free components of the chunk's nodes, with
    /// `F = complete(k, f - alpha m v)` (`k`: index in the chunk). Returns
    /// false on non-finite values.
    #[inline(always)]
    pub fn apply(&self, v: &mut [Vec3], complete: impl Fn(usize, Vec3) -> Vec3) -> bool {
        let mut ok = true;
        for (k, vi) in v.iter_mut().enumerate() {
            ok &= self.node(k, vi, &complete);
        }
        ok
    }

    /// [`ChunkKick::apply`] with `F = f - alpha m v + extra[k]` (`extra`:
    /// the contact forces, when there are any), eight nodes per pass where
    /// the CPU runs AVX-512: the same bits.
    pub fn apply_with(&self, v: &mut [Vec3], extra: Option<&[Vec3]>) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            if crate::model::kernel::has_avx512() {
                // SAFETY: the CPU has AVX-512F and DQ (checked).
                return unsafe {
                    match extra {
                        Some(e) => self.apply_avx512::<true>(v, e),
                        None => self.apply_avx512::<false>(v, &[]),
                    }
                };
            }
        }
        match extra {
            Some(e) => self.apply(v, |k, force| force + e[k]),
            None => self.apply(v, |_, force| force),
        }
    }

    /// The kick of node `k` of the chunk; whether its velocity is finite.
    #[inline(always)]
    fn node(&self, k: usize, vi: &mut Vec3, complete: impl Fn(usize, Vec3) -> Vec3) -> bool {
        let force = complete(k, self.f[k] - *vi * (self.alpha * self.masses[k]));
        let dv = force * self.scale[k];
        let held = self.held[k];
        if held == 0 {
            *vi += dv;
        } else {
            for c in 0..3 {
                if held & (1 << c) == 0 {
                    vi[c] += dv[c];
                }
            }
        }
        all_finite(vi)
    }

    /// [`ChunkKick::apply_with`] on AVX-512: eight nodes at a time, those
    /// of a group with a held component node by node.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512dq")]
    fn apply_avx512<const EXTRA: bool>(&self, v: &mut [Vec3], extra: &[Vec3]) -> bool {
        use std::arch::x86_64::*;
        let n = v.len();
        assert!(self.f.len() >= n && self.masses.len() >= n && self.scale.len() >= n);
        assert!(self.held.len() >= n && (!EXTRA || extra.len() >= n));
        let complete = |k: usize, force: Vec3| if EXTRA { force + extra[k] } else { force };
        let mut ok = true;
        let mut bad: __mmask8 = 0;
        let whole = n / 8 * 8;
        // Lane l of register r holds component (8 r + l) % 3 of node
        // (8 r + l) / 3 of the group.
        let spread = [
            _mm512_setr_epi64(0, 0, 0, 1, 1, 1, 2, 2),
            _mm512_setr_epi64(2, 3, 3, 3, 4, 4, 4, 5),
            _mm512_setr_epi64(5, 5, 6, 6, 6, 7, 7, 7),
        ];
        let alpha = _mm512_set1_pd(self.alpha);
        let vp = v.as_mut_ptr().cast::<f64>();
        let fp = self.f.as_ptr().cast::<f64>();
        let ep = extra.as_ptr().cast::<f64>();
        for base in (0..whole).step_by(8) {
            let held = u64::from_le_bytes(self.held[base..base + 8].try_into().expect("8 bytes"));
            if held != 0 {
                for (k, vi) in v.iter_mut().enumerate().skip(base).take(8) {
                    ok &= self.node(k, vi, complete);
                }
                continue;
            }
            // SAFETY: nodes base..base + 8 exist in `v`, `f`, `masses`,
            // `scale` (and `extra`), asserted: 24 f64 from 3 base each.
            unsafe {
                let m = _mm512_loadu_pd(self.masses.as_ptr().add(base));
                let s = _mm512_loadu_pd(self.scale.as_ptr().add(base));
                let am = _mm512_mul_pd(alpha, m);
                for (r, idx) in spread.iter().enumerate() {
                    let at = 3 * base + 8 * r;
                    let vv = _mm512_loadu_pd(vp.add(at));
                    let damped = _mm512_mul_pd(vv, _mm512_permutexvar_pd(*idx, am));
                    let mut force = _mm512_sub_pd(_mm512_loadu_pd(fp.add(at)), damped);
                    if EXTRA {
                        force = _mm512_add_pd(force, _mm512_loadu_pd(ep.add(at)));
                    }
                    let dv = _mm512_mul_pd(force, _mm512_permutexvar_pd(*idx, s));
                    let kicked = _mm512_add_pd(vv, dv);
                    _mm512_storeu_pd(vp.add(at), kicked);
                    // NaN, +inf, -inf: not finite.
                    bad |= _mm512_fpclass_pd_mask::<0x99>(kicked);
                }
            }
        }
        for (k, vi) in v.iter_mut().enumerate().skip(whole) {
            ok &= self.node(k, vi, complete);
        }
        ok && bad == 0
    }
}

/// `x += dt v` over a chunk; false if a position is not finite. A flat
/// loop over the components, which the compiler vectorizes: eight at a
/// time where the CPU has AVX-512 (compiled for the baseline, it took two,
/// and a fifth of the sub-step's node passes), the same operations per
/// component either way.
pub(super) fn drift(x: &mut [Vec3], v: &[Vec3], dt: f64) -> bool {
    #[cfg(target_arch = "x86_64")]
    if crate::model::kernel::has_avx512() {
        // SAFETY: the CPU has AVX-512F (checked just above).
        return unsafe { drift_avx512(x, v, dt) };
    }
    drift_flat(x, v, dt)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
fn drift_avx512(x: &mut [Vec3], v: &[Vec3], dt: f64) -> bool {
    drift_flat(x, v, dt)
}

#[inline(always)]
fn drift_flat(x: &mut [Vec3], v: &[Vec3], dt: f64) -> bool {
    let xs = crate::as_arrays_mut(x).as_flattened_mut();
    let vs = crate::as_arrays(v).as_flattened();
    let mut finite = true;
    for (x, v) in xs.iter_mut().zip(vs) {
        *x += *v * dt;
        finite &= x.is_finite();
    }
    finite
}

/// Whether all three components are finite, without a branch (a
/// short-circuiting test per value costs more than the kick it checks).
#[inline(always)]
pub(super) fn all_finite(v: &Vec3) -> bool {
    v.x.is_finite() & v.y.is_finite() & v.z.is_finite()
}

/// `dst.copy_from_slice(src)` with stores that bypass the caches where the
/// CPU has them (x86-64's `movntpd`), then a store fence: the step's start
/// state, which is read again only if the step is taken again. Copied
/// through the caches, each line of `dst` was first read from memory (the
/// copy was 7 % of a 64^3 step, more than its share of bytes).
pub(super) fn copy_past_caches(dst: &mut [Vec3], src: &[Vec3]) {
    assert_eq!(dst.len(), src.len(), "copy of equal lengths");
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_loadu_pd, _mm_sfence, _mm_stream_pd};
        let d = crate::as_arrays_mut(dst).as_flattened_mut();
        let s = crate::as_arrays(src).as_flattened();
        // The first value alone where `d` is not 16-byte aligned (Vec3 is
        // 8-byte aligned): the streaming stores need aligned addresses.
        let head = (d.as_ptr() as usize / 8) % 2;
        let head = head.min(d.len());
        d[..head].copy_from_slice(&s[..head]);
        let (d, s) = (&mut d[head..], &s[head..]);
        let pairs = d.len() / 2;
        // SAFETY: SSE2 is part of x86-64; each store writes two f64 of `d`
        // at an even offset from its 16-byte aligned start, each load reads
        // two of `s`, both within their slices (2 k + 1 < 2 pairs <= len);
        // the fence orders the streaming stores before this thread's later
        // stores (the join that publishes `dst` to other threads).
        unsafe {
            for k in 0..pairs {
                _mm_stream_pd(
                    d.as_mut_ptr().add(2 * k),
                    _mm_loadu_pd(s.as_ptr().add(2 * k)),
                );
            }
            _mm_sfence();
        }
        d[2 * pairs..].copy_from_slice(&s[2 * pairs..]);
    }
    #[cfg(not(target_arch = "x86_64"))]
    dst.copy_from_slice(src);
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::noise;

    /// The copy past the caches copies every value, whatever the slices'
    /// alignment and length (odd and even counts of f64, empty).
    #[test]
    fn the_copy_past_caches_copies() {
        let mut seed = 3u64;
        let src: Vec<Vec3> = (0..12)
            .map(|_| Vec3::new(noise(&mut seed), noise(&mut seed), noise(&mut seed)))
            .collect();
        for from in 0..3 {
            for len in 0..9 {
                let mut dst = vec![Vec3::repeat(f64::NAN); 12];
                copy_past_caches(&mut dst[from..from + len], &src[from..from + len]);
                for (k, (d, s)) in dst.iter().zip(&src).enumerate() {
                    if (from..from + len).contains(&k) {
                        assert_eq!(d, s, "from {from}, len {len}, node {k}");
                    } else {
                        assert!(d.x.is_nan(), "from {from}, len {len}: node {k} untouched");
                    }
                }
            }
        }
    }

    /// The kick eight nodes at a time (where the CPU has AVX-512) gives the
    /// bits of the node-by-node kick, with and without contact forces, with
    /// held components in some groups and a tail shorter than eight; a
    /// non-finite velocity is reported wherever it lies.
    #[test]
    fn the_wide_kick_is_the_node_by_node_kick() {
        let mut seed = 7u64;
        let n = 8 * 6 + 5;
        let mut vec3 = |scale: f64| -> Vec<Vec3> {
            (0..n)
                .map(|_| Vec3::new(noise(&mut seed), noise(&mut seed), noise(&mut seed)) * scale)
                .collect()
        };
        let (f, extra, v0) = (vec3(3.0), vec3(0.5), vec3(1.0));
        let masses: Vec<f64> = (0..n).map(|k| 0.5 + (k % 7) as f64 * 0.1).collect();
        let scale: Vec<f64> = masses.iter().map(|m| 1e-3 / m).collect();
        let mut held = vec![0u8; n];
        held[9] = 0b101;
        held[30] = 0b010;
        held[n - 2] = 0b111;
        let kick = ChunkKick {
            f: &f,
            masses: &masses,
            scale: &scale,
            held: &held,
            alpha: 2.5,
        };
        for e in [None, Some(&extra[..])] {
            let (mut wide, mut one) = (v0.clone(), v0.clone());
            assert!(kick.apply_with(&mut wide, e));
            assert!(kick.apply(&mut one, |k, force| e.map_or(force, |e| force + e[k])));
            let bits = |v: &[Vec3]| -> Vec<u64> {
                v.iter()
                    .flat_map(|p| p.map(f64::to_bits).data.0[0])
                    .collect()
            };
            assert_eq!(bits(&wide), bits(&one));
            assert_eq!(wide[9].x, v0[9].x, "a held component keeps its velocity");
            assert_ne!(wide[9].y, v0[9].y);
        }
        for at in [3, 17, n - 1] {
            let mut broken = f.clone();
            broken[at].z = f64::NAN;
            let kick = ChunkKick { f: &broken, ..kick };
            assert!(!kick.apply_with(&mut v0.clone(), None), "NaN at node {at}");
        }
    }

    /// The drift over flat components: the node-by-node `x += dt v`, and a
    /// non-finite position reported.
    #[test]
    fn the_flat_drift_is_the_node_drift() {
        let mut x = vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 0.25)];
        let v = vec![Vec3::new(0.1, 0.2, 0.3), Vec3::new(3.0, -2.0, 1.0)];
        let want: Vec<Vec3> = x.iter().zip(&v).map(|(x, v)| x + v * 0.01).collect();
        assert!(drift(&mut x, &v, 0.01));
        assert_eq!(x, want);
        let v = vec![Vec3::zeros(), Vec3::new(0.0, f64::INFINITY, 0.0)];
        assert!(!drift(&mut x, &v, 0.01));
    }
}
