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

use std::collections::HashMap;

use crate::linalg::{
    dot, expm_and_integral, matvec, spectral_radius_estimate, vecmat, Mat, Vector,
};
use crate::Error;

mod blocks;
mod locate;
#[cfg(test)]
mod tests;

use locate::{find_crossing, Taylor};

/// Terms of the Taylor expansion of the flow used to locate events: with
/// `rho(A) h <= 1/2` the remainder is below `0.5^19 / 19! ~ 1.6e-23` of the state scale.
pub(crate) const TAYLOR_TERMS: usize = 18;
/// Sub-intervals scanned for a crossing or an extremum when locating events. With
/// `rho(A) h <= 1/2` every mode turns by at most 1/16 rad over one of them, too little
/// for a guard function to have two extrema there.
pub(crate) const SCAN_POINTS: usize = 8;
/// Largest `rho(A) h` for which the Taylor expansion is used.
const MAX_RHO_H: f64 = 0.5;
/// Most mode changes allowed inside one internal step (guards against Zeno chatter).
const MAX_EVENTS_PER_STEP: usize = 64;
/// A guard counts as crossed when its normalised functions exceed this.
pub(crate) const EVENT_RTOL: f64 = 1e-12;
/// Relative distance to a boundary under which an extremum is reported as near-grazing.
pub const GRAZE_RTOL: f64 = 1e-6;
/// Most switches of a model: mode codes are packed in base `MODE_CODES` into a `usize`.
const MAX_SWITCHES: usize = 26;

/// An affine function `h.x + hu u + d` of the state and the held input.
#[derive(Clone, Debug)]
pub struct GuardFn<const S: usize> {
    pub h: Vector<S>,
    /// Coefficient of the input (0 for a function of the state alone). The input is
    /// held over a sample, so such a function may jump at a sample boundary; it then
    /// fires at the start of the sample.
    pub hu: f64,
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

/// A piecewise-affine model whose mode is a vector of `n_switches()` codes in
/// `-2..=2` (`MODE_CODES` values per switch).
pub trait HybridModel<const S: usize>: Sync {
    fn n_switches(&self) -> usize;
    /// `(A, b, c)` of the mode.
    fn dynamics(&self, modes: &[i8]) -> (Mat<S>, Vector<S>, Vector<S>);
    /// Guards that leave the mode.
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<S>>;
    /// Mode of a state under input `u` (used for the initial state).
    fn classify(&self, x: &Vector<S>, u: f64) -> Vec<i8>;
    /// The mode switch `index` actually takes when a guard leading from mode `from` to
    /// `target` fires at `x` under input `u` (`modes` holds the other switches'
    /// modes). The model may also reset state components there (e.g. a speed that
    /// sticks at exactly 0). The default keeps the guard's target and the state.
    fn resolve(
        &self,
        index: usize,
        from: i8,
        target: i8,
        modes: &[i8],
        x: &mut Vector<S>,
        u: f64,
    ) -> i8 {
        let _ = (index, from, modes, x, u);
        target
    }
    /// Modes whose dynamics bound the fastest time scale of the model.
    fn extreme_modes(&self) -> Vec<Vec<i8>>;
    /// Number of values of a mode code: 3 (`-1..=1`, the default) or 5 (`-2..=2`).
    fn mode_codes(&self) -> usize {
        3
    }
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
    hu: f64,
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
    hu: [f64; W],
    d: [f64; W],
    ha: [Vector<S>; W],
    hb: [f64; W],
    hc: [f64; W],
    /// Lanes of each guard (bit i = lane i); unused entries hold a bit no lane sets.
    lanes: [u64; W],
    /// Whether the input enters some value or slope (`hu != 0` or `hb != 0`).
    input_enters: bool,
}

/// Largest number of lanes: one bit of a `u64` mask each, and one spare bit.
const MAX_LANES: usize = 60;
/// A lane mask bit that no lane sets (W <= MAX_LANES), so an unused guard never fires.
const NEVER: u64 = 1 << 63;

impl<const S: usize, const W: usize> FastGuards<S, W> {
    fn new(funcs: &[FuncData<S>], guards: &[GuardData]) -> Self {
        assert!(
            funcs.len() <= W && guards.len() <= W && W <= MAX_LANES,
            "too many guard functions"
        );
        let mut fg = FastGuards {
            h: [[0.0; S]; W],
            hu: [0.0; W],
            d: [-1.0; W],
            ha: [[0.0; S]; W],
            hb: [0.0; W],
            hc: [0.0; W],
            lanes: [NEVER; W],
            input_enters: funcs.iter().any(|f| f.hb != 0.0 || f.hu != 0.0),
        };
        for (i, f) in funcs.iter().enumerate() {
            (fg.h[i], fg.hu[i], fg.d[i]) = (f.h, f.hu, f.d);
            (fg.ha[i], fg.hb[i], fg.hc[i]) = (f.ha, f.hb, f.hc);
        }
        for (gi, g) in guards.iter().enumerate() {
            fg.lanes[gi] = g.funcs.clone().fold(0, |m, i| m | (1 << i));
        }
        fg
    }
}

/// Most values a switch's mode code takes (`-2..=2`).
const MODE_CODES: usize = 5;

/// The modes as one number in base `codes` (codes `-(codes / 2) ..= codes / 2`).
fn encode(modes: &[i8], codes: usize) -> usize {
    let offset = (codes / 2) as i8;
    modes
        .iter()
        .rev()
        .fold(0usize, |acc, &m| acc * codes + (m + offset) as usize)
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
    /// Modes built so far, by code (only the few visited ones are ever built).
    cache: ModeCache<S, W>,
}

/// Most mode codes for which the cache is a dense table (one pointer per code); larger
/// mode spaces (many friction switches) use a hash map.
const DENSE_MODES: usize = 1 << 12;

/// Built modes by code: a dense table where the mode space is small (a plain index on
/// the hot path), a hash map where it is not.
enum ModeCache<const S: usize, const W: usize> {
    Dense(Vec<Option<Box<ModeData<S, W>>>>),
    Sparse(HashMap<usize, Box<ModeData<S, W>>>),
}

impl<const S: usize, const W: usize> ModeCache<S, W> {
    fn new(n_codes: usize) -> Self {
        if n_codes <= DENSE_MODES {
            ModeCache::Dense((0..n_codes).map(|_| None).collect())
        } else {
            ModeCache::Sparse(HashMap::new())
        }
    }

