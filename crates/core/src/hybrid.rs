//! Event-accurate simulation of piecewise-affine systems with zero-order-hold input.
//!
//! A [`HybridModel`] has discrete modes; in each mode the state obeys
//! `dx/dt = A x + b u + c` and the mode is left when a *guard* fires. A guard is a set
//! of affine functions `g(x) = h.x + d` and fires when all of them become positive.
//!
//! The engine advances the state sample by sample with the exact flow of the current
//! mode, `x <- E x + F (b u + c)`, `E = exp(A h)`, `F = int_0^h exp(A s) ds`. After each
//! sample it checks the guards cheaply (sign at the end of the sample, and whether a
//! guard function reached an extremum towards its boundary inside the sample). Only
//! when a check fires does it look closely: it expands the flow as a Taylor polynomial
//! in time (valid because the internal step `h` keeps `rho(A) h <= 1/2`), scans it for
//! the earliest crossing, bisects the crossing to ~1e-17 of the step, switches mode
//! there and finishes the step in the new mode. The switching instants are therefore
//! located inside the sample, not rounded to the grid.

use crate::linalg::{dot, expm_and_integral, matvec, spectral_radius_estimate, vecmat, Mat, Vector};
use crate::Error;

/// Terms of the Taylor expansion of the flow used to locate events.
const TAYLOR_TERMS: usize = 24;
/// Sub-intervals scanned for a crossing or an extremum when locating events.
const SCAN_POINTS: usize = 16;
/// Largest `rho(A) h` for which the Taylor expansion is used.
const MAX_RHO_H: f64 = 0.5;
/// Most mode changes allowed inside one internal step (guards against Zeno chatter).
const MAX_EVENTS_PER_STEP: usize = 64;
/// A guard counts as crossed when its normalised functions exceed this.
const EVENT_RTOL: f64 = 1e-12;
/// Relative distance to a boundary under which an extremum is reported as near-grazing.
pub const GRAZE_RTOL: f64 = 1e-6;

/// An affine function `h.x + d` of the state.
#[derive(Clone, Debug)]
pub struct GuardFn<const S: usize> {
    pub h: Vector<S>,
    pub d: f64,
    /// Positive magnitude by which the function is normalised (e.g. the half-width);
    /// crossing tolerance and grazing margins are relative to it.
    pub scale: f64,
}

/// A guard: fires when every function in `funcs` is positive; the switch then sets the
/// mode of switch `index` to `target`.
#[derive(Clone, Debug)]
pub struct GuardSpec<const S: usize> {
    pub funcs: Vec<GuardFn<S>>,
    pub index: usize,
    pub target: i8,
}

/// A piecewise-affine model whose mode is a vector of `n_switches()` codes in {-1, 0, 1}.
pub trait HybridModel<const S: usize>: Sync {
    fn n_switches(&self) -> usize;
    /// `(A, b, c)` of the mode.
    fn dynamics(&self, modes: &[i8]) -> (Mat<S>, Vector<S>, Vector<S>);
    /// Guards that leave the mode.
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<S>>;
    /// Mode of a state (used for the initial state).
    fn classify(&self, x: &Vector<S>) -> Vec<i8>;
    /// Modes whose dynamics bound the fastest time scale of the model.
    fn extreme_modes(&self) -> Vec<Vec<i8>>;
}

/// A change of mode of one switch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event {
    pub time: f64,
    pub index: usize,
    pub from: i8,
    pub to: i8,
}

/// A close pass of a guard function to its boundary (see [`GRAZE_RTOL`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Graze {
    pub time: f64,
    pub index: usize,
    pub margin: f64,
}

/// States on the grid (row-major `n x S`), modes on the grid (`n x n_switches`),
/// events and near-grazing passes.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    pub states: Vec<f64>,
    pub modes: Vec<i8>,
    pub events: Vec<Event>,
    pub grazes: Vec<Graze>,
}

#[derive(Clone, Debug)]
struct FuncData<const S: usize> {
    h: Vector<S>,
    d: f64,
    /// Time derivative along the flow: `g' = ha.x + hb u + hc`.
    ha: Vector<S>,
    hb: f64,
    hc: f64,
}

#[derive(Clone, Debug)]
struct GuardData {
    funcs: std::ops::Range<usize>,
    index: usize,
    target: i8,
}

#[derive(Clone, Debug)]
struct ModeData<const S: usize> {
    a: Mat<S>,
    b: Vector<S>,
    c: Vector<S>,
    e: Mat<S>,
    fb: Vector<S>,
    fc: Vector<S>,
    funcs: Vec<FuncData<S>>,
    guards: Vec<GuardData>,
}

fn encode(modes: &[i8]) -> usize {
    modes.iter().rev().fold(0usize, |acc, &m| acc * 3 + (m + 1) as usize)
}

