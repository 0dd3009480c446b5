//! A mode of the two-mass drive, `dx/dt = A x + b u + c`, and the derivatives of its
//! matrices with respect to each parameter, written out from the torque balances.
//!
//! A mode is the shaft's contact and each inertia's friction switch: slipping forwards
//! or backwards (the Coulomb torque `-+fc_i` on it) or stuck (its speed row zero).
//!
//! The state has `N` entries: the drive's three; behind a current loop (`tau_i > 0`)
//! the motor torque `T`, `tau_i dT/dt = u - T`, which then drives the motor in place of
//! `u`; and last, where `N` has room for it beyond those, the motor's angle,
//! `dphi_M/dt = w_M`. The loop's and the angle's rows are the same in every mode (a
//! stuck motor's torque still follows its set-point, and its angle stays with its
//! speed at 0), and nothing in the drive depends on the angle.

use super::index::{D, FC_L, FC_M, F_L, F_M, J_L, J_M, K, TAU, THETA};
use super::{has_loop, state_count, N_PARAMS, N_STATES};
use crate::linalg::{matvec, Mat, Vector};

/// `dx/dt = a x + b u + c` (or the derivative of these with respect to a parameter).
#[derive(Clone, Copy, Debug)]
pub(super) struct System<const N: usize> {
    pub a: Mat<N>,
    pub b: Vector<N>,
    pub c: Vector<N>,
}

impl<const N: usize> Default for System<N> {
    fn default() -> Self {
        System {
            a: [[0.0; N]; N],
            b: [0.0; N],
            c: [0.0; N],
        }
    }
}

impl<const N: usize> System<N> {
    /// The vector field at `x` under torque `u`.
    pub fn field(&self, x: &Vector<N>, u: f64) -> Vector<N> {
        let ax = matvec(&self.a, x);
        std::array::from_fn(|i| ax[i] + self.b[i] * u + self.c[i])
    }

    /// Every coefficient times `f`.
    pub fn scaled(mut self, f: f64) -> Self {
        self.a.iter_mut().flatten().for_each(|v| *v *= f);
        self.b.iter_mut().for_each(|v| *v *= f);
        self.c.iter_mut().for_each(|v| *v *= f);
        self
    }
}

/// The shaft's contact (0 the gap, +-1 a flank) and each inertia's friction switch
/// (+-1 slipping forwards / backwards, 0 stuck); an inertia without Coulomb friction
/// counts as slipping (its Coulomb torque is 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Mode {
    pub flank: i8,
    pub slip: [i8; 2],
}

impl Mode {
    /// Contact `flank`, both inertias slipping forwards.
    pub fn contact(flank: i8) -> Self {
        Mode {
            flank,
            slip: [1, 1],
        }
    }

    /// The mode's slot among the 27, for the cache of whole-sample flows.
    pub fn slot(&self) -> usize {
        let code = |m: i8| (m + 1) as usize;
        (code(self.flank) * 3 + code(self.slip[0])) * 3 + code(self.slip[1])
    }
}

/// Number of modes: three contacts times three switches of each inertia.
pub(super) const N_MODES: usize = 27;

/// Torque balances of the two inertias, `J_i dw_i/dt = r_i . x + beta_i u + gamma_i`,
/// or their derivative with respect to a parameter other than an inertia.
#[derive(Clone, Copy, Debug)]
pub(super) struct Balance<const N: usize> {
    pub r: [Vector<N>; 2],
    pub beta: [f64; 2],
    pub gamma: [f64; 2],
}

impl<const N: usize> Default for Balance<N> {
    fn default() -> Self {
        Balance {
            r: [[0.0; N]; 2],
            beta: [0.0; 2],
            gamma: [0.0; 2],
        }
    }
}

impl<const N: usize> Balance<N> {
    /// Balance `i` at `x` under torque `u`.
    pub fn torque(&self, i: usize, x: &Vector<N>, u: f64) -> f64 {
        let rx: f64 = (0..N).map(|q| self.r[i][q] * x[q]).sum();
        rx + self.beta[i] * u + self.gamma[i]
    }
}

/// The balances of `mode` with its Coulomb torques, `-slip_i fc_i` on each inertia.
fn balance_with_friction<const N: usize>(p: &[f64; N_PARAMS], mode: Mode) -> Balance<N> {
    let mut bal = balance(p, mode.flank);
    for (i, fc) in [p[FC_M], p[FC_L]].into_iter().enumerate() {
        bal.gamma[i] -= mode.slip[i] as f64 * fc;
    }
    bal
}

/// The derivative of the balances of `mode` with respect to `j`, not an inertia.
fn balance_with_friction_derivative<const N: usize>(
    p: &[f64; N_PARAMS],
    mode: Mode,
    j: usize,
) -> Balance<N> {
    let mut db = balance_derivative(p, mode.flank, j);
    if let Some(i) = [FC_M, FC_L].iter().position(|&f| f == j) {
        db.gamma[i] = -(mode.slip[i] as f64);
    }
    db
}