    #[inline(always)]
    fn get(&self, id: usize) -> Option<&ModeData<S, W>> {
        match self {
            ModeCache::Dense(v) => v[id].as_deref(),
            ModeCache::Sparse(m) => m.get(&id).map(|b| b.as_ref()),
        }
    }

    fn insert(&mut self, id: usize, md: Box<ModeData<S, W>>) {
        match self {
            ModeCache::Dense(v) => v[id] = Some(md),
            ModeCache::Sparse(m) => {
                m.insert(id, md);
            }
        }
    }
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
        assert!(
            model.mode_codes() % 2 == 1 && model.mode_codes() <= MODE_CODES,
            "mode codes must be -k..=k with k <= 2"
        );
        if model.n_switches() > MAX_SWITCHES {
            return Err(Error::InvalidArgument(format!(
                "at most {MAX_SWITCHES} switches are supported, got {}",
                model.n_switches()
            )));
        }
        Ok(Engine {
            model,
            ts,
            h: ts / substeps as f64,
            substeps,
            cache: ModeCache::new(model.mode_codes().saturating_pow(model.n_switches() as u32)),
        })
    }

    fn mode(&mut self, modes: &[i8]) -> usize {
        let id = encode(modes, self.model.mode_codes());
        if self.cache.get(id).is_none() {
            let md = Box::new(self.build(modes));
            self.cache.insert(id, md);
        }
        id
    }

    #[inline(always)]
    fn mode_data(&self, id: usize) -> &ModeData<S, W> {
        self.cache.get(id).expect("mode built before use")
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
                    hu: g.hu / g.scale,
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
        let mut modes = self.model.classify(&x, u[0]);
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
            let md = self.mode_data(id);
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
        let md = self.mode_data(id);
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
            let mut positive = 0u64;
            let mut peak = false;
            for i in 0..md.funcs.len().min(W) {
                // Values without the input term are carried over; the held input's
                // term (zero for functions of the state alone) is added for this step.
                let (g0, q0) = (cur.0[i] + fg.hu[i] * uk, cur.1[i]);
                let g1x = dot(&fg.h[i], &xn) + fg.d[i];
                let g1 = g1x + fg.hu[i] * uk;
                let q1 = dot(&fg.ha[i], &xn) + fg.hc[i];
                let (s0, s1) = (q0 + fg.hb[i] * uk, q1 + fg.hb[i] * uk);
                positive |= ((g1 > 0.0) as u64) << i;
                // An extremum towards the boundary inside the step: the function rises
                // at the start and falls at the end; tangent lines bound its peak.
                peak |= (s0 > 0.0)
                    & (s1 < 0.0)
                    & ((g0 + s0 * h > -GRAZE_RTOL) | (g1 - s1 * h > -GRAZE_RTOL));
                cur.0[i] = g1x;
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

    /// Advance one internal step locating every guard crossing inside it.
    fn slow_step(
        &mut self,
        modes: &mut [i8],
        x: &mut Vector<S>,
        u: f64,
        start: f64,
        out: &mut Sink<'_>,
    ) -> Result<usize, Error> {
        let mut id = encode(modes, self.model.mode_codes());
        let mut done = 0.0;
        for _ in 0..MAX_EVENTS_PER_STEP {
            let rem = self.h - done;
            let md = self.mode_data(id);
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
                    let from = modes[index];
                    modes[index] = target;
                    let to = self.model.resolve(index, from, target, modes, x, u);
                    modes[index] = to;
                    out.events.push(Event {
                        time: start + done + s * rem,
                        index,
                        from,
                        to,
                    });
                    id = self.mode(modes);
                    done += s * rem;
                }
            }
        }
        Err(Error::Zeno { time: start + done })
    }
}

/// Whether some guard has all its lanes set in `positive`.
#[inline(always)]
fn crossed(positive: u64, lanes: &[u64]) -> bool {
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
    if ns == 1 {
        out[from..to].fill(modes[0]);
        return;
    }
    // One row, then doubling copies: a copy per grid row would be a memcpy call each.
    let region = &mut out[from * ns..to * ns];
    region[..ns].copy_from_slice(modes);
    let mut filled = ns;
    while filled < region.len() {
        let n = filled.min(region.len() - filled);
        region.copy_within(..n, filled);
        filled += n;
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