/// The simulator for one model and one internal step.
pub struct Engine<'m, const S: usize, M: HybridModel<S>> {
    model: &'m M,
    h: f64,
    substeps: usize,
    cache: Vec<Option<Box<ModeData<S>>>>,
}

impl<'m, const S: usize, M: HybridModel<S>> Engine<'m, S, M> {
    /// An engine for sample time `ts`; the internal step is `ts / substeps` with
    /// `substeps` the smallest integer giving `rho(A) h <= 1/2` in every mode.
    pub fn new(model: &'m M, ts: f64) -> Result<Self, Error> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::InvalidArgument(format!("sample time must be > 0, got {ts}")));
        }
        let rho = model
            .extreme_modes()
            .iter()
            .map(|m| spectral_radius_estimate(&model.dynamics(m).0))
            .fold(0.0, f64::max);
        let substeps = ((rho * ts / MAX_RHO_H).ceil() as usize).max(1);
        if substeps > 1_000_000 {
            return Err(Error::InvalidArgument(format!(
                "sample time {ts} s is far too long for the drive's fastest mode ({rho:.3e} rad/s); \
                 use a sample time below {:.3e} s",
                1000.0 * MAX_RHO_H / rho
            )));
        }
        let n_modes = 3usize.pow(model.n_switches() as u32);
        Ok(Engine { model, h: ts / substeps as f64, substeps, cache: vec![None; n_modes] })
    }

    /// Internal steps per sample.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    fn mode(&mut self, modes: &[i8]) -> usize {
        let id = encode(modes);
        if self.cache[id].is_none() {
            self.cache[id] = Some(Box::new(self.build(modes)));
        }
        id
    }

    fn build(&self, modes: &[i8]) -> ModeData<S> {
        let (a, b, c) = self.model.dynamics(modes);
        let (e, f) = expm_and_integral(&a, self.h);
        let mut funcs = Vec::new();
        let mut guards = Vec::new();
        for spec in self.model.guards(modes) {
            let start = funcs.len();
            for g in spec.funcs {
                // Normalise by the scale so that the functions of a guard compare, and
                // tolerances and margins are relative.
                let mut h = g.h;
                h.iter_mut().for_each(|v| *v /= g.scale);
                funcs.push(FuncData {
                    ha: vecmat(&h, &a),
                    hb: dot(&h, &b),
                    hc: dot(&h, &c),
                    h,
                    d: g.d / g.scale,
                });
            }
            guards.push(GuardData { funcs: start..funcs.len(), index: spec.index, target: spec.target });
        }
        ModeData { a, b, c, fb: matvec(&f, &b), fc: matvec(&f, &c), e, funcs, guards }
    }

    /// Simulate from `x0` at `t0` with ZOH input `u` (one value per sample); the
    /// trajectory has `u.len()` samples, the last input value is not used.
    pub fn run(&mut self, t0: f64, ts: f64, u: &[f64], x0: &Vector<S>) -> Result<Trajectory, Error> {
        let n = u.len();
        let ns = self.model.n_switches();
        let mut out = Trajectory {
            states: Vec::with_capacity(n * S),
            modes: Vec::with_capacity(n * ns),
            ..Default::default()
        };
        if n == 0 {
            return Ok(out);
        }
        let mut x = *x0;
        let mut modes = self.model.classify(&x);
        let mut id = self.mode(&modes);
        out.states.extend_from_slice(&x);
        out.modes.extend_from_slice(&modes);
        for k in 0..n - 1 {
            let uk = u[k];
            for sub in 0..self.substeps {
                if !self.fast_step(id, &mut x, uk) {
                    let start = t0 + (k as f64) * ts + (sub as f64) * self.h;
                    id = self.slow_step(&mut modes, &mut x, uk, start, &mut out)?;
                }
            }
            if !x.iter().all(|v| v.is_finite()) {
                return Err(Error::Diverged { time: t0 + (k + 1) as f64 * ts });
            }
            out.states.extend_from_slice(&x);
            out.modes.extend_from_slice(&modes);
        }
        Ok(out)
    }

    /// One internal step with the precomputed flow; `false` (and `x` untouched) when a
    /// guard may fire inside the step.
    #[inline(always)]
    fn fast_step(&self, id: usize, x: &mut Vector<S>, u: f64) -> bool {
        let md = self.cache[id].as_deref().expect("mode built before use");
        let mut xn = matvec(&md.e, x);
        for i in 0..S {
            xn[i] += md.fb[i] * u + md.fc[i];
        }
        let h = self.h;
        for g in &md.guards {
            let mut v = f64::INFINITY;
            for f in &md.funcs[g.funcs.clone()] {
                let g0 = dot(&f.h, x) + f.d;
                let g1 = dot(&f.h, &xn) + f.d;
                v = v.min(g1);
                let s0 = dot(&f.ha, x) + f.hb * u + f.hc;
                let s1 = dot(&f.ha, &xn) + f.hb * u + f.hc;
                // An extremum towards the boundary inside the step: the function rises
                // at the start and falls at the end. Tangent lines bound its peak.
                if s0 > 0.0 && s1 < 0.0 && (g0 + s0 * h).max(g1 - s1 * h) > -GRAZE_RTOL {
                    return false;
                }
            }
            if v > 0.0 {
                return false;
            }
        }
        *x = xn;
        true
    }

    /// Advance one internal step locating every guard crossing inside it.
    fn slow_step(
        &mut self,
        modes: &mut [i8],
        x: &mut Vector<S>,
        u: f64,
        start: f64,
        out: &mut Trajectory,
    ) -> Result<usize, Error> {
        let mut id = encode(modes);
        let mut done = 0.0;
        for _ in 0..MAX_EVENTS_PER_STEP {
            let rem = self.h - done;
            let md = self.cache[id].as_deref().expect("mode built before use");
            let taylor = Taylor::new(md, x, u, rem);
            let hit = find_crossing(md, &taylor, start + done, rem, &mut out.grazes);
            match hit {
                None => {
                    *x = taylor.state(1.0);
                    return Ok(id);
                }
                Some((s, gi)) => {
                    *x = taylor.state(s);
                    let guard = &md.guards[gi];
                    let (index, target) = (guard.index, guard.target);
                    out.events.push(Event { time: start + done + s * rem, index, from: modes[index], to: target });
                    modes[index] = target;
                    id = self.mode(modes);
                    done += s * rem;
                }
            }
        }
        Err(Error::Zeno { time: start + done })
    }
}

