//! The carried columns over the whole samples of one mode, side by side.
//!
//! Between contact changes every column follows `s <- e s + coupling_j x + su_j u +
//! s1_j` with the same `e` and the simulator's state `x`: the columns advance in groups
//! of [`LANES`], each group one array of lanes, which the compiler turns into vector
//! instructions. Each lane's arithmetic is the same whichever columns share the group
//! and whichever instructions carry it (no fused multiply-add), so a column depends
//! neither on the others carried nor on the machine.
//!
//! The samples are the outer loop: each sample's row (every column, unscaled) goes to
//! a [`Sink`] in order, which writes it out or folds it into a sum and keeps nothing
//! else (`information`).

use super::flow::Flow;
use super::N_PARAMS;
use crate::linalg::{Mat, Vector};

/// Columns per group: four doubles fill a 256-bit register (AVX2, chosen at run time
/// where the processor has it; two 128-bit registers in the baseline x86-64 build).
pub(super) const LANES: usize = 4;
type Lanes = [f64; LANES];
/// Groups at most: every parameter carried.
const MAX_GROUPS: usize = N_PARAMS.div_ceil(LANES);
/// Lanes of a [`Row`]: every group's, side by side.
pub(super) const WIDTH: usize = MAX_GROUPS * LANES;

/// One sample's carried columns in the parameters' units: each of the `N` states' row
/// of [`WIDTH`] lanes, the columns in the order wanted, zero beyond them.
pub(super) type Row<const N: usize> = [[f64; WIDTH]; N];

/// Where the rows of a run of `N` states go, one per sample, in order.
pub(super) trait Sink<const N: usize> {
    fn take(&mut self, row: &Row<N>);
}

/// The lanes of the first `groups` groups of `lanes` pushed onto `out`: a copy of a
/// length known when compiling (one per arm) is a few vector moves, where a length
/// known only when running is a call to `memcpy`, per state and sample.
#[inline(always)]
pub(super) fn push_lanes(out: &mut Vec<f64>, lanes: &[f64; WIDTH], groups: usize) {
    match groups {
        0 => {}
        1 => out.extend_from_slice(&lanes[..LANES]),
        2 => out.extend_from_slice(&lanes[..2 * LANES]),
        _ => out.extend_from_slice(lanes),
    }
}

/// The lanes of the first `groups` groups of `lanes` copied to the start of `dst`,
/// which holds at least as many: as [`push_lanes`], lengths known when compiling.
#[inline(always)]
pub(super) fn copy_lanes(dst: &mut [f64], lanes: &[f64; WIDTH], groups: usize) {
    match groups {
        0 => {}
        1 => dst[..LANES].copy_from_slice(&lanes[..LANES]),
        2 => dst[..2 * LANES].copy_from_slice(&lanes[..2 * LANES]),
        _ => dst[..WIDTH].copy_from_slice(lanes),
    }
}

/// Up to [`LANES`] carried columns of one mode's whole-sample flow, side by side; the
/// group `g` of a run carries the wanted columns `g LANES ..`.
#[derive(Clone, Debug)]
pub(super) struct Group<const N: usize> {
    /// Each lane's parameter.
    params: Vec<usize>,
    e: Mat<N>,
    /// `coupling[r][q][lane]`, and so on: lane-innermost for the vector instructions.
    coupling: [[Lanes; N]; N],
    su: [Lanes; N],
    s1: [Lanes; N],
    unscale: Lanes,
}

/// The columns `wanted` of `flow` in groups of [`LANES`]; a column `j` is written
/// times `unscale[j]`.
pub(super) fn groups<const N: usize>(
    flow: &Flow<N>,
    wanted: &[usize],
    unscale: &[f64; N_PARAMS],
) -> Vec<Group<N>> {
    wanted
        .chunks(LANES)
        .map(|chunk| {
            let lane = |f: &dyn Fn(usize) -> f64| -> Lanes {
                std::array::from_fn(|l| chunk.get(l).map_or(0.0, |&j| f(j)))
            };
            Group {
                params: chunk.to_vec(),
                e: flow.e,
                coupling: std::array::from_fn(|r| {
                    std::array::from_fn(|q| lane(&|j| flow.coupling[j][r][q]))
                }),
                su: std::array::from_fn(|r| lane(&|j| flow.su[j][r])),
                s1: std::array::from_fn(|r| lane(&|j| flow.s1[j][r])),
                unscale: lane(&|j| unscale[j]),
            }
        })
        .collect()
}

/// The columns of `s` that `groups` carry, over whole samples, one per torque of `u`,
/// along the simulator's states `x` (one row of `N` per sample's start); each sample's
/// start goes to `sink`. Runs the same arithmetic with AVX2's wider registers where
/// the processor has them.
pub(super) fn stream<const N: usize, S: Sink<N>>(
    groups: &[Group<N>],
    s: &mut [Vector<N>; N_PARAMS],
    u: &[f64],
    x: &[f64],
    sink: &mut S,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2, checked just above.
        return unsafe { stream_avx2(groups, s, u, x, sink) };
    }
    stream_lanes(groups, s, u, x, sink)
}

