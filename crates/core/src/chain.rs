//! Drive chains with backlash: `N` inertias joined by `N - 1` elastic shafts, each with
//! a dead zone of half-width `theta_j` (paper A, eq. 2, for `N = 2`).
//!
//! State: `[w_1 .. w_N, phi_1 .. phi_{N-1}]`, `phi_j` the twist of shaft `j`. Mode of a
//! shaft: `0` in the gap, `+1` on the positive flank, `-1` on the negative flank.

use rayon::prelude::*;

use crate::hybrid::{Engine, Event, Graze, GuardFn, GuardSpec, HybridModel, Trajectory};
use crate::linalg::{Mat, Vector};
use crate::Error;

/// Largest number of inertias handled (state dimension 15).
pub const MAX_INERTIAS: usize = 8;
/// Twist scale (rad) used for tolerances when a shaft has no backlash (`theta = 0`).
pub const MIN_TWIST_SCALE: f64 = 1e-6;

/// Contact law of the shafts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// Paper A's law: torque `k (phi -+ theta) + d dphi/dt` whenever `|phi| >= theta`.
    Paper,
    /// The damper never pulls: contact holds while the spring-damper torque pushes.
    NoPull,
}

impl Law {
    pub fn from_code(code: i64) -> Result<Self, Error> {
        match code {
            0 => Ok(Law::Paper),
            1 => Ok(Law::NoPull),
            _ => Err(Error::InvalidArgument(format!(
                "law code must be 0 (paper) or 1 (no-pull), got {code}"
            ))),
        }
    }
}

/// Parameters of a chain (SI units).
#[derive(Clone, Debug, PartialEq)]
pub struct ChainParams {
    /// Inertias, kg m^2, > 0.
    pub j: Vec<f64>,
    /// Viscous frictions to ground, N m s/rad, >= 0.
    pub f: Vec<f64>,
    /// Shaft stiffnesses, N m/rad, > 0.
    pub k: Vec<f64>,
    /// Shaft damping, N m s/rad, >= 0.
    pub d: Vec<f64>,
    /// Backlash half-widths, rad, >= 0.
    pub theta: Vec<f64>,
}

impl ChainParams {
    /// Parameters from the packed layout `[J.., f.., k.., d.., theta..]`.
    pub fn from_packed(n: usize, p: &[f64]) -> Result<Self, Error> {
        if p.len() != 5 * n - 3 {
            return Err(Error::InvalidArgument(format!(
                "packed parameters of a {n}-inertia chain need {} values, got {}",
                5 * n - 3,
                p.len()
            )));
        }
        let (j, rest) = p.split_at(n);
        let (f, rest) = rest.split_at(n);
        let (k, rest) = rest.split_at(n - 1);
        let (d, theta) = rest.split_at(n - 1);
        let params = ChainParams {
            j: j.to_vec(),
            f: f.to_vec(),
            k: k.to_vec(),
            d: d.to_vec(),
            theta: theta.to_vec(),
        };
        params.validate()?;
        Ok(params)
    }

    pub fn n_inertias(&self) -> usize {
        self.j.len()
    }

    pub fn validate(&self) -> Result<(), Error> {
        let n = self.j.len();
        if !(2..=MAX_INERTIAS).contains(&n) {
            return Err(Error::InvalidArgument(format!(
                "a chain needs 2 to {MAX_INERTIAS} inertias, got {n}"
            )));
        }
        let check = |name: &str, v: &[f64], len: usize, positive: bool| -> Result<(), Error> {
            if v.len() != len {
                return Err(Error::InvalidArgument(format!(
                    "{name} must have {len} entries, got {}",
                    v.len()
                )));
            }
            for (i, &x) in v.iter().enumerate() {
                let ok = x.is_finite() && if positive { x > 0.0 } else { x >= 0.0 };
                if !ok {
                    let c = if positive { "> 0" } else { ">= 0" };
                    return Err(Error::InvalidArgument(format!(
                        "{name}[{i}] must be finite and {c}, got {x}"
                    )));
                }
            }
            Ok(())
        };
        check("J", &self.j, n, true)?;
        check("f", &self.f, n, false)?;
        check("k", &self.k, n - 1, true)?;
        check("d", &self.d, n - 1, false)?;
        check("theta", &self.theta, n - 1, false)
    }
}

/// The chain as a hybrid model with state dimension `S = 2 N - 1`.
pub struct ChainModel<const S: usize> {
    p: ChainParams,
    law: Law,
}

