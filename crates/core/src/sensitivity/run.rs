//! Sensitivities along a run: the samples, split at the simulator's contact changes,
//! and the saltation jump at each change.

use super::flow::{Augmented, Flow};
use super::index::{D, F_L, F_M, J_L, J_M, K, THETA};
use super::lanes::{groups, Group};
use super::mode::system;
use super::{N_PARAMS, N_STATES};
use crate::chain::{simulate_chain, ChainParams, Law};
use crate::hybrid::{Event, Graze};
use crate::Error;

/// Sensitivities along a run, the run's states, and its near-grazing passes.
#[derive(Clone, Debug, Default)]
pub struct DriveSensitivities {
    /// `dx/dp`, row-major `(samples, 3, m)`: state by parameter, for the `m`
    /// parameters asked for (all seven, in the order [`PARAMS`](super::PARAMS), for
    /// [`drive_sensitivities`]).
    pub values: Vec<f64>,
    /// The simulator's states `x`, row-major `(samples, 3)`.
    pub states: Vec<f64>,
    /// The simulator's near-grazing passes (see [`Graze`]): after one, the
    /// sensitivities are ill-conditioned (the derivative barely exists).
    pub grazes: Vec<Graze>,
}

/// Sensitivities `dx/dp` of the two-mass drive on the grid `t0 + i ts`, row-major
/// `(u.len(), 3, 7)`: state `[w_M, w_L, phi]` by parameter (order
/// [`PARAMS`](super::PARAMS)), in the parameters' SI units. The torque `u[i]` is held
/// over `[t_i, t_{i+1})`; the run starts at `x0` with zero sensitivity (paper A's law,
/// no Coulomb friction, no current loop).
///
/// Also returns the simulator's near-grazing passes.
///
/// Errors: invalid parameters (`J`, `k`, `theta` must be > 0, the frictions >= 0, all
/// finite), sample time, input or initial state; a simulation error; a change at which
/// the shaft exactly grazes a flank ([`Error::Grazing`]).
pub fn drive_sensitivities(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
) -> Result<DriveSensitivities, Error> {
    let all: [usize; N_PARAMS] = std::array::from_fn(|j| j);
    drive_sensitivities_of(p, t0, ts, u, x0, &all)
}

/// As [`drive_sensitivities`], for the parameters `wanted` only (indices into
/// [`PARAMS`](super::PARAMS), distinct, in the order of the output's last axis): each
/// column adds two small matrix-vector products per sample, so a bound or a fit that
/// estimates a few parameters pays for those alone.
///
/// Errors: as [`drive_sensitivities`], and an index out of range or repeated.
pub fn drive_sensitivities_of(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    wanted: &[usize],
) -> Result<DriveSensitivities, Error> {
    let mut active = [false; N_PARAMS];
    for &j in wanted {
        if j >= N_PARAMS || active[j] {
            return Err(Error::InvalidArgument(format!(
                "parameter indices must be distinct and below {N_PARAMS}, got {wanted:?}"
            )));
        }
        active[j] = true;
    }
    let chain = chain_params(p)?;
    if !t0.is_finite() {
        return Err(Error::InvalidArgument(format!(
            "start time must be finite, got {t0}"
        )));
    }
    let run = simulate_chain(&chain, Law::Paper, t0, ts, u, x0)?;
    let Some(&first_mode) = run.modes.first() else {
        return Ok(DriveSensitivities::default());
    };
    // Sensitivities are carried per log-parameter (see `flow`); a zero friction or
    // damping keeps the plain derivative.
    let scale = p.map(|v| if v > 0.0 { v } else { 1.0 });
    // The simulator has checked that x0 has three finite entries.
    let x = [x0[0], x0[1], x0[2]];
    let z = Augmented {
        x,
        s: [[0.0; N_STATES]; N_PARAMS],
    };
    let mut walk = Walk {
        p,
        scale,
        unscale: scale.map(|v| 1.0 / v),
        active,
        wanted,
        flank: first_mode,
        z,
        full: [None, None, None],
    };
    let values = walk.run(t0, ts, u, &run.states, &run.events)?;
    Ok(DriveSensitivities {
        values,
        states: run.states,
        grazes: run.grazes,
    })
}

/// The chain of the two-mass drive, validated; `theta` must be positive, the NumPy
/// twin's scope (with no gap both flanks' changes fall at one instant, not checked).
fn chain_params(p: &[f64; N_PARAMS]) -> Result<ChainParams, Error> {
    let chain = ChainParams::new(
        vec![p[J_M], p[J_L]],
        vec![p[F_M], p[F_L]],
        vec![p[K]],
        vec![p[D]],
        vec![p[THETA]],
    );
    chain.validate()?;
    if p[THETA] <= 0.0 {
        return Err(Error::InvalidArgument(format!(
            "theta must be > 0 for the sensitivities, got {}",
            p[THETA]
        )));
    }
    Ok(chain)
}