/// [`stream_lanes`] compiled for AVX2.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn stream_avx2<const N: usize, S: Sink<N>>(
    groups: &[Group<N>],
    s: &mut [Vector<N>; N_PARAMS],
    u: &[f64],
    x: &[f64],
    sink: &mut S,
) {
    stream_lanes(groups, s, u, x, sink)
}

/// The body of [`stream`].
#[inline(always)]
fn stream_lanes<const N: usize, S: Sink<N>>(
    groups: &[Group<N>],
    s: &mut [Vector<N>; N_PARAMS],
    u: &[f64],
    x: &[f64],
    sink: &mut S,
) {
    let mut v = [[[0.0; LANES]; N]; MAX_GROUPS];
    for (group, vg) in groups.iter().zip(v.iter_mut()) {
        for (l, &j) in group.params.iter().enumerate() {
            for r in 0..N {
                vg[r][l] = s[j][r];
            }
        }
    }
    let mut row: Row<N> = [[0.0; WIDTH]; N];
    for (xi, &ui) in x.chunks_exact(N).zip(u) {
        let xi: Vector<N> = std::array::from_fn(|i| xi[i]);
        for (g, (group, vg)) in groups.iter().zip(v.iter_mut()).enumerate() {
            for r in 0..N {
                for l in 0..LANES {
                    row[r][g * LANES + l] = vg[r][l] * group.unscale[l];
                }
            }
            *vg = group.step(vg, xi, ui);
        }
        sink.take(&row);
    }
    for (group, vg) in groups.iter().zip(v.iter()) {
        for (l, &j) in group.params.iter().enumerate() {
            for r in 0..N {
                s[j][r] = vg[r][l];
            }
        }
    }
}

impl<const N: usize> Group<N> {
    /// One whole sample: `e v + coupling x + su u + s1`, lane by lane (plain loops:
    /// the compiler vectorises them; `array::from_fn` closures it did not inline).
    #[inline(always)]
    fn step(&self, v: &[Lanes; N], x: Vector<N>, u: f64) -> [Lanes; N] {
        let mut next = [[0.0; LANES]; N];
        for r in 0..N {
            for l in 0..LANES {
                next[r][l] = self.su[r][l] * u + self.s1[r][l];
            }
            for q in 0..N {
                for l in 0..LANES {
                    next[r][l] += self.e[r][q] * v[q][l] + self.coupling[r][q][l] * x[q];
                }
            }
        }
        next
    }
}

#[cfg(test)]
mod tests {
    use super::super::mode::Mode;
    use super::*;

    /// Every row the walk hands over.
    struct Record<const N: usize>(Vec<Row<N>>);

    impl<const N: usize> Sink<N> for Record<N> {
        fn take(&mut self, row: &Row<N>) {
            self.0.push(*row);
        }
    }

    #[test]
    fn the_wide_registers_give_the_baseline_builds_bits() {
        // The walk picks the AVX2 build where the processor has it; its lanes must
        // carry the baseline build's arithmetic to the bit (no fused multiply-add).
        // Paper A's drive with Coulomb torques, every column (three groups), in
        // contact and in the play, from a start with a sensitivity; without and with a
        // current loop.
        let mut p = [
            4.88e-3, 6.8e-2, 78.0, 0.5e-2, 0.5e-2, 1.575e-2, 3.49e-2, 0.01, 0.02, 0.0,
        ];
        wide_and_baseline_agree::<3>(&p, N_PARAMS - 1);
        p[N_PARAMS - 1] = 1e-3;
        wide_and_baseline_agree::<4>(&p, N_PARAMS);
    }

    /// The wide and the baseline build's rows and end, `n_wanted` first columns.
    fn wide_and_baseline_agree<const N: usize>(p: &[f64; N_PARAMS], n_wanted: usize) {
        let wanted: Vec<usize> = (0..n_wanted).collect();
        let scale = p.map(|v| if v > 0.0 { v } else { 1.0 });
        let unscale = scale.map(|v| 1.0 / v);
        let u: Vec<f64> = (0..500).map(|i| 0.9 * (i as f64 * 0.03).sin()).collect();
        let x: Vec<f64> = (0..N * u.len())
            .map(|i| 0.1 * (i as f64 * 0.011).cos())
            .collect();
        let active = std::array::from_fn(|j| j < n_wanted);
        for flank in [1, 0] {
            let flow = Flow::<N>::new(p, &scale, Mode::contact(flank), 1e-3, &active);
            let groups = groups(&flow, &wanted, &unscale);
            let start: [Vector<N>; N_PARAMS] =
                std::array::from_fn(|j| std::array::from_fn(|r| 1e-2 * (j * N + r) as f64));
            let (mut s_wide, mut s_base) = (start, start);
            let (mut wide, mut base) = (Record(Vec::new()), Record(Vec::new()));
            stream(&groups, &mut s_wide, &u, &x, &mut wide);
            stream_lanes(&groups, &mut s_base, &u, &x, &mut base);
            assert!(
                wide.0 == base.0 && s_wide == s_base,
                "flank {flank}, {N} states"
            );
            assert!(base
                .0
                .iter()
                .all(|r| r.iter().flatten().all(|v| v.is_finite())));
        }
    }
}
