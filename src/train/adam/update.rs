//! Adam's update loops: one step of one group (or of both SH groups together) over every
//! Gaussian, or over only the listed ones whose moments a focused run keeps, in rayon tasks of
//! contiguous Gaussians (or of a contiguous part of the list), vectorised, with the NaN/Inf check
//! fused in. The state, the rates and the group switches live in `mod.rs`.

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

/// Which Gaussian each slot of a run of moments belongs to. The parameters and gradients passed
/// with the run start at Gaussian `base`.
#[derive(Clone, Copy)]
pub(super) enum Slots<'a> {
    /// Slot `i` is Gaussian `base + i`: every Gaussian has moments.
    Every,
    /// Slot `i` is Gaussian `list[i]` (ascending, at least `base`): only those have moments (the
    /// trainable ones of a focused run; `Adam::for_trainable`).
    Listed(&'a [u32]),
}

impl Slots<'_> {
    #[inline(always)]
    fn gaussian(&self, base: usize, slot: usize) -> usize {
        match self {
            Slots::Every => base + slot,
            Slots::Listed(list) => list[slot] as usize,
        }
    }

    /// Slots in a run whose parameters are `values` long, `stride` per Gaussian.
    fn count(&self, values: usize, stride: usize) -> usize {
        match self {
            Slots::Every => values / stride,
            Slots::Listed(list) => list.len(),
        }
    }
}

