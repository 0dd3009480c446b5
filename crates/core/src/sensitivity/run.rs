//! Sensitivities along a run: the samples, split at the simulator's contact and
//! stick-slip changes, and the saltation jump at each change.

use super::flow::{Augmented, Flow};
use super::index::{D, FC_L, FC_M, F_L, F_M, J_L, J_M, K, TAU, THETA};
use super::lanes::{copy_lanes, groups, push_lanes, stream, Group, Row, Sink, LANES, WIDTH};
use super::mode::{balance, balance_derivative, system, Mode, N_MODES};
use super::{
    has_loop, state_count, N_LINEAR, N_LOOP_STATES, N_MAX_STATES, N_PARAMS, N_STATES, PARAMS,
};
use crate::chain::{simulate_chain, ChainParams, Law};
use crate::hybrid::{Event, Graze};
use crate::Error;

/// Sensitivities along a run, the run's states, and its near-grazing passes.
#[derive(Clone, Debug, Default)]
pub struct DriveSensitivities {
    /// `dx/dp`, row-major `(samples, n, m)` (`n` the drive's [`state_count`]): state
    /// by parameter, for the `m` parameters asked for (all seven, in the order
    /// [`PARAMS`](super::PARAMS), for [`drive_sensitivities`]).
    pub values: Vec<f64>,
    /// The simulator's states `x`, row-major `(samples, n)`.
    pub states: Vec<f64>,
    /// The simulator's near-grazing passes (see [`Graze`]): after one, the
    /// sensitivities are ill-conditioned (the derivative barely exists).
    pub grazes: Vec<Graze>,
}

/// Sensitivities `dx/dp` of the two-mass drive on the grid `t0 + i ts`, row-major
/// `(u.len(), n, 7)`: state `[w_M, w_L, phi]` (and the motor torque `T` behind a
/// current loop, `n` = [`state_count`]) by parameter of paper A's model (the first
/// [`N_LINEAR`] of [`PARAMS`]), in the parameters' SI units. The torque `u[i]` (the
/// loop's set-point where there is one) is held over `[t_i, t_{i+1})`; the run starts
/// at `x0` with zero sensitivity (paper A's law, Coulomb friction `p[7..9]` with
/// breakaway torques equal to it, a current loop of time constant `p[9]` where > 0).
///
/// Also returns the simulator's near-grazing passes.
///
/// Errors: invalid parameters (`J`, `k`, `theta` must be > 0, the frictions and
/// `tau_i` >= 0, all finite), sample time, input or initial state; a simulation
/// error; a change at which the shaft exactly grazes a flank ([`Error::Grazing`]).
pub fn drive_sensitivities(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
) -> Result<DriveSensitivities, Error> {
    let linear: [usize; N_LINEAR] = std::array::from_fn(|j| j);
    drive_sensitivities_of(p, t0, ts, u, x0, &linear)
}

/// As [`drive_sensitivities`], for the parameters `wanted` only (indices into
/// [`PARAMS`](super::PARAMS), distinct, in the order of the output's last axis): each
/// column adds two small matrix-vector products per sample, so a bound or a fit that
/// estimates a few parameters pays for those alone.
///
/// Errors: as [`drive_sensitivities`], an index out of range or repeated, and a
/// Coulomb torque wanted where it is 0 (the inertia has no friction switch there, and
/// the derivative is one-sided).
pub fn drive_sensitivities_of(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    wanted: &[usize],
) -> Result<DriveSensitivities, Error> {
    drive_sensitivities_from(p, t0, ts, u, x0, None, wanted)
}

/// As [`drive_sensitivities_of`], from `x0` whose sensitivity `dx0/dp` is `s0`
/// (row-major `(n, wanted.len())`, the output's layout; `None`: zero): a run that
/// continues another, such as the window after a held torque's run, or one that
/// starts from a steady state that moves with the parameters. The jumps and the flow
/// are linear in the sensitivities, so the run carries `s0` exactly.
///
/// Errors: as [`drive_sensitivities_of`], and `s0` of another size or not finite.
pub fn drive_sensitivities_from(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    s0: Option<&[f64]>,
    wanted: &[usize],
) -> Result<DriveSensitivities, Error> {
    let mut rows = Rows::new(u.len(), state_count(p), wanted.len());
    let (states, grazes) = simulate_and_walk(p, t0, ts, u, x0, s0, wanted, &mut rows)?;
    Ok(DriveSensitivities {
        values: rows.out,
        states,
        grazes,
    })
}

