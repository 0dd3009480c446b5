//! Event-accurate simulation of piecewise-affine systems with zero-order-hold input.
//!
//! A [`HybridModel`] has discrete modes; in each mode the state obeys
//! `dx/dt = A x + b u + c` and the mode is left when a *guard* fires. A guard is a set
//! of affine functions `g(x) = h.x + d` and fires when all of them become positive.
//!
//! The engine advances the state sample by sample with the exact flow of the current
//! mode, `x <- E x + F (b u + c)`, `E = exp(A h)`, `F = int_0^h exp(A s) ds`, and checks
//! every sample cheaply: the sign of each guard function at the sample's end, and
//! whether one reached an extremum towards its boundary inside the sample (slopes of
//! opposite signs at the two ends, peak bounded by the tangent lines). To keep those
//! checks off the state's dependency chain it runs the flow over a block of samples
//! first, then proves whole blocks clear with interval bounds, testing sample by
//! sample only where a bound fails, and rolls back to the first suspect sample.
//!
//! Only there does it look closely: it expands the flow as a Taylor polynomial in
//! time (valid because the internal step `h` keeps `rho(A) h <= 1/2`), scans it for the
//! earliest crossing, locates it by regula falsi (Illinois) to a few ulps of the step,
//! switches mode there and finishes the step in the new mode. The switching instants
//! are therefore located inside the sample, not rounded to the grid.

use crate::linalg::{
    dot, expm_and_integral, matvec, spectral_radius_estimate, vecmat, Mat, Vector,
};
use crate::Error;

/// Terms of the Taylor expansion of the flow used to locate events: with
/// `rho(A) h <= 1/2` the remainder is below `0.5^19 / 19! ~ 1.6e-23` of the state scale.
const TAYLOR_TERMS: usize = 18;
/// Sub-intervals scanned for a crossing or an extremum when locating events. With
/// `rho(A) h <= 1/2` every mode turns by at most 1/16 rad over one of them, too little
/// for a guard function to have two extrema there.
const SCAN_POINTS: usize = 8;
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

/// A close pass of a guard function to its boundary (see [`GRAZE_RTOL`]): `margin` is
/// the guard's value at its extremum relative to the guard's scale (the half-width for
/// a twist), negative when the boundary was missed, positive when barely crossed.
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

/// Where a run writes: borrowed output buffers and growing event lists.
struct Sink<'a> {
    states: &'a mut [f64],
    modes: &'a mut [i8],
    events: Vec<Event>,
    grazes: Vec<Graze>,
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
struct ModeData<const S: usize, const W: usize> {
    a: Mat<S>,
    b: Vector<S>,
    c: Vector<S>,
    e: Mat<S>,
    fb: Vector<S>,
    fc: Vector<S>,
    funcs: Vec<FuncData<S>>,
    guards: Vec<GuardData>,
    fast: FastGuards<S, W>,
}

/// The guard functions of a mode in fixed-width struct-of-arrays form for the
/// per-sample check: `W` lanes (4 per shaft), unused lanes padded so they never fire.
/// Fixed widths let the compiler unroll and vectorise the check.
#[derive(Clone, Debug)]
struct FastGuards<const S: usize, const W: usize> {
    h: [Vector<S>; W],
    d: [f64; W],
    ha: [Vector<S>; W],
    hb: [f64; W],
    hc: [f64; W],
    /// Lanes of each guard (bit i = lane i); unused entries hold a bit no lane sets.
    lanes: [u32; W],
    /// Whether the input enters some slope (`hb != 0`).
    input_enters: bool,
}

/// A lane mask bit that no lane sets (W <= 28), so an unused guard never fires.
const NEVER: u32 = 1 << 31;

impl<const S: usize, const W: usize> FastGuards<S, W> {
    fn new(funcs: &[FuncData<S>], guards: &[GuardData]) -> Self {
        assert!(
            funcs.len() <= W && guards.len() <= W && W <= 28,
            "too many guard functions"
        );
        let mut fg = FastGuards {
            h: [[0.0; S]; W],
            d: [-1.0; W],
            ha: [[0.0; S]; W],
            hb: [0.0; W],
            hc: [0.0; W],
            lanes: [NEVER; W],
            input_enters: funcs.iter().any(|f| f.hb != 0.0),
        };
        for (i, f) in funcs.iter().enumerate() {
            (fg.h[i], fg.d[i], fg.ha[i], fg.hb[i], fg.hc[i]) = (f.h, f.d, f.ha, f.hb, f.hc);
        }
        for (gi, g) in guards.iter().enumerate() {
            fg.lanes[gi] = g.funcs.clone().fold(0, |m, i| m | (1 << i));
        }
        fg
    }
}