/// One rayon task of [`update_group`]: the Gaussians of `slots`, their parameters and gradients
/// from Gaussian `base` on.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn update_chunk_impl(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    base: usize,
    slots: Slots,
    stride: usize,
    offset: usize,
    len: usize,
    u: &Update,
) -> FiniteCheck {
    let count = slots.count(p.len(), stride);
    let mut check = FiniteCheck::default();
    let keeps = |gi: usize| !(u.frozen[gi] || u.visible.is_some_and(|vis| !vis[gi]));
    if stride == len && len <= MAX_CONTIGUOUS && u.rate.is_none() {
        // The group is the whole array: blocks of Gaussians, one flat (masked) run each. Listed
        // Gaussians are gathered into one run and scattered back, so their block is one vector
        // loop too (the update is per value: the same bits either way).
        let mut keep = [false; BLOCK_GAUSSIANS * MAX_CONTIGUOUS];
        let mut gathered_p = [0.0f32; BLOCK_GAUSSIANS * MAX_CONTIGUOUS];
        let mut gathered_g = [0.0f32; BLOCK_GAUSSIANS * MAX_CONTIGUOUS];
        let mut start = 0;
        while start < count {
            let end = count.min(start + BLOCK_GAUSSIANS);
            let values = (end - start) * len;
            let mut all = true;
            for i in start..end {
                let k = keeps(slots.gaussian(base, i));
                all &= k;
                let at = (i - start) * len;
                keep[at..at + len].fill(k);
            }
            let slot_values = start * len..end * len;
            let (m, v) = (&mut m[slot_values.clone()], &mut v[slot_values.clone()]);
            let keep = &keep[..values];
            let run = |p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32]| {
                if all {
                    adam_run(p, g, m, v, u)
                } else {
                    adam_run_masked(p, g, m, v, keep, u)
                }
            };
            check = check.merge(match slots {
                Slots::Every => run(&mut p[slot_values.clone()], &g[slot_values], m, v),
                Slots::Listed(list) => {
                    let list = &list[start..end];
                    for (j, &gi) in list.iter().enumerate() {
                        let at = (gi as usize - base) * len;
                        gathered_p[j * len..(j + 1) * len].copy_from_slice(&p[at..at + len]);
                        gathered_g[j * len..(j + 1) * len].copy_from_slice(&g[at..at + len]);
                    }
                    let found = run(&mut gathered_p[..values], &gathered_g[..values], m, v);
                    for (j, &gi) in list.iter().enumerate() {
                        let at = (gi as usize - base) * len;
                        p[at..at + len].copy_from_slice(&gathered_p[j * len..(j + 1) * len]);
                    }
                    found
                }
            });
            start = end;
        }
        return check;
    }
    for i in 0..count {
        let gi = slots.gaussian(base, i);
        if !keeps(gi) {
            continue;
        }
        let at = (gi - base) * stride + offset;
        let scaled;
        let u = match u.rate {
            Some(rate) => {
                scaled = Update {
                    lr: u.lr * rate[gi],
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
        base: usize,
        slots: Slots,
        stride: usize,
        offset: usize,
        len: usize,
        u: &Update,
    ) -> FiniteCheck
);

/// One rayon task of [`update_sh_groups`]: the Gaussians of `slots` (their SH records from
/// Gaussian `base` on), their DC values (`dc`) then their higher bands (`rest`) one record at
/// a time.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn update_sh_chunk_impl(
    p: &mut [f32],
    g: &[f32],
    dc: (&mut [f32], &mut [f32]),
    rest: (&mut [f32], &mut [f32]),
    base: usize,
    slots: Slots,
    k3: usize,
    u_dc: &Update,
    u_rest: &Update,
) -> [FiniteCheck; 2] {
    let count = slots.count(p.len(), k3);
    let r = k3 - 3;
    let (m_dc, v_dc) = dc;
    let (m_rest, v_rest) = rest;
    let mut checks = [FiniteCheck::default(); 2];
    for i in 0..count {
        let gi = slots.gaussian(base, i);
        // Frozen and visible flags are the same for both groups.
        if u_dc.frozen[gi] || u_dc.visible.is_some_and(|vis| !vis[gi]) {
            continue;
        }
        let at = (gi - base) * k3;
        let (p_dc, p_rest) = p[at..at + k3].split_at_mut(3);
        let (g_dc, g_rest) = g[at..at + k3].split_at(3);
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
        base: usize,
        slots: Slots,
        k3: usize,
        u_dc: &Update,
        u_rest: &Update,
    ) -> [FiniteCheck; 2]
);

/// Both SH groups in one pass over the SH records (`k3` values per Gaussian: DC first), so each
/// record and its gradient are read once instead of once per group. The same values, in the
/// same order, as two [`update_group`] calls. `listed`: the Gaussians the moments belong to
/// (None: every one).
pub(super) fn update_sh_groups(
    params: &mut [f32],
    grads: &[f32],
    (dc, rest): (&mut Moments, &mut Moments),
    k3: usize,
    (u_dc, u_rest): (Update, Update),
    listed: Option<&[u32]>,
) -> [FiniteCheck; 2] {
    let chunk = GAUSSIANS_PER_TASK;
    let r = k3 - 3;
    let dc = (dc.m.as_mut_slice(), dc.v.as_mut_slice());
    let rest = (rest.m.as_mut_slice(), rest.v.as_mut_slice());
    if let Some(list) = listed {
        return listed_sh(params, grads, 0, list, dc, rest, k3, (&u_dc, &u_rest));
    }
    params
        .par_chunks_mut(k3 * chunk)
        .zip(grads.par_chunks(k3 * chunk))
        .zip(
            dc.0.par_chunks_mut(3 * chunk)
                .zip(dc.1.par_chunks_mut(3 * chunk)),
        )
        .zip(
            rest.0
                .par_chunks_mut(r * chunk)
                .zip(rest.1.par_chunks_mut(r * chunk)),
        )
        .enumerate()
        .map(|(t, (((p, g), dc), rest))| {
            update_sh_chunk(p, g, dc, rest, t * chunk, Slots::Every, k3, &u_dc, &u_rest)
        })
        .reduce(
            || [FiniteCheck::default(); 2],
            |a, b| [a[0].merge(b[0]), a[1].merge(b[1])],
        )
}

/// [`update_sh_groups`] of the listed Gaussians `list` (records from Gaussian `base` on): halves
/// of the list in parallel down to a task's worth. The list ascends, so each half's records are
/// a slice of their own.
#[allow(clippy::too_many_arguments)]
fn listed_sh(
    p: &mut [f32],
    g: &[f32],
    base: usize,
    list: &[u32],
    dc: (&mut [f32], &mut [f32]),
    rest: (&mut [f32], &mut [f32]),
    k3: usize,
    u: (&Update, &Update),
) -> [FiniteCheck; 2] {
    if list.len() <= GAUSSIANS_PER_TASK {
        return update_sh_chunk(p, g, dc, rest, base, Slots::Listed(list), k3, u.0, u.1);
    }
    let mid = list.len() / 2;
    let split = list[mid] as usize;
    let (p_left, p_right) = p.split_at_mut((split - base) * k3);
    let (g_left, g_right) = g.split_at((split - base) * k3);
    let (dc_left, dc_right) = split_moments(dc, mid * 3);
    let (rest_left, rest_right) = split_moments(rest, mid * (k3 - 3));
    let (left, right) = rayon::join(
        || {
            listed_sh(
                p_left,
                g_left,
                base,
                &list[..mid],
                dc_left,
                rest_left,
                k3,
                u,
            )
        },
        || {
            listed_sh(
                p_right,
                g_right,
                split,
                &list[mid..],
                dc_right,
                rest_right,
                k3,
                u,
            )
        },
    );
    [left[0].merge(right[0]), left[1].merge(right[1])]
}

type MomentSlices<'a> = (&'a mut [f32], &'a mut [f32]);

/// First and second moments split at value `at`.
fn split_moments((m, v): MomentSlices<'_>, at: usize) -> (MomentSlices<'_>, MomentSlices<'_>) {
    let (m_left, m_right) = m.split_at_mut(at);
    let (v_left, v_right) = v.split_at_mut(at);
    ((m_left, v_left), (m_right, v_right))
}

/// Where one group's values sit in its parameter array: `stride` values per Gaussian, of which
/// `offset..offset + len` are the group's (`len == Moments::per_gaussian`).
#[derive(Clone, Copy)]
pub(super) struct GroupLayout {
    pub stride: usize,
    pub offset: usize,
    pub len: usize,
}

/// Updates one group laid out in `params` as `layout` says; `grads` has the parameters' layout.
/// `listed`: the Gaussians the moments belong to (None: every one).
pub(super) fn update_group(
    params: &mut [f32],
    grads: &[f32],
    mom: &mut Moments,
    layout: GroupLayout,
    u: Update,
    listed: Option<&[u32]>,
) -> FiniteCheck {
    let (stride, len) = (layout.stride, layout.len);
    if len == 0 || params.is_empty() {
        return FiniteCheck::default();
    }
    if let Some(list) = listed {
        let moments = (mom.m.as_mut_slice(), mom.v.as_mut_slice());
        return listed_group(params, grads, 0, list, moments, layout, &u);
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
        .map(|(t, ((p, g), (m, v)))| {
            let offset = layout.offset;
            update_chunk(p, g, m, v, t * chunk, Slots::Every, stride, offset, len, &u)
        })
        .reduce(FiniteCheck::default, FiniteCheck::merge)
}

/// [`update_group`] of the listed Gaussians `list` (parameters from Gaussian `base` on): halves
/// of the list in parallel down to a task's worth, as [`listed_sh`].
fn listed_group(
    p: &mut [f32],
    g: &[f32],
    base: usize,
    list: &[u32],
    (m, v): MomentSlices<'_>,
    layout: GroupLayout,
    u: &Update,
) -> FiniteCheck {
    let GroupLayout {
        stride,
        offset,
        len,
    } = layout;
    if list.len() <= GAUSSIANS_PER_TASK {
        return update_chunk(
            p,
            g,
            m,
            v,
            base,
            Slots::Listed(list),
            stride,
            offset,
            len,
            u,
        );
    }
    let mid = list.len() / 2;
    let split = list[mid] as usize;
    let (p_left, p_right) = p.split_at_mut((split - base) * stride);
    let (g_left, g_right) = g.split_at((split - base) * stride);
    let (left, right) = split_moments((m, v), mid * len);
    let (left, right) = rayon::join(
        || listed_group(p_left, g_left, base, &list[..mid], left, layout, u),
        || listed_group(p_right, g_right, split, &list[mid..], right, layout, u),
    );
    left.merge(right)
}