/// The run of the simulator (its states, row-major `(samples, n)`, and its
/// near-grazing passes), and the sensitivities along it to `sink`: the body of
/// [`drive_sensitivities_from`], whatever becomes of the rows.
#[allow(clippy::too_many_arguments)]
pub(super) fn simulate_and_walk<S: AnySink>(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    s0: Option<&[f64]>,
    wanted: &[usize],
    sink: &mut S,
) -> Result<(Vec<f64>, Vec<Graze>), Error> {
    let active = checked(p, state_count(p), s0, wanted)?;
    let chain = chain_params(p)?;
    if !t0.is_finite() {
        return Err(Error::InvalidArgument(format!(
            "start time must be finite, got {t0}"
        )));
    }
    let run = simulate_chain(&chain, Law::Paper, t0, ts, u, x0)?;
    let sticky = chain.sticky();
    if let Some(first) = run.modes.get(..1 + sticky.len()) {
        let along = Along {
            states: &run.states,
            first_modes: first,
            events: &run.events,
            motor_angle: false,
        };
        walk(p, &sticky, t0, ts, u, &along, s0, wanted, active, sink)?;
    }
    Ok((run.states, run.grazes))
}

/// A run of the simulator that the sensitivities can follow without simulating it
/// again: its states, row-major `(samples, n)`; its first sample's modes (the contact,
/// then each inertia with friction, as the simulator writes them); its changes; and
/// whether its states end with the motor's angle (the simulator's `track_angle`), whose
/// sensitivity the walk then carries too (an encoder's record is fitted as angles).
#[derive(Clone, Copy, Debug)]
pub struct Along<'a> {
    pub states: &'a [f64],
    pub first_modes: &'a [i8],
    pub events: &'a [Event],
    pub motor_angle: bool,
}

impl Along<'_> {
    /// The states of each sample of the run of a drive with parameters `p`: the
    /// drive's ([`state_count`]), and the motor's angle where tracked.
    pub fn state_count(&self, p: &[f64; N_PARAMS]) -> usize {
        state_count(p) + self.motor_angle as usize
    }
}

/// As [`drive_sensitivities_from`], along `run`, the simulator's run of the same
/// drive, grid and torque from `run`'s first state (the simulator's output for
/// `x0 = run.states[..n]`): the joint fit has just simulated the point whose
/// Jacobian it wants, and this skips simulating it again. The same arithmetic, so
/// the same values to the bit as [`drive_sensitivities_from`] on that run. Returns
/// `dx/dp` alone.
///
/// Errors: as [`drive_sensitivities_from`], and a run whose sizes do not match the
/// grid or the drive's switches, whose states are not finite, or whose changes are
/// out of order, outside the grid or not switches of this drive.
pub fn drive_sensitivities_along(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
) -> Result<Vec<f64>, Error> {
    let mut out = vec![0.0; u.len() * run.state_count(p) * wanted.len()];
    drive_sensitivities_along_into(p, t0, ts, u, run, s0, wanted, &mut out)?;
    Ok(out)
}

/// As [`drive_sensitivities_along`], into `out` (row-major `(u.len(), n,
/// wanted.len())`): a caller that asks again and again for runs of one size (the joint
/// fit's Jacobians) keeps one array, where a new one each time costs its fresh pages.
///
/// Errors: as [`drive_sensitivities_along`], and `out` of another size.
#[allow(clippy::too_many_arguments)]
pub fn drive_sensitivities_along_into(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
    out: &mut [f64],
) -> Result<(), Error> {
    let (active, sticky) = checked_along(p, t0, ts, u, run, s0, wanted)?;
    let n = run.state_count(p);
    let size = u.len() * n * wanted.len();
    if out.len() != size {
        return Err(Error::InvalidArgument(format!(
            "the output must hold {} x {n} x {} values, got {}",
            u.len(),
            wanted.len(),
            out.len()
        )));
    }
    if !u.is_empty() {
        let mut rows = RowsInto::new(out, wanted.len());
        walk(p, &sticky, t0, ts, u, run, s0, wanted, active, &mut rows)?;
    }
    Ok(())
}