impl<const S: usize> ChainModel<S> {
    const N: usize = S.div_ceil(2);

    pub fn new(p: ChainParams, law: Law) -> Result<Self, Error> {
        p.validate()?;
        if 2 * p.n_inertias() - 1 != S {
            return Err(Error::InvalidArgument(
                "state dimension does not match the chain".into(),
            ));
        }
        Ok(ChainModel { p, law })
    }

    fn twist_scale(&self, j: usize) -> f64 {
        self.p.theta[j].max(MIN_TWIST_SCALE)
    }

    /// `phi_j - side * theta_j` (side = +1 / -1).
    fn twist_fn(&self, j: usize, side: f64) -> GuardFn<S> {
        let mut h = [0.0; S];
        h[Self::N + j] = 1.0;
        GuardFn {
            h,
            d: -side * self.p.theta[j],
            scale: self.twist_scale(j),
        }
    }

    /// Spring-damper torque on flank `side`: `k (phi - side theta) + d (w_j - w_{j+1})`.
    fn torque_fn(&self, j: usize, side: f64) -> GuardFn<S> {
        let mut h = [0.0; S];
        h[Self::N + j] = self.p.k[j];
        h[j] = self.p.d[j];
        h[j + 1] = -self.p.d[j];
        GuardFn {
            h,
            d: -side * self.p.k[j] * self.p.theta[j],
            scale: self.p.k[j] * self.twist_scale(j),
        }
    }
}

fn negate<const S: usize>(mut g: GuardFn<S>) -> GuardFn<S> {
    g.h.iter_mut().for_each(|v| *v = -*v);
    g.d = -g.d;
    g
}

impl<const S: usize> HybridModel<S> for ChainModel<S> {
    fn n_switches(&self) -> usize {
        Self::N - 1
    }

    fn dynamics(&self, modes: &[i8]) -> (Mat<S>, Vector<S>, Vector<S>) {
        let n = Self::N;
        let p = &self.p;
        let mut a = [[0.0; S]; S];
        let mut b = [0.0; S];
        let mut c = [0.0; S];
        for i in 0..n {
            a[i][i] = -p.f[i] / p.j[i];
        }
        b[0] = 1.0 / p.j[0];
        for (jx, &m) in modes.iter().enumerate() {
            let q = n + jx;
            a[q][jx] = 1.0;
            a[q][jx + 1] = -1.0;
            if m == 0 {
                continue;
            }
            // Shaft torque T = k phi + d (w_j - w_{j+1}) - m k theta acts as -T on
            // inertia j and +T on inertia j+1.
            let (k, d, off) = (p.k[jx], p.d[jx], -(m as f64) * p.k[jx] * p.theta[jx]);
            for (i, sign) in [(jx, -1.0), (jx + 1, 1.0)] {
                let s = sign / p.j[i];
                a[i][q] += s * k;
                a[i][jx] += s * d;
                a[i][jx + 1] -= s * d;
                c[i] += s * off;
            }
        }
        (a, b, c)
    }

    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<S>> {
        let mut out = Vec::new();
        for (j, &m) in modes.iter().enumerate() {
            let spec = |funcs: Vec<GuardFn<S>>, target: i8| GuardSpec {
                funcs,
                index: j,
                target,
            };
            match (self.law, m) {
                (Law::Paper, 0) => {
                    out.push(spec(vec![self.twist_fn(j, 1.0)], 1));
                    out.push(spec(vec![negate(self.twist_fn(j, -1.0))], -1));
                }
                (Law::Paper, 1) => out.push(spec(vec![negate(self.twist_fn(j, 1.0))], 0)),
                (Law::Paper, _) => out.push(spec(vec![self.twist_fn(j, -1.0)], 0)),
                (Law::NoPull, 0) => {
                    out.push(spec(vec![self.twist_fn(j, 1.0), self.torque_fn(j, 1.0)], 1));
                    out.push(spec(
                        vec![
                            negate(self.twist_fn(j, -1.0)),
                            negate(self.torque_fn(j, -1.0)),
                        ],
                        -1,
                    ));
                }
                (Law::NoPull, 1) => out.push(spec(vec![negate(self.torque_fn(j, 1.0))], 0)),
                (Law::NoPull, _) => out.push(spec(vec![self.torque_fn(j, -1.0)], 0)),
            }
        }
        out
    }