/// Taylor expansion of the flow over `[0, rem]` in the normalised time `s = tau / rem`:
/// `x(s) = sum_k v_k s^k`, `v_k = A^(k-1) (A x0 + b u + c) rem^k / k!`.
struct Taylor<const S: usize> {
    v: [Vector<S>; TAYLOR_TERMS + 1],
}

impl<const S: usize> Taylor<S> {
    fn new(md: &ModeData<S>, x0: &Vector<S>, u: f64, rem: f64) -> Self {
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
        Taylor { v }
    }

    fn state(&self, s: f64) -> Vector<S> {
        let mut x = self.v[TAYLOR_TERMS];
        for k in (0..TAYLOR_TERMS).rev() {
            for i in 0..S {
                x[i] = x[i] * s + self.v[k][i];
            }
        }
        x
    }

    /// Scalar polynomial coefficients of `h.x(s) + d`.
    fn project(&self, f: &FuncData<S>) -> [f64; TAYLOR_TERMS + 1] {
        let mut p = [0.0; TAYLOR_TERMS + 1];
        for k in 0..=TAYLOR_TERMS {
            p[k] = dot(&f.h, &self.v[k]);
        }
        p[0] += f.d;
        p
    }
}

fn poly(p: &[f64; TAYLOR_TERMS + 1], s: f64) -> f64 {
    p.iter().rev().fold(0.0, |acc, &c| acc * s + c)
}

fn poly_deriv(p: &[f64; TAYLOR_TERMS + 1], s: f64) -> f64 {
    (1..=TAYLOR_TERMS).rev().fold(0.0, |acc, k| acc * s + k as f64 * p[k])
}

/// Earliest `s` in `(0, 1]` at which a guard fires, with the guard's index. Close
/// passes before that instant are appended to `grazes`.
fn find_crossing<const S: usize>(
    md: &ModeData<S>,
    taylor: &Taylor<S>,
    t_start: f64,
    rem: f64,
    grazes: &mut Vec<Graze>,
) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    let mut close: Vec<(f64, Graze)> = Vec::new();
    for (gi, g) in md.guards.iter().enumerate() {
        let polys: Vec<_> = md.funcs[g.funcs.clone()].iter().map(|f| taylor.project(f)).collect();
        let value = |s: f64| polys.iter().map(|p| poly(p, s)).fold(f64::INFINITY, f64::min);
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
                    let se = bisect(|s| poly_deriv(p, s) > 0.0, lo, hi);
                    let ve = value(se);
                    if ve > EVENT_RTOL {
                        crossing_before = Some(crossing_before.map_or(se, |c: f64| c.min(se)));
                    } else if ve > -GRAZE_RTOL {
                        close.push((se, Graze { time: t_start + se * rem, index: g.index, margin: ve }));
                    }
                }
            }
            let end = match crossing_before {
                Some(se) => Some(se),
                None if value(hi) > EVENT_RTOL => Some(hi),
                None => None,
            };
            if let Some(end) = end {
                let s = if value(lo) >= 0.0 { lo } else { bisect(|s| value(s) <= 0.0, lo, end) };
                if best.is_none_or(|b| s < b.0) {
                    best = Some((s, gi));
                }
                break;
            }
            lo = hi;
        }
    }
    let limit = best.map_or(f64::INFINITY, |b| b.0);
    grazes.extend(close.into_iter().filter(|(s, _)| *s < limit).map(|(_, g)| g));
    best
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
