use super::*;
use crate::hybrid::{Engine, Event};

fn paper_drive(theta: f64) -> ChainParams {
    ChainParams::new(
        vec![4.88e-3, 6.8e-2],
        vec![0.5e-2, 0.5e-2],
        vec![78.0],
        vec![1.575e-2],
        vec![theta],
    )
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
    // One worker runs on the caller's thread, 0 on the global pool, 2 on a kept pool
    // (the second call reuses it).
    let (one, two) = (run(1), run(2));
    assert_eq!((run(0), run(2)), (one.clone(), two.clone()));
    for (i, p) in params.iter().enumerate() {
        let single = simulate_chain(p, Law::Paper, 0.0, 1e-3, &u, &[0.0; 3]).unwrap();
        assert_eq!(single.states[..], one.0[i * n * 3..(i + 1) * n * 3]);
        assert_eq!(single.states[..], two.0[i * n * 3..(i + 1) * n * 3]);
        assert_eq!(single.events, one.2[i].0);
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

/// The motor alone (a gap far wider than its travel) with Coulomb friction `fc`.
fn free_motor(f_m: f64, fc: f64, fs: f64) -> ChainParams {
    let mut p = paper_drive(100.0);
    p.f[0] = f_m;
    p.fc = vec![fc, 0.0];
    p.fs = vec![fs, 0.0];
    p
}

#[test]
fn coulomb_block_stops_at_closed_form_time_and_sticks() {
    // J w' = -fc: the speed reaches 0 at J w0 / fc and stays there exactly.
    let (jm, fc, w0) = (4.88e-3, 0.02, 3.1);
    let p = free_motor(0.0, fc, fc);
    let out = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &[0.0; 1000], &[w0, 0.0, 0.0]).unwrap();
    assert_eq!(out.events.len(), 1, "{:?}", out.events);
    let e = out.events[0];
    // friction switch of inertia 0 is reported as N - 1 + 0 = 1
    assert_eq!((e.index, e.from, e.to), (1, 1, 0));
    assert!((e.time - jm * w0 / fc).abs() < 1e-12, "{e:?}");
    let last = &out.states[out.states.len() - 3..];
    assert_eq!(last[0], 0.0);
    // modes: shaft, then the sticky inertia (the load has no friction switch)
    assert_eq!(p.n_switches(), 2);
    assert_eq!(&out.modes[out.modes.len() - 2..], &[0, 0]);
}

#[test]
fn breakaway_on_the_held_input() {
    // Stuck at rest; the staircase u_k = 0.003 k first exceeds fs = 0.05 at k = 17.
    let p = free_motor(0.5e-2, 0.03, 0.05);
    let u: Vec<f64> = (0..40).map(|k| 0.003 * k as f64).collect();
    let out = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &u, &[0.0; 3]).unwrap();
    assert_eq!(out.events.len(), 1, "{:?}", out.events);
    let e = out.events[0];
    assert_eq!((e.from, e.to), (0, 1));
    assert!((e.time - 0.017).abs() < 1e-15, "{e:?}");
}

#[test]
fn current_loop_lags_the_set_point() {
    // Free motor without friction, T(0) = 0: T = u (1 - exp(-t / tau)).
    let mut p = paper_drive(100.0);
    p.tau_i = 2e-3;
    let u = vec![0.3; 50];
    let out = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &u, &[0.0; 4]).unwrap();
    for k in 0..50 {
        let t = k as f64 * 1e-3;
        let torque = out.states[4 * k + 3];
        assert!(
            (torque - 0.3 * (1.0 - (-t / 2e-3).exp())).abs() < 1e-15,
            "{k}"
        );
    }
}

#[test]
fn modelica_reports_flanks_only() {
    // Modelica's example (J = 5 on a fixed flange, c = 20e3, d = 50, b/2 = pi/8): the
    // doubled-spring sub-modes (+-2) are internal; modes and events show +-1 only.
    let p = ChainParams::new(
        vec![5.0, 1e12],
        vec![0.0, 0.0],
        vec![20e3],
        vec![50.0],
        vec![std::f64::consts::FRAC_PI_8],
    );
    let x0 = [0.0, 0.0, std::f64::consts::FRAC_PI_2];
    let out = simulate_chain(&p, Law::Modelica, 0.0, 5e-4, &[0.0; 2001], &x0).unwrap();
    assert!(out.modes.iter().all(|m| m.abs() <= 1));
    assert!(out.events.len() > 10);
    for e in &out.events {
        assert!(e.from == 0 || e.to == 0, "{e:?}");
    }
}