    fn classify(&self, x: &Vector<S>) -> Vec<i8> {
        let n = Self::N;
        (0..n - 1)
            .map(|j| {
                let phi = x[n + j];
                let th = self.p.theta[j];
                let spring_damper =
                    |side: f64| self.p.k[j] * (phi - side * th) + self.p.d[j] * (x[j] - x[j + 1]);
                let pos = phi > th && (self.law == Law::Paper || spring_damper(1.0) > 0.0);
                let neg = phi < -th && (self.law == Law::Paper || spring_damper(-1.0) < 0.0);
                if pos {
                    1
                } else if neg {
                    -1
                } else {
                    0
                }
            })
            .collect()
    }

    fn extreme_modes(&self) -> Vec<Vec<i8>> {
        vec![vec![0; Self::N - 1], vec![1; Self::N - 1]]
    }
}

/// Result of a chain simulation.
pub type ChainOutput = Trajectory;

/// Events and near-grazing passes of one run.
pub type RunEvents = (Vec<Event>, Vec<Graze>);

#[allow(clippy::too_many_arguments)]
fn run_sized<const S: usize, const W: usize>(
    p: &ChainParams,
    law: Law,
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    states: &mut [f64],
    modes: &mut [i8],
) -> Result<RunEvents, Error> {
    let model = ChainModel::<S>::new(p.clone(), law)?;
    let x0: Vector<S> = x0.try_into().map_err(|_| {
        Error::InvalidArgument(format!(
            "initial state must have {S} entries, got {}",
            x0.len()
        ))
    })?;
    if !x0.iter().all(|v| v.is_finite()) || !u.iter().all(|v| v.is_finite()) {
        return Err(Error::InvalidArgument(
            "input and initial state must be finite".into(),
        ));
    }
    Engine::<S, W, _>::new(&model, ts)?.run_into(t0, u, &x0, states, modes)
}

/// As [`simulate_chain`], writing states (`u.len() x (2N - 1)`) and modes
/// (`u.len() x (N - 1)`) into caller-provided row-major buffers.
#[allow(clippy::too_many_arguments)]
pub fn simulate_chain_into(
    p: &ChainParams,
    law: Law,
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
    states: &mut [f64],
    modes: &mut [i8],
) -> Result<RunEvents, Error> {
    match p.n_inertias() {
        2 => run_sized::<3, 4>(p, law, t0, ts, u, x0, states, modes),
        3 => run_sized::<5, 8>(p, law, t0, ts, u, x0, states, modes),
        4 => run_sized::<7, 12>(p, law, t0, ts, u, x0, states, modes),
        5 => run_sized::<9, 16>(p, law, t0, ts, u, x0, states, modes),
        6 => run_sized::<11, 20>(p, law, t0, ts, u, x0, states, modes),
        7 => run_sized::<13, 24>(p, law, t0, ts, u, x0, states, modes),
        8 => run_sized::<15, 28>(p, law, t0, ts, u, x0, states, modes),
        n => Err(Error::InvalidArgument(format!(
            "a chain needs 2 to {MAX_INERTIAS} inertias, got {n}"
        ))),
    }
}

/// Simulate a chain from `x0` at `t0` under ZOH torque `u` sampled every `ts` seconds.
pub fn simulate_chain(
    p: &ChainParams,
    law: Law,
    t0: f64,
    ts: f64,
    u: &[f64],
    x0: &[f64],
) -> Result<ChainOutput, Error> {
    let n_in = p.n_inertias().clamp(2, MAX_INERTIAS);
    let mut states = vec![0.0; u.len() * (2 * n_in - 1)];
    let mut modes = vec![0; u.len() * (n_in - 1)];
    let (events, grazes) = simulate_chain_into(p, law, t0, ts, u, x0, &mut states, &mut modes)?;
    Ok(Trajectory {
        states,
        modes,
        events,
        grazes,
    })
}

