//! Locating guard crossings inside one internal step: the Taylor expansion of the
//! flow, a scan for the earliest crossing, and root finding.

use super::mode::{FuncData, ModeData};
use super::{Graze, GRAZE_RTOL};
use crate::linalg::{dot, matvec, Vector};

/// Terms of the Taylor expansion of the flow used to locate events: with
/// `rho(A) h <= 1/2` the remainder is below `0.5^19 / 19! ~ 1.6e-23` of the state scale.
pub(crate) const TAYLOR_TERMS: usize = 18;
/// Sub-intervals scanned for a crossing or an extremum when locating events. With
/// `rho(A) h <= 1/2` every mode turns by at most 1/16 rad over one of them, too little
/// for a guard function to have two extrema there.
pub(crate) const SCAN_POINTS: usize = 8;
/// A guard counts as crossed when its normalised functions exceed this.
pub(crate) const EVENT_RTOL: f64 = 1e-12;

/// Normalised time within which an extremum at the very start of a step counts as the
/// start itself (see `find_crossing`).
const STATIONARY_START: f64 = 1e-9;

/// Taylor expansion of the flow over `[0, rem]` in the normalised time `s = tau / rem`:
/// `x(s) = sum_k v_k s^k`, `v_k = A^(k-1) (A x0 + b u + c) rem^k / k!`.
pub(super) struct Taylor<const S: usize> {
    v: [Vector<S>; TAYLOR_TERMS + 1],
    /// The held input (enters guard functions with an input term).
    u: f64,
}

impl<const S: usize> Taylor<S> {
    pub(super) fn new<const W: usize>(
        md: &ModeData<S, W>,
        x0: &Vector<S>,
        u: f64,
        rem: f64,
    ) -> Self {
        let mut v = [[0.0; S]; TAYLOR_TERMS + 1];
        v[0] = *x0;
        let mut d = matvec(&md.a, x0);
        for i in 0..S {
            d[i] += md.b[i] * u + md.c[i];
        }
        let mut coef = rem;
        for k in 1..=TAYLOR_TERMS {
            if k > 1 {
                d = matvec(&md.a, &d);
                coef *= rem / k as f64;
            }
            for i in 0..S {
                v[k][i] = d[i] * coef;
            }
        }
        Taylor { v, u }
    }

    pub(super) fn state(&self, s: f64) -> Vector<S> {
        let mut x = self.v[TAYLOR_TERMS];
        for k in (0..TAYLOR_TERMS).rev() {
            for i in 0..S {
                x[i] = x[i] * s + self.v[k][i];
            }
        }
        x
    }

    /// Scalar polynomial coefficients of `h.x(s) + hu u + d`.
    fn project(&self, f: &FuncData<S>) -> [f64; TAYLOR_TERMS + 1] {
        let mut p = [0.0; TAYLOR_TERMS + 1];
        for k in 0..=TAYLOR_TERMS {
            p[k] = dot(&f.h, &self.v[k]);
        }
        p[0] += f.d + f.hu * self.u;
        p
    }
}

/// An upper bound of the polynomial on `[0, 1]`.
fn upper_bound(p: &[f64; TAYLOR_TERMS + 1]) -> f64 {
    p[0] + p[1..].iter().map(|c| c.abs()).sum::<f64>()
}

fn poly(p: &[f64; TAYLOR_TERMS + 1], s: f64) -> f64 {
    p.iter().rev().fold(0.0, |acc, &c| acc * s + c)
}

fn poly_deriv(p: &[f64; TAYLOR_TERMS + 1], s: f64) -> f64 {
    (1..=TAYLOR_TERMS)
        .rev()
        .fold(0.0, |acc, k| acc * s + k as f64 * p[k])
}

/// Earliest `s` in `(0, 1]` at which a guard fires, with the guard's index. Close
/// passes before that instant are appended to `grazes`.
pub(super) fn find_crossing<const S: usize, const W: usize>(
    md: &ModeData<S, W>,
    taylor: &Taylor<S>,
    t_start: f64,
    rem: f64,
    grazes: &mut Vec<Graze>,
) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    let mut close: Vec<(f64, Graze)> = Vec::new();
    for (gi, g) in md.guards.iter().enumerate() {
        let polys: Vec<_> = md.funcs[g.funcs.clone()]
            .iter()
            .map(|f| taylor.project(f))
            .collect();
        // A guard fires only where all its functions are positive: one that provably
        // stays below -GRAZE_RTOL over the step (|s^k| <= 1) rules out both a crossing
        // and a graze, and the scan below would find neither.
        if polys.iter().any(|p| upper_bound(p) < -GRAZE_RTOL) {
            continue;
        }
        let value = |s: f64| {
            polys
                .iter()
                .map(|p| poly(p, s))
                .fold(f64::INFINITY, f64::min)
        };
        let limit = best.map_or(1.0, |b| b.0);
        let mut lo = 0.0;
        for j in 1..=SCAN_POINTS {
            let hi = j as f64 / SCAN_POINTS as f64;
            if lo >= limit {
                break;
            }
            let mut crossing_before: Option<f64> = None;
            for p in &polys {
                if poly_deriv(p, lo) > 0.0 && poly_deriv(p, hi) < 0.0 {
                    let se = illinois(|s| -poly_deriv(p, s), lo, hi);
                    let ve = value(se);
                    if ve > EVENT_RTOL {
                        crossing_before = Some(crossing_before.map_or(se, |c: f64| c.min(se)));
                    }
                    // A near miss: the extremum stays within GRAZE_RTOL of the boundary.
                    // A function that starts exactly on its boundary and is stationary
                    // there (a speed at exactly 0 breaking away with zero acceleration)
                    // does not pass it: no graze.
                    let stationary_start = p[0] == 0.0 && lo == 0.0 && se <= STATIONARY_START;
                    if ve <= EVENT_RTOL && ve > -GRAZE_RTOL && !stationary_start {
                        let graze = Graze {
                            time: t_start + se * rem,
                            index: g.index,
                            margin: ve,
                        };
                        close.push((se, graze));
                    }
                }
            }
            let end = match crossing_before {
                Some(se) => Some(se),
                None if value(hi) > EVENT_RTOL => Some(hi),
                None => None,
            };
            if let Some(end) = end {
                let s = crossing_in(&polys, lo, end);
                if let Some((at, peak)) = shallow_peak(&polys, s) {
                    // A crossing that barely gets over the boundary: as sensitive as a
                    // near miss (the same peak a hair lower would be no contact at all).
                    let graze = Graze {
                        time: t_start + at * rem,
                        index: g.index,
                        margin: peak,
                    };
                    close.push((s, graze));
                }
                if best.is_none_or(|b| s < b.0) {
                    best = Some((s, gi));
                }
                break;
            }
            lo = hi;
        }
    }
    let limit = best.map_or(f64::INFINITY, |b| b.0);
    grazes.extend(
        close
            .into_iter()
            .filter(|(s, _)| *s <= limit)
            .map(|(_, g)| g),
    );
    best
}