/// The parameters carried (see [`checked`]) and the drive's inertias with a friction
/// switch, for a walk along `run` (checked against the grid and those switches).
pub(super) fn checked_along(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
) -> Result<([bool; N_PARAMS], Vec<usize>), Error> {
    let active = checked(p, run.state_count(p), s0, wanted)?;
    let sticky = chain_params(p)?.sticky();
    check_run(t0, ts, (u.len(), run.state_count(p)), run, &sticky)?;
    Ok((active, sticky))
}

/// As [`drive_sensitivities_along`], the last sample's sensitivities alone, row-major
/// `(n, wanted.len())`: a run whose end alone is wanted (a held torque's, which the
/// window after it starts from) writes no other row.
///
/// Errors: as [`drive_sensitivities_along`], and a run of no sample.
pub fn drive_sensitivity_at_end_along(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
) -> Result<Vec<f64>, Error> {
    let (active, sticky) = checked_along(p, t0, ts, u, run, s0, wanted)?;
    if u.is_empty() {
        return Err(Error::InvalidArgument(
            "a run of no sample has no last sensitivity".into(),
        ));
    }
    let mut last = Last {
        row: [[0.0; WIDTH]; N_MAX_STATES],
        left: u.len(),
    };
    walk(p, &sticky, t0, ts, u, run, s0, wanted, active, &mut last)?;
    let m = wanted.len();
    let rows = &last.row[..run.state_count(p)];
    Ok(rows.iter().flat_map(|r| &r[..m]).copied().collect())
}

/// A sink for the runs of any state count: the drive's own, behind a loop, and either
/// with the motor's angle.
pub(super) trait AnySink: Sink<N_STATES> + Sink<N_LOOP_STATES> + Sink<N_MAX_STATES> {}

impl<S: Sink<N_STATES> + Sink<N_LOOP_STATES> + Sink<N_MAX_STATES>> AnySink for S {}

/// The last of `left` rows, copied when it comes, and the others not at all (its
/// first `N` states' rows).
struct Last {
    row: Row<N_MAX_STATES>,
    left: usize,
}

impl<const N: usize> Sink<N> for Last {
    #[inline(always)]
    fn take(&mut self, row: &Row<N>) {
        self.left -= 1;
        if self.left == 0 {
            self.row[..N].copy_from_slice(row);
        }
    }
}

/// The rows written into a given array, row-major `(samples, n, m)`, in order.
struct RowsInto<'a> {
    out: &'a mut [f64],
    m: usize,
    groups: usize,
    pos: usize,
}

impl<'a> RowsInto<'a> {
    fn new(out: &'a mut [f64], m: usize) -> Self {
        RowsInto {
            out,
            m,
            groups: m.div_ceil(LANES),
            pos: 0,
        }
    }
}

impl<const N: usize> Sink<N> for RowsInto<'_> {
    /// Each state's lanes of the groups carried where the array has room for them
    /// (the next row overwrites what lies past this one's `m`; see [`copy_lanes`]),
    /// else its `m` values.
    #[inline(always)]
    fn take(&mut self, row: &Row<N>) {
        for r in row {
            let (pos, m) = (self.pos, self.m);
            if pos + self.groups * LANES <= self.out.len() {
                copy_lanes(&mut self.out[pos..], r, self.groups);
            } else {
                self.out[pos..pos + m].copy_from_slice(&r[..m]);
            }
            self.pos += m;
        }
    }
}

/// The rows pushed onto a new array, row-major `(samples, n, m)`: unlike [`RowsInto`]
/// on a zeroed one, nothing is written twice.
struct Rows {
    m: usize,
    groups: usize,
    out: Vec<f64>,
}

impl Rows {
    fn new(samples: usize, n: usize, m: usize) -> Self {
        Rows {
            m,
            groups: m.div_ceil(LANES),
            out: Vec::with_capacity(samples * n * m + WIDTH),
        }
    }
}