fn encode(modes: &[i8]) -> usize {
    modes
        .iter()
        .rev()
        .fold(0usize, |acc, &m| acc * 3 + (m + 1) as usize)
}

/// The simulator for one model and one internal step.
///
/// `S` is the state dimension, `W` the number of guard-function lanes of the fast
/// check (at least the largest number of guard functions of any mode).
pub struct Engine<'m, const S: usize, const W: usize, M: HybridModel<S>> {
    model: &'m M,
    ts: f64,
    h: f64,
    substeps: usize,
    cache: Vec<Option<Box<ModeData<S, W>>>>,
}

impl<'m, const S: usize, const W: usize, M: HybridModel<S>> Engine<'m, S, W, M> {
    /// An engine for sample time `ts`; the internal step is `ts / substeps` with
    /// `substeps` the smallest integer giving `rho(A) h <= 1/2` in every mode.
    pub fn new(model: &'m M, ts: f64) -> Result<Self, Error> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "sample time must be > 0, got {ts}"
            )));
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
        Ok(Engine {
            model,
            ts,
            h: ts / substeps as f64,
            substeps,
            cache: vec![None; n_modes],
        })
    }

    fn mode(&mut self, modes: &[i8]) -> usize {
        let id = encode(modes);
        if self.cache[id].is_none() {
            self.cache[id] = Some(Box::new(self.build(modes)));
        }
        id
    }

    fn build(&self, modes: &[i8]) -> ModeData<S, W> {
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
            guards.push(GuardData {
                funcs: start..funcs.len(),
                index: spec.index,
                target: spec.target,
            });
        }
        let fast = FastGuards::new(&funcs, &guards);
        ModeData {
            a,
            b,
            c,
            fb: matvec(&f, &b),
            fc: matvec(&f, &c),
            e,
            funcs,
            guards,
            fast,
        }
    }

    /// Simulate from `x0` at `t0` with ZOH input `u` (one value per sample time); the
    /// trajectory has `u.len()` samples, the last input value is not used.
    pub fn run(&mut self, t0: f64, u: &[f64], x0: &Vector<S>) -> Result<Trajectory, Error> {
        let (n, ns) = (u.len(), self.model.n_switches());
        let mut states = vec![0.0; n * S];
        let mut modes = vec![0; n * ns];
        let (events, grazes) = self.run_into(t0, u, x0, &mut states, &mut modes)?;
        Ok(Trajectory {
            states,
            modes,
            events,
            grazes,
        })
    }

    /// As [`Self::run`], writing states and modes into caller-provided row-major buffers
    /// of `u.len() * S` and `u.len() * n_switches` entries; returns events and grazes.
    pub fn run_into(
        &mut self,
        t0: f64,
        u: &[f64],
        x0: &Vector<S>,
        states: &mut [f64],
        modes_out: &mut [i8],
    ) -> Result<(Vec<Event>, Vec<Graze>), Error> {
        let (n, ns, ts) = (u.len(), self.model.n_switches(), self.ts);
        if states.len() != n * S || modes_out.len() != n * ns {
            return Err(Error::InvalidArgument(
                "output buffers do not match the input length".into(),
            ));
        }
        let mut out = Sink {
            states,
            modes: modes_out,
            events: Vec::new(),
            grazes: Vec::new(),
        };
        if n == 0 {
            return Ok((out.events, out.grazes));
        }
        let mut x = *x0;
        let mut modes = self.model.classify(&x);
        let mut id = self.mode(&modes);
        out.states[..S].copy_from_slice(&x);
        out.modes[..ns].copy_from_slice(&modes);
        // Guard function values and input-free slopes at the current state.
        let mut cur = ([0.0; W], [0.0; W]);
        self.refresh(id, &x, &mut cur);
        // Position: internal step `sub` of sample `k`. Grid modes from `filled` on are
        // not written yet; they equal `modes` up to the current sample.
        let (mut k, mut sub, mut filled) = (0usize, 0usize, 1usize);
        while k + 1 < n {
            let md = self.cache[id].as_deref().expect("mode built before use");
            let fired = if self.substeps == 1 {
                self.fast_run_blocks(md, &mut x, u, &mut k, out.states)
            } else {
                self.fast_run(md, &mut x, &mut cur, u, &mut k, &mut sub, out.states)
            };
            if !fired {
                break;
            }
            // A guard may fire inside internal step `sub` of sample `k`: redo it closely.
            fill_modes(out.modes, &modes, filled, k + 1);
            filled = k + 1;
            let start = t0 + (k as f64) * ts + (sub as f64) * self.h;
            id = self.slow_step(&mut modes, &mut x, u[k], start, &mut out)?;
            self.refresh(id, &x, &mut cur);
            sub += 1;
            if sub == self.substeps {
                sub = 0;
                k += 1;
                out.states[k * S..(k + 1) * S].copy_from_slice(&x);
            }
        }
        fill_modes(out.modes, &modes, filled, n);
        // NaN/inf propagate, so one look at the end finds a divergence.
        if !x.iter().all(|v| v.is_finite()) {
            let first = out.states.iter().position(|v| !v.is_finite()).unwrap_or(0) / S;
            return Err(Error::Diverged {
                time: t0 + first as f64 * ts,
            });
        }
        Ok((out.events, out.grazes))
    }

    /// Per guard function of the mode at `x`: its value, and the input-free part of its
    /// slope (`ha.x + hc`; the slope under input `u` adds `hb u`).
    fn refresh(&self, id: usize, x: &Vector<S>, cur: &mut ([f64; W], [f64; W])) {
        let md = self.cache[id].as_deref().expect("mode built before use");
        let fg = &md.fast;
        for i in 0..W {
            cur.0[i] = dot(&fg.h[i], x) + fg.d[i];
            cur.1[i] = dot(&fg.ha[i], x) + fg.hc[i];
        }
    }

    /// Advance with the precomputed flow of mode `md` until the end of the input or
    /// until a guard may fire inside an internal step; returns `true` in the latter
    /// case, with `x` and the position `(k, sub)` at the start of that step (`cur` is
    /// then stale: the caller refreshes it). Modes are not written: they do not change.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn fast_run(
        &self,
        md: &ModeData<S, W>,
        x: &mut Vector<S>,
        cur: &mut ([f64; W], [f64; W]),
        u: &[f64],
        k: &mut usize,
        sub: &mut usize,
        states: &mut [f64],
    ) -> bool {
        let (h, n) = (self.h, u.len());
        let single = self.substeps == 1;
        let fg = &md.fast;
        while *k + 1 < n {
            let uk = u[*k];
            let xn = flow(&md.e, &md.fb, &md.fc, x, uk);
            let mut positive = 0u32;
            let mut peak = false;
            for i in 0..md.funcs.len().min(W) {
                let (g0, q0) = (cur.0[i], cur.1[i]);
                let g1 = dot(&fg.h[i], &xn) + fg.d[i];
                let q1 = dot(&fg.ha[i], &xn) + fg.hc[i];
                let (s0, s1) = (q0 + fg.hb[i] * uk, q1 + fg.hb[i] * uk);
                positive |= ((g1 > 0.0) as u32) << i;
                // An extremum towards the boundary inside the step: the function rises
                // at the start and falls at the end; tangent lines bound its peak.
                peak |= (s0 > 0.0)
                    & (s1 < 0.0)
                    & ((g0 + s0 * h > -GRAZE_RTOL) | (g1 - s1 * h > -GRAZE_RTOL));
                cur.0[i] = g1;
                cur.1[i] = q1;
            }
            if peak | crossed(positive, &fg.lanes[..md.guards.len().min(W)]) {
                return true;
            }
            *x = xn;
            if !single {
                *sub += 1;
                if *sub < self.substeps {
                    continue;
                }
                *sub = 0;
            }
            *k += 1;
            states[*k * S..(*k + 1) * S].copy_from_slice(x);
        }
        false
    }

    /// As [`Self::fast_run`] when the internal step is the sample (`substeps == 1`):
    /// runs the flow optimistically over a block of samples (the bare recurrence, so
    /// the state's dependency chain carries nothing else), then checks the guards over
    /// the stored block in a separate pass without loop-carried dependencies. On a hit
    /// it rolls back to the start of the first suspect sample. The decisions are the
    /// same as checking sample by sample.
    #[inline(always)]
    fn fast_run_blocks(
        &self,
        md: &ModeData<S, W>,
        x: &mut Vector<S>,
        u: &[f64],
        k: &mut usize,
        states: &mut [f64],
    ) -> bool {
        let (h, n) = (self.h, u.len());
        let fg = &md.fast;
        let (nf, ng) = (md.funcs.len().min(W), md.guards.len().min(W));
        // The block column-major, one guard function over the block, per-lane "positive
        // at the end of the sample" flags, and per-sample "look closely" flags.
        let mut cols = [[0.0; BLOCK + 1]; S];
        let (mut gv, mut qv) = ([0.0; BLOCK + 1], [0.0; BLOCK + 1]);
        let mut pos = [[0u64; BLOCK]; W];
        while *k + 1 < n {
            let kb = *k;
            let m = BLOCK.min(n - 1 - kb);
            let uu = &u[kb..kb + m];
            let mut xx = *x;
            let (mut lo, mut hi) = (xx, xx);
            for (uk, dst) in uu
                .iter()
                .zip(states[(kb + 1) * S..(kb + m + 1) * S].chunks_exact_mut(S))
            {
                xx = flow(&md.e, &md.fb, &md.fc, &xx, *uk);
                dst.copy_from_slice(&xx);
                for c in 0..S {
                    lo[c] = if xx[c] < lo[c] { xx[c] } else { lo[c] };
                    hi[c] = if xx[c] > hi[c] { xx[c] } else { hi[c] };
                }
            }
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
            let mut suspect = 0u32;
            for i in 0..nf {
                let (mut gub, mut qmid, mut qrad) = (fg.d[i], fg.hc[i], fg.hb[i].abs() * umax);
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
                *k = kb + m;
                *x = xx;
                continue;
            }
            for (j, row) in states[kb * S..(kb + m + 1) * S].chunks_exact(S).enumerate() {
                for c in 0..S {
                    cols[c][j] = row[c];
                }
            }
            let mut flag = [0u64; BLOCK];
            // Lanes that may fire in this block (the others provably stay clear).
            let mut active = 0u32;
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
                let hb = fg.hb[i];
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
                if hb != 0.0 {
                    for &v in uu {
                        uabs = if v.abs() > uabs { v.abs() } else { uabs };
                    }
                }
                if gmax + (qmax.max(-qmin) + hb.abs() * uabs) * h < -GRAZE_RTOL {
                    continue;
                }
                active |= 1 << i;
                for j in 0..m {
                    let (g0, g1) = (gv[j], gv[j + 1]);
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
                *k = kb + m;
                *x = xx;
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
                *k = kb + j;
                x.copy_from_slice(&states[(kb + j) * S..(kb + j + 1) * S]);
                return true;
            }
            *k = kb + m;
            *x = xx;
        }
        false
    }

    /// Advance one internal step locating every guard crossing inside it.
    fn slow_step(
        &mut self,
        modes: &mut [i8],
        x: &mut Vector<S>,
        u: f64,
        start: f64,
        out: &mut Sink<'_>,
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
                    out.events.push(Event {
                        time: start + done + s * rem,
                        index,
                        from: modes[index],
                        to: target,
                    });
                    modes[index] = target;
                    id = self.mode(modes);
                    done += s * rem;
                }
            }
        }
        Err(Error::Zeno { time: start + done })
    }
}