/// The state of the walk along the samples.
struct Walk<'a> {
    p: &'a [f64; N_PARAMS],
    scale: [f64; N_PARAMS],
    /// `1 / scale`: the written sensitivities are in the parameters' units.
    unscale: [f64; N_PARAMS],
    /// The sensitivities carried, and the order they are written in.
    active: [bool; N_PARAMS],
    wanted: &'a [usize],
    /// Current contact mode: 0 the gap, +-1 a flank.
    flank: i8,
    z: Augmented,
    /// Whole-sample flows of the modes -1, 0, +1 in groups of columns, built when
    /// first needed.
    full: [Option<Vec<Group>>; 3],
}

impl Walk<'_> {
    /// The sensitivities at every sample, along the simulator's `states` (row-major
    /// `(u.len(), 3)`). Between the samples that hold contact changes the mode is
    /// fixed, and the columns advance over those whole samples side by side (see
    /// `lanes`); a sample holding changes is split at them.
    fn run(
        &mut self,
        t0: f64,
        ts: f64,
        u: &[f64],
        states: &[f64],
        events: &[Event],
    ) -> Result<Vec<f64>, Error> {
        let (n, row) = (u.len(), N_STATES * self.wanted.len());
        let mut out = vec![0.0; n * row];
        let (mut k, mut next_event) = (0, 0);
        loop {
            // Changes up to a sample's end, inclusive, belong to that sample.
            let next_time = events.get(next_event).map_or(f64::INFINITY, |e| e.time);
            let split = (k..n - 1)
                .find(|&i| t0 + (i + 1) as f64 * ts >= next_time)
                .unwrap_or(n - 1);
            self.steady(ts, k, split, u, states, &mut out[k * row..]);
            self.z.x = std::array::from_fn(|i| states[split * N_STATES + i]);
            self.write(&mut out[split * row..(split + 1) * row]);
            if split + 1 == n {
                return Ok(out);
            }
            let (t_start, t_end) = (t0 + split as f64 * ts, t0 + (split + 1) as f64 * ts);
            let mut t_now = t_start;
            while let Some(ev) = events.get(next_event).filter(|e| e.time <= t_end) {
                self.advance(u[split], ev.time - t_now);
                self.jump(ev, u[split])?;
                (t_now, next_event) = (ev.time, next_event + 1);
            }
            self.advance(u[split], t_end - t_now);
            k = split + 1;
        }
    }

    /// Rows `k..end` of `out` (which starts at row `k`) over the whole samples `k..end`
    /// in the current mode, leaving the carried columns at sample `end`'s start.
    fn steady(
        &mut self,
        ts: f64,
        k: usize,
        end: usize,
        u: &[f64],
        states: &[f64],
        out: &mut [f64],
    ) {
        if end == k || self.wanted.is_empty() {
            return;
        }
        let slot = (self.flank + 1) as usize;
        let (p, scale, flank, active) = (self.p, &self.scale, self.flank, &self.active);
        let (wanted, unscale) = (self.wanted, &self.unscale);
        let groups = self.full[slot].get_or_insert_with(|| {
            groups(&Flow::new(p, scale, flank, ts, active), wanted, unscale)
        });
        let x = &states[k * N_STATES..end * N_STATES];
        for group in groups.iter() {
            group.stream(&mut self.z.s, wanted.len(), &u[k..end], x, out);
        }
    }

    /// Rows `state x wanted parameter` of `dx/dp` into `row`.
    fn write(&self, row: &mut [f64]) {
        let m = self.wanted.len();
        for i in 0..N_STATES {
            for (c, &j) in self.wanted.iter().enumerate() {
                row[i * m + c] = self.z.s[j][i] * self.unscale[j];
            }
        }
    }

    /// Advance by `tau` in the current mode (nothing for `tau <= 0`).
    fn advance(&mut self, u: f64, tau: f64) {
        if tau > 0.0 {
            let flow = Flow::new(self.p, &self.scale, self.flank, tau, &self.active);
            flow.apply(&mut self.z, u, self.wanted);
        }
    }

    /// The change `ev` at the current state: the guard `g = phi - s theta` (`s` the
    /// flank met or left) moves by `dtau/dp = -(dg/dx S + dg/dp) / (dg/dx f_-)` and the
    /// sensitivities jump by `(f_- - f_+) dtau/dp`.
    fn jump(&mut self, ev: &Event, u: f64) -> Result<(), Error> {
        let side = if ev.from == 0 { ev.to } else { ev.from } as f64;
        let f_minus = system(self.p, self.flank).field(&self.z.x, u);
        let f_plus = system(self.p, ev.to).field(&self.z.x, u);
        // dg/dx = [0, 0, 1]: the guard's rate is the twist rate w_M - w_L.
        let rate = f_minus[2];
        for j in (0..N_PARAMS).filter(|&j| self.active[j]) {
            let dg_dp = if j == THETA {
                -side * self.scale[j]
            } else {
                0.0
            };
            let dtau = -(self.z.s[j][2] + dg_dp) / rate;
            if !dtau.is_finite() {
                return Err(Error::Grazing { time: ev.time });
            }
            for i in 0..N_STATES {
                self.z.s[j][i] += (f_minus[i] - f_plus[i]) * dtau;
            }
        }
        self.flank = ev.to;
        Ok(())
    }
}
