//! Drive chains with backlash: `N` inertias joined by `N - 1` elastic shafts, each with
//! a dead zone of half-width `theta_j` (paper A, eq. 2, for `N = 2`), optionally with
//! Coulomb and static friction per inertia and a first-order current loop.
//!
//! State: `[w_1 .. w_N, phi_1 .. phi_{N-1}]`, `phi_j` the twist of shaft `j`, followed
//! by the motor torque when the chain has a current loop (`tau_i > 0`), then the
//! motor's absolute angle when it is tracked (`track_angle`). Mode of a
//! shaft: `0` in the gap, `+1` on the positive flank, `-1` on the negative flank
//! (Modelica's law also uses `+-2` internally, reported as `+-1`). Mode of an inertia
//! with breakaway friction (`fs > 0`): `+1` / `-1` slipping forwards / backwards, `0`
//! stuck.

mod friction;
mod model;
mod run;
#[cfg(test)]
mod tests;

pub use model::ChainModel;
pub use run::{
    simulate_chain, simulate_chain_batch_into, simulate_chain_into, ChainOutput, RunEvents,
};

use crate::Error;

/// Largest number of inertias handled (state dimension 15, 16 with a current loop).
pub const MAX_INERTIAS: usize = 8;
/// Twist scale (rad) used for tolerances when a shaft has no backlash (`theta = 0`).
pub const MIN_TWIST_SCALE: f64 = 1e-6;

/// Contact law of the shafts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    /// Paper A's law: torque `k (phi -+ theta) + d dphi/dt` whenever `|phi| >= theta`.
    Paper,
    /// The damper never pulls: contact holds while the spring-damper torque pushes,
    /// `max(tau_c + tau_d, 0)` (Modelica's `ElastoBacklash2`).
    NoPull,
    /// Modelica's `ElastoBacklash`: `tau_c + min(tau_c, tau_d)` on the positive flank,
    /// 0 when `tau_c + tau_d <= 0` (mirrored on the negative flank), with
    /// `tau_c = k (phi - theta)` and `tau_d = d dphi/dt`.
    Modelica,
}

impl Law {
    pub fn from_code(code: i64) -> Result<Self, Error> {
        match code {
            0 => Ok(Law::Paper),
            1 => Ok(Law::NoPull),
            2 => Ok(Law::Modelica),
            _ => Err(Error::InvalidArgument(format!(
                "law code must be 0 (paper), 1 (no-pull) or 2 (modelica), got {code}"
            ))),
        }
    }
}

/// Parameters of a chain (SI units).
#[derive(Clone, Debug, PartialEq, Default)]
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
    /// Coulomb friction torques, N m, >= 0 (empty: none).
    pub fc: Vec<f64>,
    /// Breakaway (static friction) torques, N m, >= fc (empty: equal to `fc`).
    pub fs: Vec<f64>,
    /// Time constant of the current loop, s, >= 0 (0: the torque is applied exactly).
    pub tau_i: f64,
    /// Whether the state carries the motor's absolute angle (rad), integrated exactly.
    pub track_angle: bool,
}

impl ChainParams {
    /// A chain with viscous friction only and an exact torque.
    pub fn new(j: Vec<f64>, f: Vec<f64>, k: Vec<f64>, d: Vec<f64>, theta: Vec<f64>) -> Self {
        ChainParams {
            j,
            f,
            k,
            d,
            theta,
            ..Default::default()
        }
    }

    /// Parameters from the packed layout `[J.., f.., k.., d.., theta..]` (`5 N - 3`
    /// values), optionally followed by `[fc.., fs.., tau_i]` (`7 N - 2` values).
    pub fn from_packed(n: usize, p: &[f64]) -> Result<Self, Error> {
        let (short, long) = (5 * n - 3, 7 * n - 2);
        if p.len() != short && p.len() != long {
            return Err(Error::InvalidArgument(format!(
                "packed parameters of a {n}-inertia chain need {short} or {long} values, got {}",
                p.len()
            )));
        }
        let (j, rest) = p.split_at(n);
        let (f, rest) = rest.split_at(n);
        let (k, rest) = rest.split_at(n - 1);
        let (d, rest) = rest.split_at(n - 1);
        let (theta, rest) = rest.split_at(n - 1);
        let mut params = ChainParams::new(
            j.to_vec(),
            f.to_vec(),
            k.to_vec(),
            d.to_vec(),
            theta.to_vec(),
        );
        if !rest.is_empty() {
            let (fc, rest) = rest.split_at(n);
            let (fs, rest) = rest.split_at(n);
            params.fc = fc.to_vec();
            params.fs = fs.to_vec();
            params.tau_i = rest[0];
        }
        params.validate()?;
        Ok(params)
    }

    pub fn n_inertias(&self) -> usize {
        self.j.len()
    }

    /// Coulomb friction of inertia `i` (0 when none is given).
    pub fn coulomb(&self, i: usize) -> f64 {
        self.fc.get(i).copied().unwrap_or(0.0)
    }

    /// Breakaway torque of inertia `i` (the Coulomb torque when none is given).
    pub fn breakaway(&self, i: usize) -> f64 {
        self.fs.get(i).copied().unwrap_or_else(|| self.coulomb(i))
    }

    /// Inertias with a friction switch (breakaway torque > 0), in order.
    pub fn sticky(&self) -> Vec<usize> {
        (0..self.n_inertias())
            .filter(|&i| self.breakaway(i) > 0.0)
            .collect()
    }

    /// Whether the motor torque goes through a current loop (one more state).
    pub fn has_current_loop(&self) -> bool {
        self.tau_i > 0.0
    }

    /// State dimension: `2 N - 1`, plus one with a current loop, plus one for the angle.
    pub fn n_states(&self) -> usize {
        2 * self.n_inertias() - 1 + self.has_current_loop() as usize + self.track_angle as usize
    }

    /// Index of the motor torque in the state (with a current loop).
    pub fn loop_state(&self) -> Option<usize> {
        self.has_current_loop().then_some(2 * self.n_inertias() - 1)
    }

    /// Index of the motor angle in the state (when tracked).
    pub fn angle_state(&self) -> Option<usize> {
        self.track_angle.then_some(self.n_states() - 1)
    }

    /// Mode columns of the kernel's output: one per shaft, one per sticky inertia.
    pub fn n_switches(&self) -> usize {
        self.n_inertias() - 1 + self.sticky().len()
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
        check("theta", &self.theta, n - 1, false)?;
        if !self.fc.is_empty() {
            check("fc", &self.fc, n, false)?;
        }
        if !self.fs.is_empty() {
            check("fs", &self.fs, n, false)?;
        }
        for i in 0..n {
            let (fc, fs) = (self.coulomb(i), self.breakaway(i));
            if fs < fc {
                return Err(Error::InvalidArgument(format!(
                    "fs[{i}] must be >= fc[{i}] = {fc} (the breakaway torque is at least the \
                     Coulomb torque), got {fs}"
                )));
            }
        }
        if !(self.tau_i.is_finite() && self.tau_i >= 0.0) {
            return Err(Error::InvalidArgument(format!(
                "tau_i must be finite and >= 0 (0: no current loop), got {}",
                self.tau_i
            )));
        }
        Ok(())
    }
}
