//! Adam's update loops: one step of one group (or of both SH groups together) over every
//! Gaussian, in rayon tasks of contiguous Gaussians, vectorised, with the NaN/Inf check fused
//! in. The state, the rates and the group switches live in `adam.rs`.

use rayon::prelude::*;

use super::{GAUSSIANS_PER_TASK, Moments, NonFinite, ParamGroup};
use crate::raster::MAX_LABEL_CHANNELS;
use crate::simd::simd_dispatch;

/// Hyper-parameters of one update, shared by every task.
#[derive(Clone, Copy)]
pub(super) struct Update<'a> {
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub bias1: f32,
    pub bias2_sqrt: f32,
    pub frozen: &'a [bool],
    pub visible: Option<&'a [bool]>,
    /// Per Gaussian, a factor on `lr` (None: 1).
    pub rate: Option<&'a [f32]>,
}

/// What an update found not finite among the gradients it read and the values it wrote, as the
/// OR of `x * 0` bit patterns: `±0` for finite `x`, NaN otherwise. Integer ORs vectorise with
/// the update (a float sum would not: it cannot be reordered) and cost nothing next to its
/// memory traffic, which is why the training loop's guards live here rather than in two more
/// passes over the gradients and parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct FiniteCheck {
    grad_bits: u32,
    param_bits: u32,
}

impl FiniteCheck {
    #[inline(always)]
    fn see(&mut self, grad: f32, param: f32) {
        self.grad_bits |= (grad * 0.0).to_bits();
        self.param_bits |= (param * 0.0).to_bits();
    }

    pub fn merge(self, other: FiniteCheck) -> FiniteCheck {
        FiniteCheck {
            grad_bits: self.grad_bits | other.grad_bits,
            param_bits: self.param_bits | other.param_bits,
        }
    }

    pub fn verdict(self, group: ParamGroup) -> Option<NonFinite> {
        const MAGNITUDE: u32 = 0x7FFF_FFFF;
        if self.grad_bits & MAGNITUDE != 0 {
            Some(NonFinite::Gradient(group))
        } else if self.param_bits & MAGNITUDE != 0 {
            Some(NonFinite::Parameter(group))
        } else {
            None
        }
    }
}

/// One Adam update of a contiguous run of values (vectorisable: no indexing in the loop).
#[inline(always)]
fn adam_run(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], u: &Update) -> FiniteCheck {
    let step_size = u.lr / u.bias1;
    let inv_bias2_sqrt = 1.0 / u.bias2_sqrt;
    let mut check = FiniteCheck::default();
    for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
        *m = u.beta1 * *m + (1.0 - u.beta1) * g;
        *v = u.beta2 * *v + (1.0 - u.beta2) * g * g;
        *p -= step_size * *m / (v.sqrt() * inv_bias2_sqrt + u.eps);
        check.see(g, *p);
    }
    check
}

/// [`adam_run`] where only values with `keep` set change: every lane computes the update and a
/// select keeps or drops it, so the loop stays one vector loop (a branch per Gaussian would
/// leave 1–4 values between branches, all scalar square roots and divisions). The kept lanes
/// get the same bits as `adam_run`. Only kept lanes are checked: a dropped lane's gradient
/// changes nothing and its parameter is not written, so a reported gradient is always one that
/// damaged its parameter.
#[inline(always)]
fn adam_run_masked(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    keep: &[bool],
    u: &Update,
) -> FiniteCheck {
    let step_size = u.lr / u.bias1;
    let inv_bias2_sqrt = 1.0 / u.bias2_sqrt;
    let mut check = FiniteCheck::default();
    for ((((p, &g), m), v), &k) in p
        .iter_mut()
        .zip(g)
        .zip(m.iter_mut())
        .zip(v.iter_mut())
        .zip(keep)
    {
        let m_new = u.beta1 * *m + (1.0 - u.beta1) * g;
        let v_new = u.beta2 * *v + (1.0 - u.beta2) * g * g;
        let p_new = *p - step_size * m_new / (v_new.sqrt() * inv_bias2_sqrt + u.eps);
        *m = if k { m_new } else { *m };
        *v = if k { v_new } else { *v };
        *p = if k { p_new } else { *p };
        check.see(if k { g } else { 0.0 }, if k { *p } else { 0.0 });
    }
    check
}

/// Gaussians whose keep flags a contiguous group expands per value at a time (on the stack).
const BLOCK_GAUSSIANS: usize = 64;
/// Most values per Gaussian of a contiguous group (the label channels can be the widest).
const MAX_CONTIGUOUS: usize = if MAX_LABEL_CHANNELS > 4 {
    MAX_LABEL_CHANNELS
} else {
    4
};

/// One rayon task of [`update_group`]: Gaussians `first..first + p.len() / stride`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn update_chunk_impl(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    first: usize,
    stride: usize,
    offset: usize,
    len: usize,
    u: &Update,
) -> FiniteCheck {
    let count = p.len() / stride;
    let mut check = FiniteCheck::default();
    let keeps = |gi: usize| !(u.frozen[gi] || u.visible.is_some_and(|vis| !vis[gi]));
    if stride == len && len <= MAX_CONTIGUOUS && u.rate.is_none() {
        // The group is the whole array: blocks of Gaussians, one flat (masked) run each.
        let mut keep = [false; BLOCK_GAUSSIANS * MAX_CONTIGUOUS];
        let mut start = 0;
        while start < count {
            let end = count.min(start + BLOCK_GAUSSIANS);
            let mut all = true;
            for i in start..end {
                let k = keeps(first + i);
                all &= k;
                let at = (i - start) * len;
                keep[at..at + len].fill(k);
            }
            let vals = start * len..end * len;
            let (p, g) = (&mut p[vals.clone()], &g[vals.clone()]);
            let (m, v) = (&mut m[vals.clone()], &mut v[vals]);
            check = check.merge(if all {
                adam_run(p, g, m, v, u)
            } else {
                adam_run_masked(p, g, m, v, &keep[..(end - start) * len], u)
            });
            start = end;
        }
        return check;
    }
    for i in 0..count {
        if !keeps(first + i) {
            continue;
        }
        let at = i * stride + offset;
        let scaled;
        let u = match u.rate {
            Some(rate) => {
                scaled = Update {
                    lr: u.lr * rate[first + i],
                    ..*u
                };
                &scaled
            }
            None => u,
        };
        check = check.merge(adam_run(
            &mut p[at..at + len],
            &g[at..at + len],
            &mut m[i * len..(i + 1) * len],
            &mut v[i * len..(i + 1) * len],
            u,
        ));
    }
    check
}