impl<const N: usize> Sink<N> for Rows {
    /// Each state's lanes of the groups carried, then back to its first `m` (see
    /// [`push_lanes`]; the capacity has a row's room to spare).
    #[inline(always)]
    fn take(&mut self, row: &Row<N>) {
        for r in row {
            let len = self.out.len();
            push_lanes(&mut self.out, r, self.groups);
            self.out.truncate(len + self.m);
        }
    }
}

/// Which parameters are carried: `wanted`, checked (distinct, in range, a Coulomb
/// torque only where positive), with `s0` of the matching size (`n` states by the
/// parameters).
fn checked(
    p: &[f64; N_PARAMS],
    n: usize,
    s0: Option<&[f64]>,
    wanted: &[usize],
) -> Result<[bool; N_PARAMS], Error> {
    let mut active = [false; N_PARAMS];
    for &j in wanted {
        if j >= N_PARAMS || active[j] {
            return Err(Error::InvalidArgument(format!(
                "parameter indices must be distinct and below {N_PARAMS}, got {wanted:?}"
            )));
        }
        active[j] = true;
    }
    if let Some(&j) = wanted.iter().find(|&&j| j >= N_LINEAR && p[j] == 0.0) {
        return Err(Error::InvalidArgument(format!(
            "the sensitivity to {} needs {} > 0, got 0",
            PARAMS[j], PARAMS[j]
        )));
    }
    if let Some(s0) = s0 {
        if s0.len() != n * wanted.len() || !s0.iter().all(|v| v.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "the initial sensitivity must hold {n} x {} finite values (states by \
                 parameters), got {} values",
                wanted.len(),
                s0.len()
            )));
        }
    }
    Ok(active)
}

/// A run given to [`drive_sensitivities_along`] checked against the grid of `n`
/// samples and the drive's switches: the contact (event 0), then each inertia `i` of
/// `sticky` (event `1 + i`, the simulator's numbering).
fn check_run(
    t0: f64,
    ts: f64,
    (n, n_states): (usize, usize),
    run: &Along<'_>,
    sticky: &[usize],
) -> Result<(), Error> {
    let switches = 1 + sticky.len();
    let bad = |what: String| Err(Error::InvalidArgument(format!("the run given {what}")));
    if !(t0.is_finite() && ts.is_finite() && ts > 0.0) {
        return bad(format!(
            "needs a finite start and a sample time > 0, got {t0} and {ts}"
        ));
    }
    if run.states.len() != n * n_states || !run.states.iter().all(|v| v.is_finite()) {
        return bad(format!(
            "must hold {n} x {n_states} finite states, got {} values",
            run.states.len()
        ));
    }
    if n > 0 && run.first_modes.len() != switches {
        return bad(format!(
            "must give the first sample's {switches} modes, got {}",
            run.first_modes.len()
        ));
    }
    // The grid's ends widened by a sample: what the simulator locates lies inside,
    // and only rounding could put it a hair outside.
    let (start, end) = (t0 - ts, t0 + n as f64 * ts);
    let mut last = start;
    for ev in run.events {
        let mode = |m: i8| (-1..=1).contains(&m);
        let switch = ev.index == 0 || sticky.contains(&(ev.index - 1));
        if !(ev.time >= last && ev.time <= end && switch && mode(ev.from) && mode(ev.to)) {
            return bad(format!(
                "has a change out of order, outside [{start}, {end}] s or of no switch of \
                 this drive: {ev:?}"
            ));
        }
        last = ev.time;
    }
    Ok(())
}

/// The sensitivities along a run of the drive (`run`, checked; `sticky`: its inertias
/// with a friction switch), from `s0`, each sample's row to `sink`: of the drive's
/// three states, four behind a current loop, and one more with the motor's angle.
#[allow(clippy::too_many_arguments)]
pub(super) fn walk<S: AnySink>(
    p: &[f64; N_PARAMS],
    sticky: &[usize],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
    active: [bool; N_PARAMS],
    sink: &mut S,
) -> Result<(), Error> {
    match run.state_count(p) {
        N_STATES => walk_states::<N_STATES, S>(p, sticky, t0, ts, u, run, s0, wanted, active, sink),
        N_LOOP_STATES => {
            walk_states::<N_LOOP_STATES, S>(p, sticky, t0, ts, u, run, s0, wanted, active, sink)
        }
        _ => walk_states::<N_MAX_STATES, S>(p, sticky, t0, ts, u, run, s0, wanted, active, sink),
    }
}

