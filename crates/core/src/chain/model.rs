//! The chain as a hybrid model: dynamics per mode, guards, initial classification.

use super::{ChainParams, Law, MIN_TWIST_SCALE};
use crate::hybrid::{GuardFn, GuardSpec, HybridModel};
use crate::linalg::{Mat, Vector};
use crate::Error;

/// The chain as a hybrid model with state dimension `S = 2 N - 1`, or `2 N` with a
/// current loop (the motor torque is then the last state).
pub struct ChainModel<const S: usize> {
    pub(super) p: ChainParams,
    pub(super) law: Law,
    /// Inertias with a friction switch; switch `N - 1 + r` belongs to `sticky[r]`.
    pub(super) sticky: Vec<usize>,
    /// Sample time (s): sets the speed scale of the friction guards.
    pub(super) ts: f64,
    /// Number of inertias.
    pub(super) n: usize,
}

impl<const S: usize> ChainModel<S> {
    pub fn new(p: ChainParams, law: Law, ts: f64) -> Result<Self, Error> {
        p.validate()?;
        if p.n_states() != S {
            return Err(Error::InvalidArgument(
                "state dimension does not match the chain".into(),
            ));
        }
        let (sticky, n) = (p.sticky(), p.n_inertias());
        Ok(ChainModel {
            p,
            law,
            sticky,
            ts,
            n,
        })
    }

    fn twist_scale(&self, j: usize) -> f64 {
        self.p.theta[j].max(MIN_TWIST_SCALE)
    }

    /// `phi_j - side * theta_j` (side = +1 / -1).
    fn twist_fn(&self, j: usize, side: f64) -> GuardFn<S> {
        let mut h = [0.0; S];
        h[self.n + j] = 1.0;
        GuardFn {
            h,
            hu: 0.0,
            d: -side * self.p.theta[j],
            scale: self.twist_scale(j),
        }
    }

    /// Spring-damper torque on flank `side`: `k (phi - side theta) + d (w_j - w_{j+1})`.
    fn torque_fn(&self, j: usize, side: f64) -> GuardFn<S> {
        let mut h = [0.0; S];
        h[self.n + j] = self.p.k[j];
        h[j] = self.p.d[j];
        h[j + 1] = -self.p.d[j];
        GuardFn {
            h,
            hu: 0.0,
            d: -side * self.p.k[j] * self.p.theta[j],
            scale: self.p.k[j] * self.twist_scale(j),
        }
    }

    /// Damper minus spring torque on flank `side`: `d (w_j - w_{j+1}) - k (phi - side theta)`
    /// (Modelica's law doubles the spring torque where this is positive on the
    /// positive flank, negative on the negative flank).
    fn damper_excess_fn(&self, j: usize, side: f64) -> GuardFn<S> {
        let mut h = [0.0; S];
        h[self.n + j] = -self.p.k[j];
        h[j] = self.p.d[j];
        h[j + 1] = -self.p.d[j];
        GuardFn {
            h,
            hu: 0.0,
            d: side * self.p.k[j] * self.p.theta[j],
            scale: self.p.k[j] * self.twist_scale(j),
        }
    }

