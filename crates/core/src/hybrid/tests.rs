//! Tests of the event engine on small models with closed-form answers.

use super::*;
use crate::linalg::{Mat, Vector};
use crate::Error;

/// A one-switch model of state `[x, v]` with `dx/dt = v`: `v` obeys
/// `dv/dt = -omega^2 x + b u` (`omega = 0` for free flight). Mode 0 leaves when
/// `x - level` becomes positive (to mode 1), mode 1 when `level - x` does (to 0); the
/// dynamics are the same in both, so events only mark the crossings.
struct Crossings {
    omega: f64,
    level: f64,
    scale: f64,
}

impl HybridModel<2> for Crossings {
    fn n_switches(&self) -> usize {
        1
    }
    fn dynamics(&self, _modes: &[i8]) -> (Mat<2>, Vector<2>, Vector<2>) {
        let w2 = self.omega * self.omega;
        ([[0.0, 1.0], [-w2, 0.0]], [0.0, 1.0], [0.0; 2])
    }
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<2>> {
        let sign = if modes[0] == 0 { 1.0 } else { -1.0 };
        vec![GuardSpec {
            funcs: vec![GuardFn {
                h: [sign, 0.0],
                hu: 0.0,
                d: -sign * self.level,
                scale: self.scale,
            }],
            index: 0,
            target: 1 - modes[0],
        }]
    }
    fn classify(&self, x: &Vector<2>, _u: f64) -> Vec<i8> {
        vec![(x[0] > self.level) as i8]
    }
    fn extreme_modes(&self) -> Vec<Vec<i8>> {
        vec![vec![0]]
    }
}

/// A state bouncing at unit speed inside `[-a, a]`: mode 0 moves up (`dx/dt = 1`) until
/// `x > a`, mode 1 moves down until `x < -a`. `A = 0`, so the whole sample is one step.
struct Bouncer {
    a: f64,
}

impl HybridModel<1> for Bouncer {
    fn n_switches(&self) -> usize {
        1
    }
    fn dynamics(&self, modes: &[i8]) -> (Mat<1>, Vector<1>, Vector<1>) {
        ([[0.0]], [0.0], [if modes[0] == 0 { 1.0 } else { -1.0 }])
    }
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<1>> {
        let sign = if modes[0] == 0 { 1.0 } else { -1.0 };
        vec![GuardSpec {
            funcs: vec![GuardFn {
                h: [sign],
                hu: 0.0,
                d: -self.a,
                scale: self.a,
            }],
            index: 0,
            target: 1 - modes[0],
        }]
    }
    fn classify(&self, _x: &Vector<1>, _u: f64) -> Vec<i8> {
        vec![0]
    }
    fn extreme_modes(&self) -> Vec<Vec<i8>> {
        vec![vec![0]]
    }
}

#[test]
fn free_flight_crossing_matches_closed_form() {
    // From rest under constant u: x = u t^2 / 2 reaches `level` at sqrt(2 level / u).
    let model = Crossings {
        omega: 0.0,
        level: 0.3,
        scale: 0.3,
    };
    let (u, ts) = (2.5, 1e-3);
    let out = Engine::<2, 4, _>::new(&model, ts)
        .unwrap()
        .run(0.0, &vec![u; 1000], &[0.0, 0.0])
        .unwrap();
    assert_eq!(out.events.len(), 1, "{:?}", out.events);
    let exact = (2.0 * 0.3 / u).sqrt();
    assert!(
        (out.events[0].time - exact).abs() < 1e-15,
        "{:?} vs {exact}",
        out.events[0]
    );
    // The state on the grid is the exact flow: x(t) = u t^2 / 2 at t = 0.999 s.
    let t_end = 999.0 * ts;
    assert!((out.states[2 * 999] - u * t_end * t_end / 2.0).abs() < 1e-13);
}