/// Simulate many chains of the same size in parallel into one pair of buffers:
/// `states` holds `B x n x (2N - 1)` and `modes` `B x n x (N - 1)` values (row-major).
/// `u` holds one input row shared by all chains, or one row per chain; `x0` one
/// initial state per chain. `workers == 0` uses rayon's global pool (all cores). The
/// result does not depend on the number of workers.
#[allow(clippy::too_many_arguments)]
pub fn simulate_chain_batch_into(
    params: &[ChainParams],
    law: Law,
    t0: f64,
    ts: f64,
    n_samples: usize,
    u: &[f64],
    x0: &[f64],
    states: &mut [f64],
    modes: &mut [i8],
    workers: usize,
) -> Result<Vec<RunEvents>, Error> {
    let b = params.len();
    if b == 0 {
        return Ok(Vec::new());
    }
    let n_in = params[0].n_inertias();
    if params.iter().any(|p| p.n_inertias() != n_in) {
        return Err(Error::InvalidArgument(
            "all chains of a batch must have the same number of inertias".into(),
        ));
    }
    let (s, m) = (2 * n_in - 1, n_in - 1);
    let shared = u.len() == n_samples;
    if !(shared || u.len() == b * n_samples) || x0.len() != b * s {
        return Err(Error::InvalidArgument(
            "inputs and initial states must have one row per chain".into(),
        ));
    }
    if states.len() != b * n_samples * s || modes.len() != b * n_samples * m {
        return Err(Error::InvalidArgument(
            "output buffers do not match the batch".into(),
        ));
    }
    if n_samples == 0 {
        return Ok(vec![(Vec::new(), Vec::new()); b]);
    }
    let mut job = move || -> Result<Vec<RunEvents>, Error> {
        states
            .par_chunks_mut(n_samples * s)
            .zip(modes.par_chunks_mut(n_samples * m))
            .enumerate()
            .map(|(i, (st, md))| {
                let ui = if shared {
                    u
                } else {
                    &u[i * n_samples..(i + 1) * n_samples]
                };
                simulate_chain_into(&params[i], law, t0, ts, ui, &x0[i * s..(i + 1) * s], st, md)
            })
            .collect()
    };
    if workers == 0 {
        job()
    } else {
        rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .build()
            .map_err(|e| {
                Error::InvalidArgument(format!("cannot start {workers} worker threads: {e}"))
            })?
            .install(job)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper_drive(theta: f64) -> ChainParams {
        ChainParams {
            j: vec![4.88e-3, 6.8e-2],
            f: vec![0.5e-2, 0.5e-2],
            k: vec![78.0],
            d: vec![1.575e-2],
            theta: vec![theta],
        }
    }

    fn paper_input(ts: f64) -> Vec<f64> {
        let n = (80.0 / ts) as usize + 1;
        (0..n)
            .map(|i| if (i as f64) * ts < 40.0 { 0.157 } else { 0.0 })
            .collect()
    }

    #[test]
    fn zero_backlash_matches_linear_steady_state() {
        // With theta = 0 the paper law is linear: the speed settles at u / (f_M + f_L)
        // (time constant (J_M + J_L) / (f_M + f_L) = 7.3 s, so 400 s is 55 of them).
        let p = paper_drive(0.0);
        let u = vec![0.157; 400_001];
        let out = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &u, &[0.0; 3]).unwrap();
        let last = &out.states[out.states.len() - 3..];
        assert!((last[0] - 15.7).abs() < 1e-6, "{last:?}");
        assert!((last[1] - 15.7).abs() < 1e-6);
        assert!((last[2] - 0.5e-2 * 15.7 / 78.0).abs() < 1e-9);
    }

    #[test]
    fn relation_4_holds_after_the_step_down() {
        // Paper A, eq. 4: theta = -1/2 int_{t_c}^{t_b} (w_M - w_L) dt, i.e. the twist
        // moves by exactly 2 theta between the first two contact changes after t_s.
        let theta = 3.49e-2;
        let p = paper_drive(theta);
        let out = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &paper_input(1e-3), &[0.0; 3]).unwrap();
        let after: Vec<_> = out.events.iter().filter(|e| e.time > 40.0).collect();
        assert!(after.len() >= 2, "{:?}", out.events);
        assert_eq!((after[0].from, after[0].to), (1, 0));
        assert_eq!((after[1].from, after[1].to), (0, -1));
        assert!(after[0].time > 40.0 && after[0].time < after[1].time);
    }

    #[test]
    fn steady_state_start_stays_put() {
        let theta = 0.02;
        let p = paper_drive(theta);
        let u0 = 0.3;
        let w = u0 / 1e-2;
        let x0 = [w, w, theta + 0.5e-2 * w / 78.0];
        for law in [Law::Paper, Law::NoPull] {
            let out = simulate_chain(&p, law, 0.0, 1e-3, &vec![u0; 1000], &x0).unwrap();
            assert!(out.events.is_empty());
            let last = &out.states[out.states.len() - 3..];
            for i in 0..3 {
                assert!(
                    (last[i] - x0[i]).abs() < 1e-9 * x0[i].abs().max(1.0),
                    "{law:?} {last:?}"
                );
            }
        }
    }

    #[test]
    fn event_located_inside_the_sample_free_flight() {
        // From rest in the middle of the gap, under torque u the motor alone accelerates:
        // w_M(t) = (u/f_M)(1 - exp(-f_M t / J_M)), load at rest, so the twist reaches
        // theta at the root of phi(t) = (u/f_M)(t - (J_M/f_M)(1 - exp(-f_M t/J_M))).
        let p = paper_drive(0.01);
        let u = 0.2;
        let (jm, fm) = (4.88e-3, 0.5e-2);
        let phi = |t: f64| (u / fm) * (t - (jm / fm) * (1.0 - (-fm * t / jm).exp()));
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if phi(mid) < 0.01 {
                lo = mid
            } else {
                hi = mid
            }
        }
        let out = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &vec![u; 100], &[0.0; 3]).unwrap();
        let e = out.events[0];
        assert_eq!((e.from, e.to), (0, 1));
        assert!((e.time - lo).abs() < 1e-12, "{} vs {}", e.time, lo);
        assert!(
            ((e.time / 1e-3).fract()).abs() > 1e-3,
            "event should not sit on the grid"
        );
    }

    #[test]
    fn no_pull_torque_never_negative_on_positive_flank() {
        let p = paper_drive(0.0349);
        let out = simulate_chain(
            &p,
            Law::NoPull,
            0.0,
            1e-3,
            &paper_input(1e-3)[..45_000],
            &[0.0; 3],
        )
        .unwrap();
        for (row, m) in out.states.chunks(3).zip(&out.modes) {
            if *m == 1 {
                let t = 78.0 * (row[2] - 0.0349) + 1.575e-2 * (row[0] - row[1]);
                assert!(t >= -1e-9, "{t}");
            }
        }
        // and the paper law does pull at some point after the step-down
        let out = simulate_chain(
            &p,
            Law::Paper,
            0.0,
            1e-3,
            &paper_input(1e-3)[..45_000],
            &[0.0; 3],
        )
        .unwrap();
        let min_t = out
            .states
            .chunks(3)
            .zip(&out.modes)
            .filter(|(_, m)| **m == 1)
            .map(|(r, _)| 78.0 * (r[2] - 0.0349) + 1.575e-2 * (r[0] - r[1]))
            .fold(f64::INFINITY, f64::min);
        assert!(min_t < 0.0);
    }

    #[test]
    fn batch_matches_single_runs_for_any_worker_count() {
        let params: Vec<_> = (0..8).map(|i| paper_drive(0.005 * i as f64)).collect();
        let u = paper_input(1e-3)[..5000].to_vec();
        let xs = vec![0.0; 3 * params.len()];
        let (b, n) = (params.len(), u.len());
        let run = |workers| {
            let mut st = vec![0.0; b * n * 3];
            let mut md = vec![0i8; b * n];
            let ev = simulate_chain_batch_into(
                &params,
                Law::Paper,
                0.0,
                1e-3,
                n,
                &u,
                &xs,
                &mut st,
                &mut md,
                workers,
            )
            .unwrap();
            (st, md, ev)
        };
        let (one, two) = (run(1), run(2));
        for (i, p) in params.iter().enumerate() {
            let single = simulate_chain(p, Law::Paper, 0.0, 1e-3, &u, &[0.0; 3]).unwrap();
            assert_eq!(single.states[..], one.0[i * n * 3..(i + 1) * n * 3]);
            assert_eq!(single.states[..], two.0[i * n * 3..(i + 1) * n * 3]);
            assert_eq!(single.modes[..], two.1[i * n..(i + 1) * n]);
            assert_eq!(single.events, two.2[i].0);
        }
    }

    #[test]
    fn invalid_parameters_are_reported() {
        let mut p = paper_drive(0.01);
        p.j[1] = -1.0;
        let err = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &[0.0; 10], &[0.0; 3]).unwrap_err();
        assert!(err.to_string().contains("J[1]"), "{err}");
        let p = paper_drive(0.01);
        let err = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &[0.0; 10], &[0.0; 5]).unwrap_err();
        assert!(err.to_string().contains("initial state"), "{err}");
    }
}