/// [`walk`] for a state of `N` entries.
#[allow(clippy::too_many_arguments)]
fn walk_states<const N: usize, S: Sink<N>>(
    p: &[f64; N_PARAMS],
    sticky: &[usize],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
    active: [bool; N_PARAMS],
    sink: &mut S,
) -> Result<(), Error> {
    let mut mode = Mode::contact(run.first_modes[0]);
    for (r, &i) in sticky.iter().enumerate() {
        mode.slip[i] = run.first_modes[1 + r];
    }
    // Sensitivities are carried per log-parameter (see `flow`); a zero friction or
    // damping keeps the plain derivative.
    let scale = p.map(|v| if v > 0.0 { v } else { 1.0 });
    let x = std::array::from_fn(|i| run.states[i]);
    let mut s = [[0.0; N]; N_PARAMS];
    for (c, &j) in wanted.iter().enumerate() {
        for i in 0..N {
            s[j][i] = s0.map_or(0.0, |s0| s0[i * wanted.len() + c] * scale[j]);
        }
    }
    let mut walk = Walk {
        p,
        scale,
        unscale: scale.map(|v| 1.0 / v),
        active,
        wanted,
        mode,
        z: Augmented { x, s },
        last: (f64::NAN, [0.0; N_PARAMS]),
        full: std::array::from_fn(|_| None),
        stepped: !has_loop(p),
    };
    walk.run(t0, ts, u, run.states, run.events, sink)
}

/// The chain of the two-mass drive (behind its current loop, where `tau_i > 0`),
/// validated; `theta` must be positive, the NumPy
/// twin's scope (with no gap both flanks' changes fall at one instant, not checked).
/// The breakaway torques are the Coulomb torques (`fs` left empty).
fn chain_params(p: &[f64; N_PARAMS]) -> Result<ChainParams, Error> {
    let mut chain = ChainParams::new(
        vec![p[J_M], p[J_L]],
        vec![p[F_M], p[F_L]],
        vec![p[K]],
        vec![p[D]],
        vec![p[THETA]],
    );
    if p[FC_M] != 0.0 || p[FC_L] != 0.0 {
        chain.fc = vec![p[FC_M], p[FC_L]];
    }
    chain.tau_i = p[TAU];
    chain.validate()?;
    if p[THETA] <= 0.0 {
        return Err(Error::InvalidArgument(format!(
            "theta must be > 0 for the sensitivities, got {}",
            p[THETA]
        )));
    }
    Ok(chain)
}

/// The state of the walk along the samples, of `N` states.
struct Walk<'a, const N: usize> {
    p: &'a [f64; N_PARAMS],
    scale: [f64; N_PARAMS],
    /// `1 / scale`: the written sensitivities are in the parameters' units.
    unscale: [f64; N_PARAMS],
    /// The sensitivities carried, and the order they are written in.
    active: [bool; N_PARAMS],
    wanted: &'a [usize],
    /// Current mode: contact and friction switches (the simulator's event `1 + i`
    /// switches inertia `i`'s).
    mode: Mode,
    z: Augmented<N>,
    /// The last change's time and `dtau/dp`, for a breakaway it sets off.
    last: (f64, [f64; N_PARAMS]),
    /// Whole-sample flows of the modes in groups of columns (by [`Mode::slot`]),
    /// built when first needed.
    full: [Option<Vec<Group<N>>>; N_MODES],
    /// Whether the input steps at each sample's instant on the inertias: without a
    /// current loop (behind one the motor torque is a state, continuous in time).
    stepped: bool,
}