/// Samples per block of the optimistic fast path.
const BLOCK: usize = 32;

/// Whether some guard has all its lanes set in `positive`.
#[inline(always)]
fn crossed(positive: u32, lanes: &[u32]) -> bool {
    let mut any = false;
    for &l in lanes {
        any |= positive & l == l; // all lanes of this guard are set
    }
    any
}

/// Write `modes` into grid rows `from..to` of the row-major mode output.
fn fill_modes(out: &mut [i8], modes: &[i8], from: usize, to: usize) {
    let ns = modes.len();
    if ns == 0 || to <= from {
        return;
    }
    for row in out[from * ns..to * ns].chunks_exact_mut(ns) {
        row.copy_from_slice(modes);
    }
}

/// Exact flow over one internal step, `E x + (fb u + fc)`, summed pairwise to keep
/// the dependency chain from `x` to the next state short.
#[inline(always)]
pub fn flow<const S: usize>(
    e: &Mat<S>,
    fb: &Vector<S>,
    fc: &Vector<S>,
    x: &Vector<S>,
    u: f64,
) -> Vector<S> {
    let mut y = [0.0; S];
    for i in 0..S {
        let r = &e[i];
        let mut acc = [0.0; 2];
        for j in 0..S {
            acc[j % 2] += r[j] * x[j];
        }
        y[i] = (acc[0] + acc[1]) + (fb[i] * u + fc[i]);
    }
    y
}

/// Taylor expansion of the flow over `[0, rem]` in the normalised time `s = tau / rem`:
/// `x(s) = sum_k v_k s^k`, `v_k = A^(k-1) (A x0 + b u + c) rem^k / k!`.
struct Taylor<const S: usize> {
    v: [Vector<S>; TAYLOR_TERMS + 1],
}

impl<const S: usize> Taylor<S> {
    fn new<const W: usize>(md: &ModeData<S, W>, x0: &Vector<S>, u: f64, rem: f64) -> Self {
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
    (1..=TAYLOR_TERMS)
        .rev()
        .fold(0.0, |acc, k| acc * s + k as f64 * p[k])
}

/// Earliest `s` in `(0, 1]` at which a guard fires, with the guard's index. Close
/// passes before that instant are appended to `grazes`.
fn find_crossing<const S: usize, const W: usize>(
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
                    if ve <= EVENT_RTOL && ve > -GRAZE_RTOL {
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
