//! The engine: a run sample by sample with the exact flow of the current mode, a cheap
//! check of the guards per sample, and a close look (Taylor expansion, located
//! crossings) only inside the internal steps where a guard may fire.

use super::locate::{find_crossing, Taylor};
use super::mode::{encode, ModeCache, ModeData, MODE_CODES};
use super::settle::Modal;
use super::{Event, Graze, HybridModel, Trajectory};
use crate::linalg::{spectral_radius_estimate, Mat, Vector};
use crate::Error;

/// Largest `rho(A) h` for which the Taylor expansion is used.
const MAX_RHO_H: f64 = 0.5;
/// Most mode changes allowed inside one internal step (guards against Zeno chatter).
const MAX_EVENTS_PER_STEP: usize = 64;
/// Most switches of a model: mode codes are packed in base `MODE_CODES` into a `usize`.
const MAX_SWITCHES: usize = 26;
/// A run tries to settle (module `settle`) only with at least this many internal steps
/// of held input left: a mode's first try computes its eigenvectors, which the checks
/// saved repay only over many steps.
const SETTLE_MIN_STEPS: usize = 4096;
/// Internal steps between tries to settle: a failed try costs a few products of the
/// state's size, against the checks of this many steps saved by an earlier success.
const SETTLE_EVERY: usize = 512;

/// Where a run writes: borrowed output buffers and growing event lists.
struct Sink<'a> {
    states: &'a mut [f64],
    modes: &'a mut [i8],
    events: Vec<Event>,
    grazes: Vec<Graze>,
}

/// The simulator for one model and one internal step.
///
/// `S` is the state dimension, `W` the number of guard-function lanes of the fast
/// check (at least the largest number of guard functions of any mode).
pub struct Engine<'m, const S: usize, const W: usize, M: HybridModel<S>> {
    model: &'m M,
    ts: f64,
    pub(super) h: f64,
    pub(super) substeps: usize,
    /// Modes built so far, by code (only the few visited ones are ever built).
    cache: ModeCache<S, W>,
    /// Samples of the last run computed by the flow alone (module `settle`).
    settled: usize,
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
            settled: 0,
        })
    }

    /// How many samples of the last run were the mode's flow alone, without a guard
    /// checked, where the engine proved that none could fire while the input was held.
    pub fn settled_samples(&self) -> usize {
        self.settled
    }

    fn mode(&mut self, modes: &[i8]) -> usize {
        let id = encode(modes, self.model.mode_codes());
        if self.cache.get(id).is_none() {
            let md = Box::new(ModeData::new(self.model, modes, self.h));
            self.cache.insert(id, md);
        }
        id
    }

    #[inline(always)]
    fn mode_data(&self, id: usize) -> &ModeData<S, W> {
        self.cache.get(id).expect("mode built before use")
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
        // Position: internal step `sub` of sample `k`. Grid modes from `filled` on are
        // not written yet; they equal `modes` up to the current sample.
        let (mut k, mut sub, mut filled) = (0usize, 0usize, 1usize);
        // Where the input is held long enough the run tries to settle, every `every`
        // samples at a sample's start; `stretch` is the current run of equal inputs.
        let every = (SETTLE_EVERY / self.substeps).max(1);
        let (mut try_at, mut stretch) = (0usize, 0..0);
        self.settled = 0;
        while k + 1 < n {
            if k >= try_at {
                if !stretch.contains(&k) {
                    stretch = k..held_until(u, k);
                }
                let end = stretch.end;
                try_at = if sub != 0 {
                    k + 1
                } else if (end - k) * self.substeps < SETTLE_MIN_STEPS {
                    // too short to pay, and only shorter later: on to the next hold that
                    // may (an input that changes every sample would stop the fast path
                    // at every sample)
                    next_hold(u, end, SETTLE_MIN_STEPS.div_ceil(self.substeps))
                } else if self.settles(id, &x, u[k]) {
                    self.coast(id, &mut x, u[k], k..end, out.states);
                    self.settled += end - k;
                    k = end;
                    end
                } else {
                    k + every
                };
                if k + 1 >= n {
                    break;
                }
            }
            // Run to the end, or to the sample of the next try.
            let stop = if try_at < n { try_at + 1 } else { n };
            let md = self.mode_data(id);
            let (u, states) = (&u[..stop], &mut *out.states);
            let fired = if self.substeps == 1 {
                self.fast_run_blocks::<true>(md, &mut x, u, &mut k, &mut sub, states)
            } else {
                self.fast_run_blocks::<false>(md, &mut x, u, &mut k, &mut sub, states)
            };
            if !fired {
                continue;
            }
            // A guard may fire inside internal step `sub` of sample `k`: redo it closely.
            fill_modes(out.modes, &modes, filled, k + 1);
            filled = k + 1;
            let start = t0 + (k as f64) * ts + (sub as f64) * self.h;
            id = self.slow_step(&mut modes, &mut x, u[k], start, &mut out)?;
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

    /// Whether no guard of mode `id` can fire from `x` while the input stays `u`.
    fn settles(&self, id: usize, x: &Vector<S>, u: f64) -> bool {
        let md = self.mode_data(id);
        md.modal
            .get_or_init(|| Modal::new(md))
            .as_ref()
            .is_some_and(|m| m.stays(md, x, u))
    }

    /// The samples after `held.start` up to `held.end` in mode `id` under the held input
    /// `u`, without checking a guard: the checked path's arithmetic, internal step by
    /// internal step, so the same states to the bit. (Composing a sample's steps into
    /// one map would be cheaper, but its rounding moved fits on rattling records that
    /// sit between two minima: `test_cli_notes_an_ambiguous_fit`.)
    fn coast(
        &self,
        id: usize,
        x: &mut Vector<S>,
        u: f64,
        held: std::ops::Range<usize>,
        states: &mut [f64],
    ) {
        let md = self.mode_data(id);
        for j in held.start + 1..=held.end {
            for _ in 0..self.substeps {
                *x = flow(&md.e, &md.fb, &md.fc, x, u);
            }
            states[j * S..(j + 1) * S].copy_from_slice(x);
        }
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

/// The end of the run of inputs equal to `u[k]` from `k` (exclusive): the samples up to
/// it follow that input. The last value, which no step uses, is not part of a run.
fn held_until(u: &[f64], k: usize) -> usize {
    let steps = &u[..u.len() - 1];
    steps[k..]
        .iter()
        .position(|&v| v != steps[k])
        .map_or(steps.len(), |i| k + i)
}

/// The start of the first run of equal inputs from `from` on that lasts `len` samples or
/// more (as [`held_until`] counts them), or the end of the input where none does.
fn next_hold(u: &[f64], from: usize, len: usize) -> usize {
    let last = u.len() - 1;
    let mut k = from;
    while k < last {
        let end = held_until(u, k);
        if end - k >= len {
            return k;
        }
        k = end;
    }
    last
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