#[test]
fn oscillator_crossings_match_closed_form() {
    // x = cos(omega t): it falls below `level` at acos(level) / omega and rises above it
    // again at (2 pi - acos(level)) / omega; substeps are used (rho h = 0.8 > 1/2).
    let (omega, level) = (8.0, 0.3);
    let model = Crossings {
        omega,
        level,
        scale: 1.0,
    };
    let ts = 0.1;
    let out = Engine::<2, 4, _>::new(&model, ts)
        .unwrap()
        .run(0.0, &[0.0; 20], &[1.0, 0.0])
        .unwrap();
    let first = level.acos() / omega;
    let period = 2.0 * std::f64::consts::PI / omega;
    // Five crossings before the end of the run at 1.9 s.
    let expected = [
        first,
        period - first,
        period + first,
        2.0 * period - first,
        2.0 * period + first,
    ];
    let times: Vec<f64> = out.events.iter().map(|e| e.time).collect();
    assert_eq!(times.len(), expected.len(), "{times:?}");
    for (t, e) in times.iter().zip(expected) {
        assert!((t - e).abs() < 1e-14, "{t} vs {e}");
    }
    assert_eq!((out.events[0].from, out.events[0].to), (1, 0));
}

#[test]
fn near_miss_is_a_graze_not_an_event() {
    // x = sin(t) peaks at 1 at t = pi/2: a level 1e-8 above the peak is missed (a graze
    // of margin -1e-8 relative to the scale 1), one 1e-8 below is crossed twice, at
    // asin(level) and pi - asin(level), and reported as barely crossed.
    let ts = 0.1;
    let run = |level: f64| {
        let model = Crossings {
            omega: 1.0,
            level,
            scale: 1.0,
        };
        Engine::<2, 4, _>::new(&model, ts)
            .unwrap()
            .run(0.0, &[0.0; 30], &[0.0, 1.0])
            .unwrap()
    };
    let missed = run(1.0 + 1e-8);
    assert!(missed.events.is_empty(), "{:?}", missed.events);
    assert_eq!(missed.grazes.len(), 1, "{:?}", missed.grazes);
    let g = missed.grazes[0];
    assert!((g.margin + 1e-8).abs() < 1e-12, "{g:?}");
    assert!((g.time - std::f64::consts::FRAC_PI_2).abs() < 1e-6, "{g:?}");

    let level: f64 = 1.0 - 1e-8;
    let crossed = run(level);
    let times: Vec<f64> = crossed.events.iter().map(|e| e.time).collect();
    let expected = [level.asin(), std::f64::consts::PI - level.asin()];
    assert_eq!(times.len(), 2, "{times:?}");
    // Near the peak the crossing time is ill-conditioned (dt = dx / v, v ~ 1.4e-4): a
    // rounding of the state of 1e-16 moves it by ~1e-12 s.
    for (t, e) in times.iter().zip(expected) {
        assert!((t - e).abs() < 1e-10, "{t} vs {e}");
    }
    assert!(!crossed.grazes.is_empty() && crossed.grazes[0].margin > 0.0);
}

#[test]
fn several_switches_inside_one_sample() {
    // Bouncing in [-a, a] at unit speed from 0: switches at a, 3a, 5a, ... (period 4a).
    // With a = 1e-4 and a 1 ms sample, five switches fall inside each sample.
    let a = 1e-4;
    let model = Bouncer { a };
    let ts = 1e-3;
    let out = Engine::<1, 4, _>::new(&model, ts)
        .unwrap()
        .run(0.0, &[0.0; 4], &[0.0])
        .unwrap();
    assert_eq!(out.events.len(), 15, "{:?}", out.events);
    for (k, e) in out.events.iter().enumerate() {
        let exact = a * (2 * k + 1) as f64;
        assert!((e.time - exact).abs() < 1e-17, "{k}: {} vs {exact}", e.time);
        assert_eq!(e.to, ((k + 1) % 2) as i8);
    }
    // Every 1 ms = 10 a the state is back at 0, moving down after an odd number of
    // switches (mode 1), up after an even number.
    assert!(
        out.states.iter().all(|x| x.abs() < 1e-16),
        "{:?}",
        out.states
    );
    assert_eq!(out.modes, vec![0, 1, 0, 1]);
}

#[test]
fn too_many_switches_in_one_step_is_zeno() {
    let model = Bouncer { a: 1e-7 };
    let err = Engine::<1, 4, _>::new(&model, 1e-3)
        .unwrap()
        .run(0.0, &[0.0; 2], &[0.0])
        .unwrap_err();
    assert!(matches!(err, Error::Zeno { .. }), "{err}");
}

/// `dx/dt = 0` and a guard `u - 1 > 0` on the held input alone (mode 0 to 1).
struct InputGuard;