    /// `(A, b, c)` of the contact modes `contact` with every inertia free: viscous
    /// friction included when `viscous`, no Coulomb friction.
    pub(super) fn free_dynamics(
        &self,
        contact: &[i8],
        viscous: bool,
    ) -> (Mat<S>, Vector<S>, Vector<S>) {
        let n = self.n;
        let p = &self.p;
        let mut a = [[0.0; S]; S];
        let mut b = [0.0; S];
        let mut c = [0.0; S];
        if viscous {
            for i in 0..n {
                a[i][i] = -p.f[i] / p.j[i];
            }
        }
        if let Some(q) = p.loop_state() {
            // tau_i dT/dt = u - T; the torque T acts on the motor.
            a[0][q] = 1.0 / p.j[0];
            a[q][q] = -1.0 / p.tau_i;
            b[q] = 1.0 / p.tau_i;
        } else {
            b[0] = 1.0 / p.j[0];
        }
        if let Some(q) = p.angle_state() {
            a[q][0] = 1.0;
        }
        for (jx, &m) in contact.iter().enumerate() {
            let q = n + jx;
            a[q][jx] = 1.0;
            a[q][jx + 1] = -1.0;
            if m == 0 {
                continue;
            }
            // Shaft torque T = k phi + d (w_j - w_{j+1}) - m k theta acts as -T on
            // inertia j and +T on inertia j+1; Modelica's doubled-spring modes (+-2)
            // carry 2 k (phi - theta sign(m)) and no damping.
            let side = m.signum() as f64;
            let (k, d) = if m.abs() == 2 {
                (2.0 * p.k[jx], 0.0)
            } else {
                (p.k[jx], p.d[jx])
            };
            let off = -side * k * p.theta[jx];
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

    /// Guards of shaft `j` in mode `m`.
    fn shaft_guards(&self, j: usize, m: i8, out: &mut Vec<GuardSpec<S>>) {
        let mut spec = |funcs: Vec<GuardFn<S>>, target: i8| {
            out.push(GuardSpec {
                funcs,
                index: j,
                target,
            })
        };
        match (self.law, m) {
            (Law::Paper, 0) => {
                spec(vec![self.twist_fn(j, 1.0)], 1);
                spec(vec![negate(self.twist_fn(j, -1.0))], -1);
            }
            (Law::Paper, 1) => spec(vec![negate(self.twist_fn(j, 1.0))], 0),
            (Law::Paper, _) => spec(vec![self.twist_fn(j, -1.0)], 0),
            // Both clamped laws close a flank when the spring-damper torque pushes; the
            // Modelica law then picks its sub-mode in `resolve`.
            (_, 0) => {
                spec(vec![self.twist_fn(j, 1.0), self.torque_fn(j, 1.0)], 1);
                spec(
                    vec![
                        negate(self.twist_fn(j, -1.0)),
                        negate(self.torque_fn(j, -1.0)),
                    ],
                    -1,
                );
            }
            (Law::NoPull, 1) => spec(vec![negate(self.torque_fn(j, 1.0))], 0),
            (Law::NoPull, _) => spec(vec![self.torque_fn(j, -1.0)], 0),
            (Law::Modelica, 1) => {
                spec(vec![negate(self.torque_fn(j, 1.0))], 0);
                spec(vec![self.damper_excess_fn(j, 1.0)], 2);
            }
            (Law::Modelica, 2) => spec(vec![negate(self.damper_excess_fn(j, 1.0))], 1),
            (Law::Modelica, -1) => {
                spec(vec![self.torque_fn(j, -1.0)], 0);
                spec(vec![negate(self.damper_excess_fn(j, -1.0))], -2);
            }
            (Law::Modelica, _) => spec(vec![self.damper_excess_fn(j, -1.0)], -1),
        }
    }

    /// Contact mode of shaft `j` at `x`.
    fn classify_shaft(&self, j: usize, x: &Vector<S>) -> i8 {
        let n = self.n;
        let phi = x[n + j];
        let th = self.p.theta[j];
        let spring_damper =
            |side: f64| self.p.k[j] * (phi - side * th) + self.p.d[j] * (x[j] - x[j + 1]);
        let pos = phi > th && (self.law == Law::Paper || spring_damper(1.0) > 0.0);
        let neg = phi < -th && (self.law == Law::Paper || spring_damper(-1.0) < 0.0);
        let side = if pos {
            1
        } else if neg {
            -1
        } else {
            0
        };
        self.modelica_sub_mode(j, side, x)
    }

    /// On a flank under Modelica's law: `+-2` where the damper torque exceeds the spring
    /// torque (the spring's torque is doubled), else `side` unchanged.
    fn modelica_sub_mode(&self, j: usize, side: i8, x: &Vector<S>) -> i8 {
        if self.law != Law::Modelica || side == 0 {
            return side;
        }
        let excess = self.damper_excess_fn(j, side as f64);
        let v = crate::linalg::dot(&excess.h, x) + excess.d;
        if (side > 0 && v > 0.0) || (side < 0 && v < 0.0) {
            2 * side
        } else {
            side
        }
    }
}

pub(super) fn negate<const S: usize>(mut g: GuardFn<S>) -> GuardFn<S> {
    g.h.iter_mut().for_each(|v| *v = -*v);
    g.hu = -g.hu;
    g.d = -g.d;
    g
}

impl<const S: usize> HybridModel<S> for ChainModel<S> {
    fn n_switches(&self) -> usize {
        self.n - 1 + self.sticky.len()
    }

    fn dynamics(&self, modes: &[i8]) -> (Mat<S>, Vector<S>, Vector<S>) {
        let (contact, friction) = modes.split_at(self.n - 1);
        let (mut a, mut b, mut c) = self.free_dynamics(contact, true);
        for (r, &m) in friction.iter().enumerate() {
            let i = self.sticky[r];
            if m == 0 {
                // Stuck: the speed stays at exactly 0.
                a[i] = [0.0; S];
                (b[i], c[i]) = (0.0, 0.0);
            } else {
                c[i] -= m as f64 * self.p.coulomb(i) / self.p.j[i];
            }
        }
        (a, b, c)
    }

    fn guards(&self, modes: &[i8]) -> Vec<GuardSpec<S>> {
        let (contact, friction) = modes.split_at(self.n - 1);
        let mut out = Vec::new();
        for (j, &m) in contact.iter().enumerate() {
            self.shaft_guards(j, m, &mut out);
        }
        for (r, &m) in friction.iter().enumerate() {
            self.friction_guards(r, m, contact, &mut out);
        }
        out
    }

    fn classify(&self, x: &Vector<S>, u: f64) -> Vec<i8> {
        let mut modes: Vec<i8> = (0..self.n - 1).map(|j| self.classify_shaft(j, x)).collect();
        for r in 0..self.sticky.len() {
            let m = self.classify_friction(r, &modes[..self.n - 1], x, u);
            modes.push(m);
        }
        modes
    }

    fn resolve(
        &self,
        index: usize,
        from: i8,
        target: i8,
        modes: &[i8],
        x: &mut Vector<S>,
        u: f64,
    ) -> i8 {
        if index >= self.n - 1 {
            return self.resolve_friction(index - (self.n - 1), target, modes, x, u);
        }
        // Closing a flank under Modelica's law: which of its two sub-modes. Between
        // sub-modes the guard that fired decides (re-evaluating it could disagree in
        // the last bit and chatter).
        if from == 0 {
            self.modelica_sub_mode(index, target, x)
        } else {
            target
        }
    }

    fn mode_codes(&self) -> usize {
        // Modelica's doubled-spring branches are the codes +-2.
        if self.law == Law::Modelica {
            5
        } else {
            3
        }
    }

    fn extreme_modes(&self) -> Vec<Vec<i8>> {
        let slipping = vec![1; self.sticky.len()];
        let mut out = vec![
            [vec![0; self.n - 1], slipping.clone()].concat(),
            [vec![1; self.n - 1], slipping.clone()].concat(),
        ];
        if self.law == Law::Modelica {
            out.push([vec![2; self.n - 1], slipping].concat());
        }
        out
    }
}