simd_dispatch!(
    /// [`update_chunk_impl`] with AVX2 (or AVX-512VL) where the CPU has it: 8 square roots and
    /// divisions per instruction instead of 4. Both are correctly rounded, so the bits are the
    /// same.
    update_chunk => update_chunk_impl(
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        first: usize,
        stride: usize,
        offset: usize,
        len: usize,
        u: &Update,
    ) -> FiniteCheck
);

/// One rayon task of [`update_sh_groups`]: Gaussians `first..first + p.len() / k3`, their DC
/// values (`dc`) then their higher bands (`rest`) one record at a time.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn update_sh_chunk_impl(
    p: &mut [f32],
    g: &[f32],
    dc: (&mut [f32], &mut [f32]),
    rest: (&mut [f32], &mut [f32]),
    first: usize,
    k3: usize,
    u_dc: &Update,
    u_rest: &Update,
) -> [FiniteCheck; 2] {
    let count = p.len() / k3;
    let r = k3 - 3;
    let (m_dc, v_dc) = dc;
    let (m_rest, v_rest) = rest;
    let mut checks = [FiniteCheck::default(); 2];
    for i in 0..count {
        // Frozen and visible flags are the same for both groups.
        if u_dc.frozen[first + i] || u_dc.visible.is_some_and(|vis| !vis[first + i]) {
            continue;
        }
        let (p_dc, p_rest) = p[i * k3..(i + 1) * k3].split_at_mut(3);
        let (g_dc, g_rest) = g[i * k3..(i + 1) * k3].split_at(3);
        checks[0] = checks[0].merge(adam_run(
            p_dc,
            g_dc,
            &mut m_dc[i * 3..(i + 1) * 3],
            &mut v_dc[i * 3..(i + 1) * 3],
            u_dc,
        ));
        checks[1] = checks[1].merge(adam_run(
            p_rest,
            g_rest,
            &mut m_rest[i * r..(i + 1) * r],
            &mut v_rest[i * r..(i + 1) * r],
            u_rest,
        ));
    }
    checks
}

simd_dispatch!(
    /// [`update_sh_chunk_impl`] with AVX2 (or AVX-512VL) where the CPU has it.
    update_sh_chunk => update_sh_chunk_impl(
        p: &mut [f32],
        g: &[f32],
        dc: (&mut [f32], &mut [f32]),
        rest: (&mut [f32], &mut [f32]),
        first: usize,
        k3: usize,
        u_dc: &Update,
        u_rest: &Update,
    ) -> [FiniteCheck; 2]
);

/// Both SH groups in one pass over the SH records (`k3` values per Gaussian: DC first), so each
/// record and its gradient are read once instead of once per group. The same values, in the
/// same order, as two [`update_group`] calls.
pub(super) fn update_sh_groups(
    params: &mut [f32],
    grads: &[f32],
    (dc, rest): (&mut Moments, &mut Moments),
    k3: usize,
    u_dc: Update,
    u_rest: Update,
) -> [FiniteCheck; 2] {
    let chunk = GAUSSIANS_PER_TASK;
    let r = k3 - 3;
    params
        .par_chunks_mut(k3 * chunk)
        .zip(grads.par_chunks(k3 * chunk))
        .zip(
            dc.m.par_chunks_mut(3 * chunk)
                .zip(dc.v.par_chunks_mut(3 * chunk)),
        )
        .zip(
            rest.m
                .par_chunks_mut(r * chunk)
                .zip(rest.v.par_chunks_mut(r * chunk)),
        )
        .enumerate()
        .map(|(t, (((p, g), dc), rest))| {
            update_sh_chunk(p, g, dc, rest, t * chunk, k3, &u_dc, &u_rest)
        })
        .reduce(
            || [FiniteCheck::default(); 2],
            |a, b| [a[0].merge(b[0]), a[1].merge(b[1])],
        )
}

/// Updates one group stored with `stride` values per Gaussian of which `offset..offset+len`
/// belong to the group (`len == m.per_gaussian`); `grads` has the parameters' layout.
pub(super) fn update_group(
    params: &mut [f32],
    grads: &[f32],
    mom: &mut Moments,
    stride: usize,
    offset: usize,
    u: Update,
) -> FiniteCheck {
    let len = mom.per_gaussian;
    if len == 0 || params.is_empty() {
        return FiniteCheck::default();
    }
    let chunk = GAUSSIANS_PER_TASK;
    params
        .par_chunks_mut(stride * chunk)
        .zip(grads.par_chunks(stride * chunk))
        .zip(
            mom.m
                .par_chunks_mut(len * chunk)
                .zip(mom.v.par_chunks_mut(len * chunk)),
        )
        .enumerate()
        .map(|(t, ((p, g), (m, v)))| update_chunk(p, g, m, v, t * chunk, stride, offset, len, &u))
        .reduce(FiniteCheck::default, FiniteCheck::merge)
}