/// The crossing of a guard (the min of the polynomials `polys`) in `[lo, end]`, where
/// the guard is positive at `end`. When the guard is not negative at `lo` (a segment
/// that starts on its boundary, e.g. right after the opposite switch), the direction
/// decides: moving outwards it fires at `lo`; moving inwards it fires where it comes
/// back after its dip (a short contact), or at `lo` if it never dips below zero.
///
/// Also returns the dip `(s, depth)` when one was found: the deepest point of a short
/// contact (its penetration, relative to the guard's scale).
fn crossing_in(polys: &[[f64; TAYLOR_TERMS + 1]], lo: f64, end: f64) -> f64 {
    let value = |s: f64| {
        polys
            .iter()
            .map(|p| poly(p, s))
            .fold(f64::INFINITY, f64::min)
    };
    if value(lo) < 0.0 {
        return illinois(value, lo, end);
    }
    // The function that is smallest at `lo` decides the direction.
    let p = polys
        .iter()
        .min_by(|a, b| poly(a, lo).total_cmp(&poly(b, lo)))
        .expect("a guard has at least one function");
    if poly_deriv(p, lo) >= 0.0 {
        return lo;
    }
    let bottom = if poly_deriv(p, end) > 0.0 {
        illinois(|s| poly_deriv(p, s), lo, end)
    } else {
        end
    };
    if value(bottom) < 0.0 {
        illinois(value, bottom, end)
    } else {
        lo
    }
}

/// After a guard crossed at `s`: the peak `(s_peak, value)` its functions would reach
/// under the mode it leaves, when that peak lies inside the step and stays below
/// [`GRAZE_RTOL`] (a near-tangential approach).
fn shallow_peak(polys: &[[f64; TAYLOR_TERMS + 1]], s: f64) -> Option<(f64, f64)> {
    let mut best: Option<(f64, f64)> = None;
    for p in polys {
        if poly_deriv(p, s) > 0.0 && poly_deriv(p, 1.0) < 0.0 {
            let at = illinois(|x| -poly_deriv(p, x), s, 1.0);
            let v = poly(p, at);
            if best.is_none_or(|b| v < b.1) {
                best = Some((at, v));
            }
        }
    }
    best.filter(|b| b.1 < GRAZE_RTOL)
}

/// Root of `f` on `[lo, hi]` with `f(lo) <= 0 < f(hi)` by the Illinois variant of
/// regula falsi (superlinear), safeguarded by bisection; returns the right end of the
/// final bracket, a point where `f > 0`, within a few ulps of the root.
fn illinois(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    let (mut flo, mut fhi) = (f(lo), f(hi));
    if !(flo <= 0.0 && fhi > 0.0) {
        return bisect(|s| f(s) <= 0.0, lo, hi);
    }
    let mut side = 0i8;
    for _ in 0..100 {
        let mut s = lo - flo * (hi - lo) / (fhi - flo);
        if !(s > lo && s < hi) {
            s = 0.5 * (lo + hi);
        }
        if s <= lo || s >= hi {
            break;
        }
        let fs = f(s);
        if fs > 0.0 {
            hi = s;
            fhi = fs;
            if side == 1 {
                flo *= 0.5;
            }
            side = 1;
        } else {
            lo = s;
            flo = fs;
            if side == -1 {
                fhi *= 0.5;
            }
            side = -1;
        }
    }
    // Converged to adjacent floats; if the iteration budget ran out instead, finish the
    // bracket by bisection.
    bisect(|s| f(s) <= 0.0, lo, hi)
}

/// Boundary between `pred == true` (left) and `pred == false` (right) on `[lo, hi]`;
/// returns the right end of the final bracket (the first point where `pred` fails).
fn bisect(pred: impl Fn(f64) -> bool, mut lo: f64, mut hi: f64) -> f64 {
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if pred(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}
