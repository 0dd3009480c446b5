//! The carried columns over the whole samples of one mode, side by side.
//!
//! Between contact changes every column follows `s <- e s + coupling_j x + su_j u +
//! s1_j` with the same `e` and the simulator's state `x`: up to [`LANES`] columns
//! advance together as one array of lanes, which the compiler turns into vector
//! instructions. Each lane's arithmetic is the same whichever columns share the
//! group, so a column does not depend on the others carried.

use super::flow::Flow;
use super::{N_PARAMS, N_STATES};
use crate::linalg::{Mat, Vector};

/// Columns per group: two doubles fill a 128-bit register, the vectors of the
/// baseline x86-64 build, and a lone column (`theta`'s, the bound's default) wastes
/// one lane at most.
pub(super) const LANES: usize = 2;
type Lanes = [f64; LANES];

/// Up to [`LANES`] carried columns of one mode's whole-sample flow, side by side.
#[derive(Clone, Debug)]
pub(super) struct Group {
    /// Each lane's parameter and its position among the written columns.
    cols: Vec<(usize, usize)>,
    e: Mat<N_STATES>,
    /// `coupling[r][q][lane]`, and so on: lane-innermost for the vector instructions.
    coupling: [[Lanes; N_STATES]; N_STATES],
    su: [Lanes; N_STATES],
    s1: [Lanes; N_STATES],
    unscale: Lanes,
}

/// The columns `wanted` of `flow` in groups of [`LANES`]; a column `j` is written
/// times `unscale[j]`.
pub(super) fn groups(flow: &Flow, wanted: &[usize], unscale: &[f64; N_PARAMS]) -> Vec<Group> {
    let cols: Vec<(usize, usize)> = wanted.iter().enumerate().map(|(c, &j)| (j, c)).collect();
    cols.chunks(LANES)
        .map(|chunk| {
            let lane = |f: &dyn Fn(usize) -> f64| -> Lanes {
                std::array::from_fn(|l| chunk.get(l).map_or(0.0, |&(j, _)| f(j)))
            };
            Group {
                cols: chunk.to_vec(),
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

impl Group {
    /// The group's columns of `s` carried over whole samples, one per torque of `u`,
    /// along the simulator's states `x` (one row of 3 per sample's start); each
    /// sample's start is written, unscaled, to its row of `out` (rows of `3 m`,
    /// state by column).
    pub fn stream(
        &self,
        s: &mut [Vector<N_STATES>; N_PARAMS],
        m: usize,
        u: &[f64],
        x: &[f64],
        out: &mut [f64],
    ) {
        let mut v = [[0.0; LANES]; N_STATES];
        for (l, &(j, _)) in self.cols.iter().enumerate() {
            for r in 0..N_STATES {
                v[r][l] = s[j][r];
            }
        }
        let rows = out
            .chunks_exact_mut(N_STATES * m)
            .zip(x.chunks_exact(N_STATES));
        for ((row, xi), &ui) in rows.zip(u) {
            for (l, &(_, c)) in self.cols.iter().enumerate() {
                for r in 0..N_STATES {
                    row[r * m + c] = v[r][l] * self.unscale[l];
                }
            }
            v = self.step(&v, [xi[0], xi[1], xi[2]], ui);
        }
        for (l, &(j, _)) in self.cols.iter().enumerate() {
            for r in 0..N_STATES {
                s[j][r] = v[r][l];
            }
        }
    }

    /// One whole sample: `e v + coupling x + su u + s1`, lane by lane (plain loops:
    /// the compiler vectorises them; `array::from_fn` closures it did not inline).
    #[inline(always)]
    fn step(&self, v: &[Lanes; N_STATES], x: Vector<N_STATES>, u: f64) -> [Lanes; N_STATES] {
        let mut next = [[0.0; LANES]; N_STATES];
        for r in 0..N_STATES {
            for l in 0..LANES {
                next[r][l] = self.su[r][l] * u + self.s1[r][l];
            }
            for q in 0..N_STATES {
                for l in 0..LANES {
                    next[r][l] += self.e[r][q] * v[q][l] + self.coupling[r][q][l] * x[q];
                }
            }
        }
        next
    }
}