/// `sys` with the speed rows of the stuck inertias of `mode` zero.
fn stuck_rows_zero<const N: usize>(mut sys: System<N>, mode: Mode) -> System<N> {
    for i in (0..2).filter(|&i| mode.slip[i] == 0) {
        sys.a[i] = [0.0; N];
        (sys.b[i], sys.c[i]) = (0.0, 0.0);
    }
    sys
}

/// The balances in mode `flank` (0 the gap, +-1 a flank), Coulomb friction excluded:
/// viscous friction, and in contact the shaft torque `k (phi - flank theta) + d (w_M -
/// w_L)`. At a stuck inertia (zero speed) this is the torque its breakaway guard
/// compares with `fs = fc`. Behind a current loop the motor's torque is the state
/// `T`, not the input.
pub(super) fn balance<const N: usize>(p: &[f64; N_PARAMS], flank: i8) -> Balance<N> {
    let (k, d, th) = (p[K], p[D], p[THETA]);
    let (on, s) = (flank.abs() as f64, flank as f64);
    let mut bal = Balance {
        gamma: [s * k * th, -s * k * th],
        ..Balance::default()
    };
    bal.r[0][..N_STATES].copy_from_slice(&[-p[F_M] - on * d, on * d, -on * k]);
    bal.r[1][..N_STATES].copy_from_slice(&[on * d, -p[F_L] - on * d, on * k]);
    if has_loop(p) {
        bal.r[0][N_STATES] = 1.0;
    } else {
        bal.beta[0] = 1.0;
    }
    bal
}

/// The derivative of the balances (Coulomb friction excluded) with respect to
/// parameter `j`, not an inertia.
pub(super) fn balance_derivative<const N: usize>(
    p: &[f64; N_PARAMS],
    flank: i8,
    j: usize,
) -> Balance<N> {
    let (on, s) = (flank.abs() as f64, flank as f64);
    let mut db = Balance::default();
    match j {
        K => {
            (db.r[0][2], db.r[1][2]) = (-on, on);
            db.gamma = [s * p[THETA], -s * p[THETA]];
        }
        F_M => db.r[0][0] = -1.0,
        F_L => db.r[1][1] = -1.0,
        D => {
            db.r[0][..2].copy_from_slice(&[-on, on]);
            db.r[1][..2].copy_from_slice(&[on, -on]);
        }
        THETA => db.gamma = [s * p[K], -s * p[K]],
        FC_M | FC_L | TAU => {}
        _ => unreachable!("inertias are handled by system_derivative"),
    }
    db
}

/// Rows `i` of the system from balance `i` divided by `inertia[i]`; the twist row
/// `dphi/dt = w_M - w_L` when `twist`.
fn from_balance<const N: usize>(bal: &Balance<N>, inertia: [f64; 2], twist: bool) -> System<N> {
    let mut sys = System::default();
    for i in 0..2 {
        sys.a[i] = bal.r[i].map(|v| v / inertia[i]);
        sys.b[i] = bal.beta[i] / inertia[i];
        sys.c[i] = bal.gamma[i] / inertia[i];
    }
    if twist {
        (sys.a[2][0], sys.a[2][1]) = (1.0, -1.0);
    }
    sys
}

/// `(A, b, c)` of `mode`.
pub(super) fn system<const N: usize>(p: &[f64; N_PARAMS], mode: Mode) -> System<N> {
    let mut sys = from_balance(&balance_with_friction(p, mode), [p[J_M], p[J_L]], true);
    if has_loop(p) {
        // tau_i dT/dt = u - T
        (sys.a[N_STATES][N_STATES], sys.b[N_STATES]) = (-1.0 / p[TAU], 1.0 / p[TAU]);
    }
    if N > state_count(p) {
        sys.a[N - 1][0] = 1.0; // dphi_M/dt = w_M
    }
    stuck_rows_zero(sys, mode)
}

/// The derivative of `(A, b, c)` of `mode` with respect to parameter `j`.
pub(super) fn system_derivative<const N: usize>(
    p: &[f64; N_PARAMS],
    mode: Mode,
    j: usize,
) -> System<N> {
    let sys = match j {
        // d(row / J)/dJ = -row / J^2, on that inertia's row only.
        J_M | J_L => {
            let i = j - J_M;
            let mut bal = balance_with_friction(p, mode);
            bal.r[1 - i] = [0.0; N];
            (bal.beta[1 - i], bal.gamma[1 - i]) = (0.0, 0.0);
            let sq = [p[J_M] * p[J_M], p[J_L] * p[J_L]];
            from_balance(&bal, sq, false).scaled(-1.0)
        }
        // The loop's row alone: d(-1 / tau)/dtau = 1 / tau^2, and minus that for b.
        TAU => {
            let mut sys = System::default();
            if has_loop(p) {
                let inv2 = 1.0 / (p[TAU] * p[TAU]);
                (sys.a[N_STATES][N_STATES], sys.b[N_STATES]) = (inv2, -inv2);
            }
            sys
        }
        _ => from_balance(
            &balance_with_friction_derivative(p, mode, j),
            [p[J_M], p[J_L]],
            false,
        ),
    };
    stuck_rows_zero(sys, mode)
}
