//! Running chains: one run, or a parallel batch into shared buffers.

use std::sync::{Arc, Mutex};

use rayon::prelude::*;
use rayon::{ThreadPool, ThreadPoolBuilder};

use super::{ChainModel, ChainParams, Law, MAX_INERTIAS};
use crate::hybrid::{Engine, Event, Graze, Trajectory};
use crate::linalg::Vector;
use crate::Error;

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
    let model = ChainModel::<S>::new(p.clone(), law, ts)?;
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
    let (events, mut grazes) =
        Engine::<S, W, _>::new(&model, ts)?.run_into(t0, u, &x0, states, modes)?;
    let n_shafts = p.n_inertias() - 1;
    let sticky = p.sticky();
    for g in grazes.iter_mut().filter(|g| g.index >= n_shafts) {
        g.index = n_shafts + sticky[g.index - n_shafts];
    }
    Ok((report_events(p, law, modes, events), grazes))
}

/// The kernel's modes and events as the chain reports them: Modelica's doubled-spring
/// sub-modes (+-2) as their flank (+-1), switches between a flank's sub-modes dropped;
/// friction switches indexed `N - 1 + inertia`.
fn report_events(p: &ChainParams, law: Law, modes: &mut [i8], events: Vec<Event>) -> Vec<Event> {
    let n_shafts = p.n_inertias() - 1;
    let sticky = p.sticky();
    if law == Law::Modelica {
        let ns = n_shafts + sticky.len();
        for row in modes.chunks_exact_mut(ns) {
            row[..n_shafts].iter_mut().for_each(|m| *m = m.signum());
        }
    }
    events
        .into_iter()
        .filter_map(|mut e| {
            if e.index < n_shafts {
                (e.from, e.to) = (e.from.signum(), e.to.signum());
                (e.from != e.to).then_some(e)
            } else {
                e.index = n_shafts + sticky[e.index - n_shafts];
                Some(e)
            }
        })
        .collect()
}

/// Run with the state size `S` and guard lanes `W` of the chain: `S = 2 N - 1`, one
/// more with a current loop, one more with the angle; 4 lanes per shaft and 2 per
/// sticky inertia.
macro_rules! dispatch {
    ($p:expr, $($n:literal => $s:literal, $w:literal, $wf:literal;)*) => {{
        let extra = $p.n_states() - (2 * $p.n_inertias() - 1);
        match ($p.n_inertias(), extra, !$p.sticky().is_empty()) {
            $(
                ($n, 0, false) => run_sized::<$s, $w>,
                ($n, 0, true) => run_sized::<$s, $wf>,
                ($n, 1, false) => run_sized::<{ $s + 1 }, $w>,
                ($n, 1, true) => run_sized::<{ $s + 1 }, $wf>,
                ($n, _, false) => run_sized::<{ $s + 2 }, $w>,
                ($n, _, true) => run_sized::<{ $s + 2 }, $wf>,
            )*
            (n, _, _) => {
                return Err(Error::InvalidArgument(format!(
                    "a chain needs 2 to {MAX_INERTIAS} inertias, got {n}"
                )))
            }
        }
    }};
}

/// As [`simulate_chain`], writing states (`u.len() x n_states`) and modes
/// (`u.len() x n_switches`, see [`ChainParams`]) into caller-provided row-major buffers.
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
    p.validate()?;
    let run = dispatch!(p,
        2 => 3, 4, 8;
        3 => 5, 8, 14;
        4 => 7, 12, 20;
        5 => 9, 16, 26;
        6 => 11, 20, 32;
        7 => 13, 24, 38;
        8 => 15, 28, 44;
    );
    run(p, law, t0, ts, u, x0, states, modes)
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
    p.validate()?;
    let mut states = vec![0.0; u.len() * p.n_states()];
    let mut modes = vec![0; u.len() * p.n_switches()];
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
/// initial state per chain. `workers == 0` uses rayon's global pool (all cores), `1` the
/// caller's thread. The result does not depend on the number of workers.
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
    let (s, m) = (params[0].n_states(), params[0].n_switches());
    if params
        .iter()
        .any(|p| p.n_states() != s || p.sticky() != params[0].sticky())
    {
        return Err(Error::InvalidArgument(
            "all chains of a batch must have the same number of inertias, the same \
             inertias with breakaway friction, and all or none a current loop"
                .into(),
        ));
    }
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
    let run = |i: usize, st: &mut [f64], md: &mut [i8]| {
        let ui = if shared {
            u
        } else {
            &u[i * n_samples..(i + 1) * n_samples]
        };
        simulate_chain_into(&params[i], law, t0, ts, ui, &x0[i * s..(i + 1) * s], st, md)
    };
    if workers == 1 {
        // One worker runs on the caller's thread: a pool's hand-off would cost more
        // than the short windows an estimator simulates.
        return states
            .chunks_mut(n_samples * s)
            .zip(modes.chunks_mut(n_samples * m))
            .enumerate()
            .map(|(i, (st, md))| run(i, st, md))
            .collect();
    }
    let mut job = || {
        states
            .par_chunks_mut(n_samples * s)
            .zip(modes.par_chunks_mut(n_samples * m))
            .enumerate()
            .map(|(i, (st, md))| run(i, st, md))
            .collect()
    };
    match workers {
        0 => job(),
        _ => pool(workers)?.install(job),
    }
}

/// The pool of `workers` threads, built once per size and kept: building one costs
/// a few hundred microseconds, more than a short batch.
fn pool(workers: usize) -> Result<Arc<ThreadPool>, Error> {
    static POOLS: Mutex<Vec<(usize, Arc<ThreadPool>)>> = Mutex::new(Vec::new());
    let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, p)) = pools.iter().find(|(w, _)| *w == workers) {
        return Ok(p.clone());
    }
    let p = Arc::new(
        ThreadPoolBuilder::new()
            .num_threads(workers)
            .build()
            .map_err(|e| {
                Error::InvalidArgument(format!("cannot start {workers} worker threads: {e}"))
            })?,
    );
    pools.push((workers, p.clone()));
    Ok(p)
}
