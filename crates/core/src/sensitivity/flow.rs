//! One mode of the two-mass drive with the derivatives of its matrices, and the exact
//! flow of the state and its sensitivities over a span of held torque.
//!
//! The sensitivities are carried scaled, `p_j dx/dp_j` (the derivative with respect to
//! `log p_j`), so that each coupling block `p_j dA/dp_j` is of the size of `A` itself:
//! unscaled, `dA/dJ_M ~ k / J_M^2` is 200 times `A` on paper A's drive and would set
//! the exponential's scaling and squaring by itself.

use super::coupled::coupled_expm;
use super::index::{D, F_L, F_M, J_L, J_M, K, THETA};
use super::{N_PARAMS, N_STATES};
use crate::linalg::{matvec, Mat, Vector};

/// State and sensitivities: `x`, and `s[j] = scale_j dx/dp_j`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Augmented {
    pub x: Vector<N_STATES>,
    pub s: [Vector<N_STATES>; N_PARAMS],
}

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

impl System {
    fn scaled(mut self, f: f64) -> Self {
        self.a.iter_mut().flatten().for_each(|v| *v *= f);
        self.b.iter_mut().for_each(|v| *v *= f);
        self.c.iter_mut().for_each(|v| *v *= f);
        self
    }
}

/// The exact flow of a mode over a span `tau` of held torque `u`:
/// `x <- e x + xu u + x1`, `s_j <- e s_j + coupling_j x + su_j u + s1_j`.
#[derive(Clone, Debug)]
pub(super) struct Flow {
    e: Mat<N_STATES>,
    xu: Vector<N_STATES>,
    x1: Vector<N_STATES>,
    coupling: [Mat<N_STATES>; N_PARAMS],
    su: [Vector<N_STATES>; N_PARAMS],
    s1: [Vector<N_STATES>; N_PARAMS],
}

impl Flow {
    /// The flow of mode `flank` over `tau`, sensitivities scaled by `scale`: the
    /// exponential of `[[A, 0], [scale_j A_j, A]] tau` and its integral for every `j`
    /// (see `coupled`), applied to the inputs `[b, scale_j b_j]` and `[c, scale_j c_j]`.
    pub fn new(p: &[f64; N_PARAMS], scale: &[f64; N_PARAMS], flank: i8, tau: f64) -> Self {
        let sys = system(p, flank);
        let der: [System; N_PARAMS] =
            std::array::from_fn(|j| system_derivative(p, flank, j).scaled(scale[j]));
        let ex = coupled_expm(&sys.a, &der.map(|d| d.a), tau);
        let (fb, fc) = (matvec(&ex.f, &sys.b), matvec(&ex.f, &sys.c));
        let input = |j: usize, v: &Vector<N_STATES>, dv: &Vector<N_STATES>| {
            let (kv, fdv) = (matvec(&ex.k[j], v), matvec(&ex.f, dv));
            std::array::from_fn(|i| kv[i] + fdv[i])
        };
        Flow {
            e: ex.e,
            xu: fb,
            x1: fc,
            su: std::array::from_fn(|j| input(j, &sys.b, &der[j].b)),
            s1: std::array::from_fn(|j| input(j, &sys.c, &der[j].c)),
            coupling: ex.c,
        }
    }

    /// `z` advanced by the flow under torque `u`.
    pub fn apply(&self, z: &Augmented, u: f64) -> Augmented {
        let ex = matvec(&self.e, &z.x);
        let x = std::array::from_fn(|i| ex[i] + self.xu[i] * u + self.x1[i]);
        let s = std::array::from_fn(|j| {
            let (es, cx) = (matvec(&self.e, &z.s[j]), matvec(&self.coupling[j], &z.x));
            std::array::from_fn(|i| es[i] + cx[i] + self.su[j][i] * u + self.s1[j][i])
        });
        Augmented { x, s }
    }
}
