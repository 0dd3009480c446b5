//! A mode of the two-mass drive, `dx/dt = A x + b u + c`, and the derivatives of its
//! matrices with respect to each parameter, written out from the torque balances.

use super::index::{D, F_L, F_M, J_L, J_M, K, THETA};
use super::{N_PARAMS, N_STATES};
use crate::linalg::{matvec, Mat, Vector};

/// `dx/dt = a x + b u + c` (or the derivative of these with respect to a parameter).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct System {
    pub a: Mat<N_STATES>,
    pub b: Vector<N_STATES>,
    pub c: Vector<N_STATES>,
}

impl System {
    /// The vector field at `x` under torque `u`.
    pub fn field(&self, x: &Vector<N_STATES>, u: f64) -> Vector<N_STATES> {
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

/// Torque balances of the two inertias, `J_i dw_i/dt = r_i . x + beta_i u + gamma_i`,
/// or their derivative with respect to a parameter other than an inertia.
#[derive(Clone, Copy, Debug, Default)]
struct Balance {
    r: [Vector<N_STATES>; 2],
    beta: [f64; 2],
    gamma: [f64; 2],
}

/// The balances in mode `flank` (0 the gap, +-1 a flank): viscous friction, and in
/// contact the shaft torque `k (phi - flank theta) + d (w_M - w_L)`.
fn balance(p: &[f64; N_PARAMS], flank: i8) -> Balance {
    let (k, d, th) = (p[K], p[D], p[THETA]);
    let (on, s) = (flank.abs() as f64, flank as f64);
    Balance {
        r: [
            [-p[F_M] - on * d, on * d, -on * k],
            [on * d, -p[F_L] - on * d, on * k],
        ],
        beta: [1.0, 0.0],
        gamma: [s * k * th, -s * k * th],
    }
}

/// The derivative of the balances with respect to parameter `j`, not an inertia.
fn balance_derivative(p: &[f64; N_PARAMS], flank: i8, j: usize) -> Balance {
    let (on, s) = (flank.abs() as f64, flank as f64);
    let mut db = Balance::default();
    match j {
        K => {
            db.r = [[0.0, 0.0, -on], [0.0, 0.0, on]];
            db.gamma = [s * p[THETA], -s * p[THETA]];
        }
        F_M => db.r[0][0] = -1.0,
        F_L => db.r[1][1] = -1.0,
        D => db.r = [[-on, on, 0.0], [on, -on, 0.0]],
        THETA => db.gamma = [s * p[K], -s * p[K]],
        _ => unreachable!("inertias are handled by system_derivative"),
    }
    db
}

/// Rows `i` of the system from balance `i` divided by `inertia[i]`; the twist row
/// `dphi/dt = w_M - w_L` when `twist`.
fn from_balance(bal: &Balance, inertia: [f64; 2], twist: bool) -> System {
    let mut sys = System::default();
    for i in 0..2 {
        sys.a[i] = bal.r[i].map(|v| v / inertia[i]);
        sys.b[i] = bal.beta[i] / inertia[i];
        sys.c[i] = bal.gamma[i] / inertia[i];
    }
    if twist {
        sys.a[2] = [1.0, -1.0, 0.0];
    }
    sys
}

/// `(A, b, c)` of mode `flank`.
pub(super) fn system(p: &[f64; N_PARAMS], flank: i8) -> System {
    from_balance(&balance(p, flank), [p[J_M], p[J_L]], true)
}

/// The derivative of `(A, b, c)` of mode `flank` with respect to parameter `j`.
pub(super) fn system_derivative(p: &[f64; N_PARAMS], flank: i8, j: usize) -> System {
    match j {
        // d(row / J)/dJ = -row / J^2, on that inertia's row only.
        J_M | J_L => {
            let i = j - J_M;
            let mut bal = balance(p, flank);
            bal.r[1 - i] = [0.0; N_STATES];
            (bal.beta[1 - i], bal.gamma[1 - i]) = (0.0, 0.0);
            let sq = [p[J_M] * p[J_M], p[J_L] * p[J_L]];
            from_balance(&bal, sq, false).scaled(-1.0)
        }
        _ => from_balance(&balance_derivative(p, flank, j), [p[J_M], p[J_L]], false),
    }
}
