//! The information of both speeds' samples about the parameters, summed along the
//! run: the Cramér-Rao bound's products without the sensitivities written out.
//!
//! With white noise of levels `s_M`, `s_L` on the speeds, the Fisher information is
//! `G_M / s_M^2 + G_L / s_L^2`, `G_c = sum_k s_c(k) s_c(k)^T` the sums of the outer
//! products of speed `c`'s sensitivities at each sample. The walk hands each sample's
//! row to [`Gram`], which adds it to both sums and keeps nothing else: no array of
//! `(samples, 3, m)` values to allocate, write and read again.

use super::lanes::{push_lanes, Row, Sink, LANES, WIDTH};
use super::run::simulate_and_walk;
use super::N_PARAMS;
use crate::hybrid::Graze;
use crate::Error;

/// The speeds' sums of outer products along a run, and the run's states.
#[derive(Clone, Debug, Default)]
pub struct DriveInformation {
    /// `G_c = sum_k s_c(k) s_c(k)^T`, row-major `(2, m, m)`: the motor's speed, then
    /// the load's, by the `m` parameters asked for, in their SI units.
    pub gram: Vec<f64>,
    /// The simulator's states, row-major `(samples, 3)`.
    pub states: Vec<f64>,
    /// The simulator's near-grazing passes (see [`Graze`]).
    pub grazes: Vec<Graze>,
}

/// The sums [`DriveInformation::gram`] of the sensitivities of the two-mass drive
/// from `x0` with sensitivity `s0` (`None`: zero; a steady start's moves with the
/// parameters) on the grid `t0 + i ts` under the torques `u`, for the parameters
/// `wanted` (as [`drive_sensitivities_from`](super::drive_sensitivities_from), whose
/// values these are the products of), and the run's states.
///
/// Errors: as [`drive_sensitivities_from`](super::drive_sensitivities_from).
pub fn drive_information(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    s0: Option<&[f64]>,
    wanted: &[usize],
) -> Result<DriveInformation, Error> {
    let mut gram = Gram::new(wanted.len());
    let (states, grazes) = simulate_and_walk(p, t0, ts, u, x0, s0, wanted, &mut gram)?;
    Ok(DriveInformation {
        gram: gram.sums(),
        states,
        grazes,
    })
}

/// Speeds whose products are summed: `w_M` and `w_L`, the rows 0 and 1 of a [`Row`].
const SPEEDS: usize = 2;
/// Samples whose speed rows are gathered before their products are summed: the sums
/// then run in registers over a block, where adding each sample to the sums in
/// memory waits on the last sample's store (found with `perf` on the bound's loop;
/// docs/design/sensitivities.md gives the bound's cost since); 64 rows of at most 2 x 12 lanes take
/// 12 KiB, well inside the first-level cache.
const BLOCK: usize = 64;

/// The running sums of the speeds' outer products, `sums[c][a][b]`; read from the
/// upper triangle (`a <= b`), so that the sums are symmetric to the bit.
struct Gram {
    m: usize,
    groups: usize,
    sums: [[[f64; WIDTH]; WIDTH]; SPEEDS],
    /// Up to [`BLOCK`] samples' speed rows, each the lanes of the groups carried.
    block: Vec<f64>,
}

impl Gram {
    fn new(m: usize) -> Self {
        Gram {
            m,
            groups: m.div_ceil(LANES),
            sums: [[[0.0; WIDTH]; WIDTH]; SPEEDS],
            block: Vec::with_capacity(BLOCK * SPEEDS * WIDTH),
        }
    }

    /// Both speeds' `m x m` sums, row-major, the lower triangle mirrored.
    fn sums(mut self) -> Vec<f64> {
        self.flush();
        let m = self.m;
        let mut out = Vec::with_capacity(SPEEDS * m * m);
        for sums in &self.sums {
            for a in 0..m {
                out.extend((0..m).map(|b| sums[a.min(b)][a.max(b)]));
            }
        }
        out
    }

    /// The gathered rows' products added to the sums, for as many groups of lanes as
    /// the columns fill (known when compiling, so the sums stay in registers). Inlined
    /// into the walk, so compiled for AVX2 with it where the processor has it.
    #[inline(always)]
    fn flush(&mut self) {
        match self.groups {
            0 => {}
            1 => add_products::<1>(&mut self.sums, &self.block, self.m),
            2 => add_products::<2>(&mut self.sums, &self.block, self.m),
            _ => add_products::<3>(&mut self.sums, &self.block, self.m),
        }
        self.block.clear();
    }
}

impl<const N: usize> Sink<N> for Gram {
    #[inline(always)]
    fn take(&mut self, row: &Row<N>) {
        for speed in &row[..SPEEDS] {
            push_lanes(&mut self.block, speed, self.groups);
        }
        if self.block.len() == BLOCK * SPEEDS * LANES * self.groups {
            self.flush();
        }
    }
}

/// `sums[c][a][lanes of group g] += sum over block of s_c[a] s_c[group g]`, for the
/// `G` groups that hold the `m` columns. Every group, the mirror's too, and [`LANES`]
/// rows `a` at a time (a row past the columns adds zeros): loops over ranges known
/// when compiling keep the `LANES G` sums in registers, as chains of additions
/// independent enough to fill the pipeline; one row at a time waits on each
/// addition's latency, and a range from `a`'s own group on left the sums on the
/// stack (each found as for [`BLOCK`]).
#[inline(always)]
fn add_products<const G: usize>(
    sums: &mut [[[f64; WIDTH]; WIDTH]; SPEEDS],
    block: &[f64],
    m: usize,
) {
    for (c, sums) in sums.iter_mut().enumerate() {
        for a0 in (0..m).step_by(LANES) {
            let mut acc = [[[0.0; LANES]; G]; LANES];
            for rows in block.chunks_exact(SPEEDS * G * LANES) {
                let s = &rows[c * G * LANES..(c + 1) * G * LANES];
                for i in 0..LANES {
                    for g in 0..G {
                        for l in 0..LANES {
                            acc[i][g][l] += s[a0 + i] * s[g * LANES + l];
                        }
                    }
                }
            }
            for (i, acc) in acc.iter().enumerate().take(m - a0) {
                for g in 0..G {
                    for l in 0..LANES {
                        sums[a0 + i][g * LANES + l] += acc[g][l];
                    }
                }
            }
        }
    }
}