impl<const N: usize> Walk<'_, N> {
    /// The sensitivities at every sample, along the simulator's `states` (row-major
    /// `(u.len(), N)`). Between the samples that hold contact changes the mode is
    /// fixed, and the columns advance over those whole samples side by side (see
    /// `lanes`); a sample holding changes is split at them.
    fn run<S: Sink<N>>(
        &mut self,
        t0: f64,
        ts: f64,
        u: &[f64],
        states: &[f64],
        events: &[Event],
        sink: &mut S,
    ) -> Result<(), Error> {
        let n = u.len();
        let (mut k, mut next_event) = (0, 0);
        loop {
            // Changes up to a sample's end, inclusive, belong to that sample; but a
            // breakaway at a sample's start is the next torque's (see `pinned`).
            let next = events.get(next_event);
            let split = (k..n - 1)
                .find(|&i| next.is_some_and(|e| within(e, t0 + (i + 1) as f64 * ts, self.stepped)))
                .unwrap_or(n - 1);
            self.steady(ts, k, split, u, states, sink);
            self.z.x = std::array::from_fn(|i| states[split * N + i]);
            sink.take(&self.row());
            if split + 1 == n {
                return Ok(());
            }
            let (t_start, t_end) = (t0 + split as f64 * ts, t0 + (split + 1) as f64 * ts);
            let mut t_now = t_start;
            while let Some(ev) = events
                .get(next_event)
                .filter(|e| within(e, t_end, self.stepped))
            {
                self.advance(u[split], ev.time - t_now);
                self.jump(ev, u[split], self.stepped && pinned(ev, t_start))?;
                (t_now, next_event) = (ev.time, next_event + 1);
            }
            self.advance(u[split], t_end - t_now);
            k = split + 1;
        }
    }

    /// Rows `k..end` to `sink`, over the whole samples `k..end` in the current mode,
    /// leaving the carried columns at sample `end`'s start.
    fn steady<S: Sink<N>>(
        &mut self,
        ts: f64,
        k: usize,
        end: usize,
        u: &[f64],
        states: &[f64],
        sink: &mut S,
    ) {
        if end == k || self.wanted.is_empty() {
            return;
        }
        let (p, scale, mode, active) = (self.p, &self.scale, self.mode, &self.active);
        let (wanted, unscale) = (self.wanted, &self.unscale);
        let groups = self.full[mode.slot()]
            .get_or_insert_with(|| groups(&Flow::new(p, scale, mode, ts, active), wanted, unscale));
        let x = &states[k * N..end * N];
        stream(groups, &mut self.z.s, &u[k..end], x, sink);
    }

    /// The current sample's row of `dx/dp`.
    fn row(&self) -> Row<N> {
        let mut row = [[0.0; WIDTH]; N];
        for i in 0..N {
            for (c, &j) in self.wanted.iter().enumerate() {
                row[i][c] = self.z.s[j][i] * self.unscale[j];
            }
        }
        row
    }

    /// Advance by `tau` in the current mode (nothing for `tau <= 0`).
    fn advance(&mut self, u: f64, tau: f64) {
        if tau > 0.0 {
            let flow = Flow::new(self.p, &self.scale, self.mode, tau, &self.active);
            flow.apply(&mut self.z, u, self.wanted);
        }
    }

    /// The change `ev` at the current state. It moves by `dtau/dp = -(dg/dx S + dg/dp)
    /// / (dg/dx f_-)`, its guard `g` linearised, and the sensitivities jump by `(f_- -
    /// f_+) dtau/dp`. A breakaway that another change or the torque's step set off at
    /// its instant (its guard jumped past 0 there) moves with that cause instead: by
    /// the other change's `dtau/dp`, or not at all (`pinned`).
    fn jump(&mut self, ev: &Event, u: f64, pinned: bool) -> Result<(), Error> {
        let mut after = self.mode;
        let stuck = if ev.index == 0 {
            after.flank = ev.to;
            None
        } else {
            let i = ev.index - 1;
            after.slip[i] = ev.to;
            (ev.to == 0).then_some(i)
        };
        let f_minus = system::<N>(self.p, self.mode).field(&self.z.x, u);
        let f_plus = system::<N>(self.p, after).field(&self.z.x, u);
        let set_off = ev.index > 0 && ev.from == 0 && self.last.0 == ev.time;
        let dtau = if pinned {
            [0.0; N_PARAMS]
        } else if set_off {
            self.last.1
        } else {
            let guard = self.guard(ev, &f_minus, u);
            std::array::from_fn(|j| -(guard.slope(&self.z.s[j]) + guard.dg_dp[j]) / guard.rate)
        };
        for j in (0..N_PARAMS).filter(|&j| self.active[j]) {
            if !dtau[j].is_finite() {
                return Err(Error::Grazing { time: ev.time });
            }
            for i in 0..N {
                self.z.s[j][i] += (f_minus[i] - f_plus[i]) * dtau[j];
            }
            if let Some(i) = stuck {
                self.z.s[j][i] = 0.0; // the jump's value, to rounding
            }
        }
        if let Some(i) = stuck {
            self.z.x[i] = 0.0; // as the simulator sets it
        }
        (self.mode, self.last) = (after, (ev.time, dtau));
        Ok(())
    }

    /// The guard of change `ev` linearised at the current state: a contact change's
    /// `phi - s theta` (`s` the flank met or left); a slipping inertia's speed `w_i`
    /// crossing zero; a stuck inertia's breakaway `s T_i - fc_i`, `T_i` the torque on
    /// it (input and shaft, friction excluded) and `s` the direction it breaks away
    /// in, the breakaway torque tied to the Coulomb torque (behind a current loop the
    /// torque on the motor is the state `T`, not the input).
    fn guard(&self, ev: &Event, f_minus: &[f64; N], u: f64) -> Guard<N> {
        let mut g = Guard {
            dg_dx: [0.0; N],
            dg_dp: [0.0; N_PARAMS],
            rate: 0.0,
        };
        if ev.index == 0 {
            let side = if ev.from == 0 { ev.to } else { ev.from } as f64;
            g.dg_dx[2] = 1.0;
            g.dg_dp[THETA] = -side * self.scale[THETA];
        } else if ev.from != 0 {
            // The sign of g = -m w_i cancels in dtau: w_i itself serves.
            g.dg_dx[ev.index - 1] = 1.0;
        } else {
            let (i, s) = (ev.index - 1, ev.to as f64);
            let flank = self.mode.flank;
            g.dg_dx = balance::<N>(self.p, flank).r[i].map(|v| s * v);
            for j in (0..N_PARAMS).filter(|&j| self.active[j] && j != J_M && j != J_L) {
                let torque = balance_derivative::<N>(self.p, flank, j).torque(i, &self.z.x, u);
                g.dg_dp[j] = s * torque * self.scale[j];
            }
            let fc = [FC_M, FC_L][i];
            if self.active[fc] {
                g.dg_dp[fc] -= self.scale[fc];
            }
        }
        g.rate = g.slope(f_minus);
        g
    }
}