#[test]
fn friction_and_loop_parameters_are_checked() {
    let mut p = paper_drive(0.01);
    p.fc = vec![0.02, 0.0];
    p.fs = vec![0.01, 0.0];
    let err = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &[0.0; 10], &[0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("fs[0] must be >= fc[0]"), "{err}");
    let mut p = paper_drive(0.01);
    p.tau_i = f64::NAN;
    let err = simulate_chain(&p, Law::Paper, 0.0, 1e-3, &[0.0; 10], &[0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("tau_i must be finite"), "{err}");
}

/// The paper drive's variants: as is, with Coulomb friction and breakaway, with a
/// current loop.
fn settling_drives() -> Vec<ChainParams> {
    let mut coulomb = paper_drive(3.49e-2);
    (coulomb.fc, coulomb.fs) = (vec![0.01, 0.02], vec![0.012, 0.025]);
    let mut current_loop = paper_drive(3.49e-2);
    current_loop.tau_i = 1e-3;
    vec![
        paper_drive(3.49e-2),
        paper_drive(0.0),
        coulomb,
        current_loop,
    ]
}

/// States, modes and events of `p` under `u` cut into runs of `piece` samples, each
/// started from the last state of the one before.
fn in_pieces(p: &ChainParams, ts: f64, u: &[f64], piece: usize) -> (Vec<f64>, Vec<i8>, Vec<Event>) {
    let s = p.n_states();
    let (mut states, mut modes, mut events) = (vec![0.0; s], vec![], vec![]);
    let mut k = 0;
    while k + 1 < u.len() {
        let end = (k + piece).min(u.len() - 1);
        let last = states[states.len() - s..].to_vec();
        let part = simulate_chain(p, Law::Paper, k as f64 * ts, ts, &u[k..=end], &last).unwrap();
        if modes.is_empty() {
            modes.extend_from_slice(&part.modes[..p.n_switches()]);
        }
        states.extend_from_slice(&part.states[s..]);
        modes.extend_from_slice(&part.modes[p.n_switches()..]);
        events.extend(part.events);
        k = end;
    }
    (states, modes, events)
}

#[test]
fn settling_through_a_hold_changes_no_bit() {
    // Paper A's 80 s step-down record in one run (which settles in the first hold),
    // and cut into pieces too short to settle: the same states and modes to the bit,
    // and the same events. At 1 ms the drive takes one internal step a sample (more
    // with the current loop), at 20 ms several.
    for (ts, piece) in [(1e-3, 1000), (0.02, 100)] {
        let u = paper_input(ts);
        for p in settling_drives() {
            let x0 = vec![0.0; p.n_states()];
            let whole = simulate_chain(&p, Law::Paper, 0.0, ts, &u, &x0).unwrap();
            let (states, modes, events) = in_pieces(&p, ts, &u, piece);
            assert!(whole.states == states, "states differ at {ts} s: {p:?}");
            assert!(whole.modes == modes, "modes differ at {ts} s: {p:?}");
            // Event times are summed from each piece's own start: the same to rounding.
            assert_eq!(whole.events.len(), events.len());
            for (a, b) in whole.events.iter().zip(&events) {
                assert_eq!((a.index, a.from, a.to), (b.index, b.from, b.to));
                assert!((a.time - b.time).abs() < 1e-12, "{a:?} {b:?}");
            }
        }
    }
}

#[test]
fn rattling_input_changes_no_bit_in_pieces() {
    // Paper A's record with a torque that changes every sample in its first and last
    // 10 s (the drive rattles in its backlash there) and is held between: in one run,
    // and cut into pieces of 7 samples and of 1000. The fast path checks the guards
    // over blocks of internal steps (several a sample with a current loop), so the
    // pieces align the blocks otherwise: the same states and modes to the bit.
    // Left out: Coulomb friction without a loop, whose stick-slip chatter under this
    // input a piece's start, classified from the state alone, can enter otherwise (its
    // changes differ in number in pieces of 7, before the blocks as after).
    let ts = 1e-3;
    let u: Vec<f64> = paper_input(ts)
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let t = i as f64 * ts;
            let wobble = ((i * 2_654_435_761) % 1000) as f64 / 1000.0 - 0.5;
            if !(10.0..70.0).contains(&t) {
                v + 0.04 * wobble
            } else {
                v
            }
        })
        .collect();
    let mut fast_loop = paper_drive(3.49e-2);
    fast_loop.tau_i = 2.5e-4;
    let [plain, free, coulomb, current_loop] = settling_drives().try_into().unwrap();
    let mut both = coulomb;
    both.tau_i = 1e-3;
    for p in [plain, free, current_loop, fast_loop, both] {
        let x0 = vec![0.0; p.n_states()];
        let whole = simulate_chain(&p, Law::Paper, 0.0, ts, &u, &x0).unwrap();
        assert!(whole.events.len() > 200, "too few changes to test: {p:?}");
        for piece in [7, 1000] {
            let (states, modes, events) = in_pieces(&p, ts, &u, piece);
            assert!(
                whole.states == states,
                "states differ in pieces of {piece}: {p:?}"
            );
            assert!(
                whole.modes == modes,
                "modes differ in pieces of {piece}: {p:?}"
            );
            assert_eq!(whole.events.len(), events.len());
        }
    }
}

#[test]
fn a_hold_settles_once_its_contact_changes_are_over() {
    // The torque held from rest: the engine stops checking guards within the first
    // 10 of the 40 s, and never where the input keeps changing or the run is short.
    let ts = 1e-3;
    let model = ChainModel::<3>::new(paper_drive(3.49e-2), Law::Paper, ts).unwrap();
    let mut engine = Engine::<3, 4, _>::new(&model, ts).unwrap();
    let held = vec![0.157; 40_001];
    engine.run(0.0, &held, &[0.0; 3]).unwrap();
    assert!(
        engine.settled_samples() > 30_000,
        "{}",
        engine.settled_samples()
    );
    // Paper A's record: the hold settles, the held zero torque ends on a flank
    engine.run(0.0, &paper_input(ts), &[0.0; 3]).unwrap();
    assert!((30_000..40_000).contains(&engine.settled_samples()));
    let wavy: Vec<f64> = (0..40_001)
        .map(|i| 0.157 + 0.01 * (i as f64 * 1e-3).sin())
        .collect();
    engine.run(0.0, &wavy, &[0.0; 3]).unwrap();
    assert_eq!(engine.settled_samples(), 0);
    engine.run(0.0, &held[..3000], &[0.0; 3]).unwrap();
    assert_eq!(engine.settled_samples(), 0);
}
