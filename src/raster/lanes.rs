//! `F8`: eight f32 lanes, one per Gaussian, with the arithmetic the projection needs, so that its
//! maths reads like scalar code but runs on eight Gaussians at once. Every operation is a plain
//! loop over the lanes, which LLVM turns into one AVX instruction; nothing here branches.

use std::ops::{Add, BitAnd, Div, Mul, Neg, Not, Sub};

use super::lane_math::{exp_lane, ln_lane, sigmoid_lane};

/// Gaussians per group: 8 f32 lanes fill an AVX2 register.
pub(crate) const LANES: usize = 8;

/// One f32 per lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct F8(pub [f32; LANES]);

/// One flag per lane (a compare's result).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct M8(pub [bool; LANES]);

impl F8 {
    #[inline(always)]
    pub fn splat(v: f32) -> F8 {
        F8([v; LANES])
    }

    // Plain index loops rather than `std::array::from_fn`/`map`: those are not always inlined
    // into the AVX-compiled callers, and a call per operation leaves nothing to vectorise.
    #[inline(always)]
    pub fn from_fn(f: impl Fn(usize) -> f32) -> F8 {
        let mut out = [0.0; LANES];
        for (l, v) in out.iter_mut().enumerate() {
            *v = f(l);
        }
        F8(out)
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        F8::from_fn(|l| f(self.0[l]))
    }

    #[inline(always)]
    fn zip(self, o: F8, f: impl Fn(f32, f32) -> f32) -> F8 {
        F8::from_fn(|l| f(self.0[l], o.0[l]))
    }

    #[inline(always)]
    fn cmp(self, o: F8, f: impl Fn(f32, f32) -> bool) -> M8 {
        let mut out = [false; LANES];
        for (l, m) in out.iter_mut().enumerate() {
            *m = f(self.0[l], o.0[l]);
        }
        M8(out)
    }

    #[inline(always)]
    pub fn sqrt(self) -> F8 {
        self.map(f32::sqrt)
    }

    #[inline(always)]
    pub fn ceil(self) -> F8 {
        self.map(f32::ceil)
    }

    #[inline(always)]
    pub fn exp(self) -> F8 {
        self.map(exp_lane)
    }

    /// `1 / (1 + e^-x)`, the opacity activation.
    #[inline(always)]
    pub fn sigmoid(self) -> F8 {
        self.map(sigmoid_lane)
    }

    #[inline(always)]
    pub fn ln(self) -> F8 {
        self.map(ln_lane)
    }

    /// `f32::max` per lane (a NaN lane takes `o`).
    #[inline(always)]
    pub fn max(self, o: F8) -> F8 {
        self.zip(o, f32::max)
    }

    /// `f32::min` per lane (a NaN lane takes `o`).
    #[inline(always)]
    pub fn min(self, o: F8) -> F8 {
        self.zip(o, f32::min)
    }

    /// `self.max(lo).min(hi)` per lane, as gsplat clamps the Jacobian's x / z and y / z.
    #[inline(always)]
    pub fn clamp(self, lo: f32, hi: f32) -> F8 {
        self.max(F8::splat(lo)).min(F8::splat(hi))
    }

    #[inline(always)]
    pub fn gt(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a > b)
    }

    #[inline(always)]
    pub fn lt(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a < b)
    }

    #[inline(always)]
    pub fn ge(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a >= b)
    }

    #[inline(always)]
    pub fn le(self, o: F8) -> M8 {
        self.cmp(o, |a, b| a <= b)
    }

    #[inline(always)]
    pub fn is_nan(self) -> M8 {
        self.cmp(self, |a, _| a.is_nan())
    }

    /// `if mask { a } else { b }` per lane.
    #[inline(always)]
    pub fn select(mask: M8, a: F8, b: F8) -> F8 {
        F8::from_fn(|l| if mask.0[l] { a.0[l] } else { b.0[l] })
    }
}

impl BitAnd for M8 {
    type Output = M8;
    #[inline(always)]
    fn bitand(self, o: M8) -> M8 {
        let mut out = self.0;
        for (m, o) in out.iter_mut().zip(o.0) {
            *m &= o;
        }
        M8(out)
    }
}

impl Not for M8 {
    type Output = M8;
    #[inline(always)]
    fn not(self) -> M8 {
        let mut out = self.0;
        for m in &mut out {
            *m = !*m;
        }
        M8(out)
    }
}

impl Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|a| -a)
    }
}

/// `F8 op F8`, `F8 op f32` and `f32 op F8`, lane by lane.
macro_rules! lane_op {
    ($trait:ident, $method:ident, $op:tt) => {
        impl $trait for F8 {
            type Output = F8;
            #[inline(always)]
            fn $method(self, o: F8) -> F8 {
                self.zip(o, |a, b| a $op b)
            }
        }
        impl $trait<f32> for F8 {
            type Output = F8;
            #[inline(always)]
            fn $method(self, o: f32) -> F8 {
                self.map(|a| a $op o)
            }
        }
        impl $trait<F8> for f32 {
            type Output = F8;
            #[inline(always)]
            fn $method(self, o: F8) -> F8 {
                o.map(|b| self $op b)
            }
        }
    };
}

lane_op!(Add, add, +);
lane_op!(Sub, sub, -);
lane_op!(Mul, mul, *);
lane_op!(Div, div, /);

// The builders below are written out rather than looped: a loop over matrix entries of F8
// values tempts LLVM's loop vectoriser to vectorise across entries, with gathers and scatters.

/// `[f(0), f(1), f(2)]`.
#[inline(always)]
pub(crate) fn build3(f: impl Fn(usize) -> F8) -> [F8; 3] {
    [f(0), f(1), f(2)]
}

/// `[f(0), f(1), f(2), f(3)]`.
#[inline(always)]
pub(crate) fn build4(f: impl Fn(usize) -> F8) -> [F8; 4] {
    [f(0), f(1), f(2), f(3)]
}

/// The 3×3 matrix with entries `f(row, col)`.
#[inline(always)]
pub(crate) fn build3x3(f: impl Fn(usize, usize) -> F8) -> [[F8; 3]; 3] {
    [
        [f(0, 0), f(0, 1), f(0, 2)],
        [f(1, 0), f(1, 1), f(1, 2)],
        [f(2, 0), f(2, 1), f(2, 2)],
    ]
}

/// `v[start..start + live]` copied into a group, the last element repeated into the missing
/// lanes (their results are dropped; repeating a real Gaussian keeps them harmless).
#[inline(always)]
pub(crate) fn group_of<T: Copy>(v: &[T], start: usize, live: usize) -> [T; LANES] {
    match v.get(start..start + LANES) {
        Some(full) if live == LANES => {
            let mut out = [full[0]; LANES];
            out.copy_from_slice(full);
            out
        }
        _ => {
            let mut out = [v[start + live - 1]; LANES];
            out[..live].copy_from_slice(&v[start..start + live]);
            out
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{F8, M8};

    #[test]
    fn select_and_compares_treat_nan_as_false() {
        let a = F8::from_fn(|l| if l == 3 { f32::NAN } else { l as f32 });
        let gt = a.gt(F8::splat(-1.0));
        assert!(!gt.0[3]);
        assert!(gt.0[2]);
        let s = F8::select(gt, a, F8::splat(9.0));
        assert_eq!(s.0[3], 9.0);
        assert_eq!(s.0[5], 5.0);
        assert_eq!((!gt & gt), M8::default());
    }
}