/// Whether change `ev` belongs to the sample ending at `t_end`: it is before, or at
/// the end and not [`pinned`] there (where the input steps at the samples' instants,
/// `stepped`; behind a current loop nothing is pinned).
fn within(ev: &Event, t_end: f64, stepped: bool) -> bool {
    ev.time < t_end || (ev.time == t_end && !(stepped && pinned(ev, t_end)))
}

/// Whether change `ev` is a breakaway at the sample's start `t_start`: the torque
/// stepped past the breakaway torque there, so the change stays at that instant as
/// the parameters move (`dtau/dp = 0`), under the new sample's torque. The simulator
/// finds it at the start of that sample, at exactly this time; a breakaway that the
/// flow drives lands on a sample's instant only by chance.
fn pinned(ev: &Event, t_start: f64) -> bool {
    ev.index > 0 && ev.from == 0 && ev.time == t_start
}

/// A change's guard linearised: `dg/dx`, `dg/dp` per log-parameter, and its rate
/// `dg/dx f_-` along the flow before the change.
struct Guard<const N: usize> {
    dg_dx: [f64; N],
    dg_dp: [f64; N_PARAMS],
    rate: f64,
}

impl<const N: usize> Guard<N> {
    /// `dg/dx v`.
    fn slope(&self, v: &[f64; N]) -> f64 {
        (0..N).map(|q| self.dg_dx[q] * v[q]).sum()
    }
}