impl HybridModel<1> for InputGuard {
    fn n_switches(&self) -> usize {
        1
    }
    fn dynamics(&self, _modes: &[i8]) -> (Mat<1>, Vector<1>, Vector<1>) {
        ([[0.0]], [0.0], [0.0])
    }
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<1>> {
        if modes[0] == 1 {
            return Vec::new();
        }
        vec![GuardSpec {
            funcs: vec![GuardFn {
                h: [0.0],
                hu: 1.0,
                d: -1.0,
                scale: 1.0,
            }],
            index: 0,
            target: 1,
        }]
    }
    fn classify(&self, _x: &Vector<1>, u: f64) -> Vec<i8> {
        vec![(u > 1.0) as i8]
    }
    fn extreme_modes(&self) -> Vec<Vec<i8>> {
        vec![vec![0]]
    }
}

#[test]
fn a_guard_on_the_held_input_fires_at_the_sample_start() {
    // The input steps above 1 at sample 37 of a staircase: the event is at 37 ts exactly.
    let ts = 1e-3;
    let u: Vec<f64> = (0..100).map(|k| 0.03 * k as f64).collect();
    let out = Engine::<1, 4, _>::new(&InputGuard, ts)
        .unwrap()
        .run(0.0, &u, &[0.0])
        .unwrap();
    assert_eq!(out.events.len(), 1, "{:?}", out.events);
    let first = u.iter().position(|&v| v > 1.0).unwrap();
    assert_eq!(first, 34);
    assert!(
        (out.events[0].time - first as f64 * ts).abs() < 1e-15,
        "{:?}",
        out.events
    );
}

/// `dx/dt = -x / tau + u / tau`: first-order approach to the held input; mode 0 leaves
/// when `x - level` becomes positive.
struct Approach {
    tau: f64,
    level: f64,
}

impl HybridModel<1> for Approach {
    fn n_switches(&self) -> usize {
        1
    }
    fn dynamics(&self, _modes: &[i8]) -> (Mat<1>, Vector<1>, Vector<1>) {
        ([[-1.0 / self.tau]], [1.0 / self.tau], [0.0])
    }
    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<1>> {
        if modes[0] == 1 {
            return Vec::new();
        }
        vec![GuardSpec {
            funcs: vec![GuardFn {
                h: [1.0],
                hu: 0.0,
                d: -self.level,
                scale: self.level,
            }],
            index: 0,
            target: 1,
        }]
    }
    fn classify(&self, x: &Vector<1>, _u: f64) -> Vec<i8> {
        vec![(x[0] > self.level) as i8]
    }
    fn extreme_modes(&self) -> Vec<Vec<i8>> {
        vec![vec![0]]
    }
}

#[test]
fn settling_waits_for_a_late_crossing() {
    // From 0 towards 2 with tau = 100 s, the level 1.5 is crossed at 100 ln 4 s, late in
    // a 200 s hold: the engine must not settle before it (the equilibrium lies beyond
    // the level), and settles after it (no guard left). Towards 1 the level is never
    // reached: it settles once twice the distance to the equilibrium (the bound and its
    // safety factor) clears the level, `x > 0.751` at `t = 139 s`, within a try (512
    // samples) of it.
    let model = Approach {
        tau: 100.0,
        level: 1.5,
    };
    let ts = 0.01;
    let mut engine = Engine::<1, 4, _>::new(&model, ts).unwrap();
    let out = engine.run(0.0, &[2.0; 20_001], &[0.0]).unwrap();
    assert_eq!(out.events.len(), 1);
    let exact = 100.0 * 4f64.ln();
    assert!(
        (out.events[0].time - exact).abs() < 1e-9,
        "{:?}",
        out.events
    );
    let after = 20_000 - (exact / ts).ceil() as usize;
    assert!(
        engine.settled_samples() > after - 600,
        "{}",
        engine.settled_samples()
    );
    assert!(engine.settled_samples() <= after);
    let towards_one = engine.run(0.0, &[1.0; 20_001], &[0.0]).unwrap();
    let clear = 20_000 - (-100.0 * (0.249f64).ln() / ts) as usize;
    assert!((clear - 512..=clear).contains(&engine.settled_samples()));
    let end = towards_one.states[20_000];
    assert!((end - (1.0 - (-2.0f64).exp())).abs() < 1e-12, "{end}");
    let last = out.states[20_000];
    assert!(
        (last - (2.0 - 2.0 * (-200.0f64 / 100.0).exp())).abs() < 1e-12,
        "{last}"
    );
}
