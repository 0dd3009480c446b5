//! The block-wise fast path of the engine.

use super::mode::ModeData;
use super::{flow, Engine, HybridModel, GRAZE_RTOL};
use crate::linalg::Vector;

/// Internal steps per block of the optimistic fast path.
const BLOCK: usize = 32;

impl<const S: usize, const W: usize, M: HybridModel<S>> Engine<'_, S, W, M> {
    /// Advance with the precomputed flow of mode `md` from internal step `sub` of sample
    /// `k` until the end of the input or until a guard may fire inside an internal step;
    /// returns `true` in the latter case, with `x` and the position `(k, sub)` at the
    /// start of that step. Modes are not written: they do not change.
    ///
    /// Runs the flow optimistically over a block of internal steps (the bare
    /// recurrence, so the state's dependency chain carries nothing else), writing the
    /// samples' states as it reaches them, then checks the guards over the block in a
    /// separate pass without loop-carried dependencies. On a hit it rolls back to the
    /// start of the first suspect internal step. The decisions are the same as checking
    /// step by step: each step's test takes the function's value and slope at its two
    /// ends under the input held over it.
    #[inline(always)]
    pub(super) fn fast_run_blocks<const ONE: bool>(
        &self,
        md: &ModeData<S, W>,
        x: &mut Vector<S>,
        u: &[f64],
        k: &mut usize,
        sub: &mut usize,
        states: &mut [f64],
    ) -> bool {
        let (h, n) = (self.h, u.len());
        // one internal step per sample, known to the compiler (the common case)
        let per = if ONE { 1 } else { self.substeps };
        let fg = &md.fast;
        let (nf, ng) = (md.funcs.len().min(W), md.guards.len().min(W));
        // The block's states row by row and column-major, its inputs step by step, one
        // guard function over the block, per-lane "positive at the end of the step"
        // flags, and per-step "look closely" flags.
        let mut rows = [[0.0; S]; BLOCK + 1];
        let mut ubuf = [0.0; BLOCK];
        let mut cols = [[0.0; BLOCK + 1]; S];
        let (mut gv, mut qv) = ([0.0; BLOCK + 1], [0.0; BLOCK + 1]);
        let mut pos = [[0u64; BLOCK]; W];
        while *k + 1 < n {
            let (kb, sb) = (*k, *sub);
            let m = BLOCK.min((n - 1 - kb) * per - sb);
            let mut xx = *x;
            let (mut lo, mut hi) = (xx, xx);
            let (kk, ss, steps, uu) = if ONE {
                // The steps are the samples: written in place, where the check reads them.
                let block = states[(kb + 1) * S..(kb + m + 1) * S].chunks_exact_mut(S);
                for (uk, dst) in u[kb..kb + m].iter().zip(block) {
                    xx = flow(&md.e, &md.fb, &md.fc, &xx, *uk);
                    dst.copy_from_slice(&xx);
                    widen(&mut lo, &mut hi, &xx);
                }
                (kb + m, 0, &states[kb * S..(kb + m + 1) * S], &u[kb..kb + m])
            } else {
                let (mut kk, mut ss) = (kb, sb);
                rows[0] = xx;
                for j in 0..m {
                    ubuf[j] = u[kk];
                    xx = flow(&md.e, &md.fb, &md.fc, &xx, ubuf[j]);
                    rows[j + 1] = xx;
                    ss += 1;
                    if ss == per {
                        (kk, ss) = (kk + 1, 0);
                        states[kk * S..(kk + 1) * S].copy_from_slice(&xx);
                    }
                    widen(&mut lo, &mut hi, &xx);
                }
                (kk, ss, rows[..=m].as_flattened(), &ubuf[..m])
            };
            // First filter, O(S) per guard function: interval bounds over the block's
            // state box on the function and its slope. A function whose largest value
            // plus largest slope times h stays short of the boundary cannot cross or
            // peak near it in any sample of the block.
            let umax = if fg.input_enters {
                uu.iter()
                    .fold(0.0f64, |a, v| if v.abs() > a { v.abs() } else { a })
            } else {
                0.0
            };
            let mut suspect = 0u64;
            for i in 0..nf {
                let (mut gub, mut qmid, mut qrad) = (fg.d[i], fg.hc[i], fg.hb[i].abs() * umax);
                gub += fg.hu[i].abs() * umax;
                for c in 0..S {
                    let (a, b) = (fg.h[i][c], fg.ha[i][c]);
                    gub += if a > 0.0 { a * hi[c] } else { a * lo[c] };
                    qmid += b * 0.5 * (lo[c] + hi[c]);
                    qrad += b.abs() * 0.5 * (hi[c] - lo[c]);
                }
                if gub + (qmid.abs() + qrad) * h >= -GRAZE_RTOL {
                    suspect |= 1 << i;
                }
            }
            if suspect == 0 {
                (*k, *sub, *x) = (kk, ss, xx);
                continue;
            }
            for (j, row) in steps.chunks_exact(S).enumerate() {
                for c in 0..S {
                    cols[c][j] = row[c];
                }
            }
            let mut flag = [0u64; BLOCK];
            // Lanes that may fire in this block (the others provably stay clear).
            let mut active = 0u64;
            for i in 0..nf {
                if suspect & (1 << i) == 0 {
                    continue;
                }
                gv[..=m].fill(fg.d[i]);
                qv[..=m].fill(fg.hc[i]);
                for c in 0..S {
                    let (a, b) = (fg.h[i][c], fg.ha[i][c]);
                    if a != 0.0 {
                        gv[..=m]
                            .iter_mut()
                            .zip(&cols[c][..=m])
                            .for_each(|(g, v)| *g += a * v);
                    }
                    if b != 0.0 {
                        qv[..=m]
                            .iter_mut()
                            .zip(&cols[c][..=m])
                            .for_each(|(q, v)| *q += b * v);
                    }
                }
                let (hb, hu) = (fg.hb[i], fg.hu[i]);
                let lane = &mut pos[i];
                // Over the whole block the function stays below gmax and its slope below
                // smax in magnitude; if even gmax + smax h stays short of the boundary, no
                // sample can cross or peak near it and the per-sample test is skipped.
                let (mut gmax, mut qmax, mut qmin) = (f64::NEG_INFINITY, 0.0f64, 0.0f64);
                for (&g, &q) in gv[..=m].iter().zip(&qv[..=m]) {
                    gmax = if g > gmax { g } else { gmax };
                    qmax = if q > qmax { q } else { qmax };
                    qmin = if q < qmin { q } else { qmin };
                }
                let mut uabs = 0.0f64;
                if hb != 0.0 || hu != 0.0 {
                    for &v in uu {
                        uabs = if v.abs() > uabs { v.abs() } else { uabs };
                    }
                }
                if gmax + hu.abs() * uabs + (qmax.max(-qmin) + hb.abs() * uabs) * h < -GRAZE_RTOL {
                    continue;
                }
                active |= 1 << i;
                for j in 0..m {
                    // The held input's term (zero for functions of the state alone).
                    let (g0, g1) = (gv[j] + hu * uu[j], gv[j + 1] + hu * uu[j]);
                    let (s0, s1) = (qv[j] + hb * uu[j], qv[j + 1] + hb * uu[j]);
                    // An extremum towards the boundary inside the sample: the function
                    // rises at the start and falls at the end; tangent lines bound its peak.
                    let near =
                        ((g0 + s0 * h > -GRAZE_RTOL) as u64) | ((g1 - s1 * h > -GRAZE_RTOL) as u64);
                    flag[j] |= ((s0 > 0.0) as u64) & ((s1 < 0.0) as u64) & near;
                    lane[j] = (g1 > 0.0) as u64;
                }
            }
            if active == 0 {
                (*k, *sub, *x) = (kk, ss, xx);
                continue;
            }
            for &lanes in &fg.lanes[..ng] {
                // A guard crosses only where all its lanes are positive, so only when all
                // of them are active.
                if lanes & active != lanes {
                    continue;
                }
                let mut all = [1u64; BLOCK];
                for (i, p) in pos.iter().enumerate().take(nf) {
                    if lanes & (1 << i) != 0 {
                        all.iter_mut().zip(p).for_each(|(a, p)| *a &= p);
                    }
                }
                flag.iter_mut().zip(&all).for_each(|(f, a)| *f |= a);
            }
            if let Some(j) = flag[..m].iter().position(|&f| f != 0) {
                (*k, *sub) = (kb + (sb + j) / per, (sb + j) % per);
                x.copy_from_slice(&steps[j * S..(j + 1) * S]);
                return true;
            }
            (*k, *sub, *x) = (kk, ss, xx);
        }
        false
    }
}

/// Widen the box `lo..=hi` to hold `x`.
#[inline(always)]
fn widen<const S: usize>(lo: &mut Vector<S>, hi: &mut Vector<S>, x: &Vector<S>) {
    for c in 0..S {
        lo[c] = if x[c] < lo[c] { x[c] } else { lo[c] };
        hi[c] = if x[c] > hi[c] { x[c] } else { hi[c] };
    }
}
