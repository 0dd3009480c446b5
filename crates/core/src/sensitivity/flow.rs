//! The exact flow of the state and its sensitivities over a span of held torque in one
//! mode.
//!
//! The sensitivities are carried scaled, `p_j dx/dp_j` (the derivative with respect to
//! `log p_j`), so that each coupling block `p_j dA/dp_j` is of the size of `A` itself:
//! unscaled, `dA/dJ_M ~ k / J_M^2` is 200 times `A` on paper A's drive and would set
//! the exponential's scaling and squaring by itself.

use super::coupled::coupled_expm;
use super::mode::{system, system_derivative, Mode, System};
use super::N_PARAMS;
use crate::linalg::{matvec, Mat, Vector};

/// State and sensitivities: `x`, and `s[j] = scale_j dx/dp_j`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Augmented<const N: usize> {
    pub x: Vector<N>,
    pub s: [Vector<N>; N_PARAMS],
}

/// The exact flow of a mode over a span `tau` of held torque `u`:
/// `x <- e x + xu u + x1`, `s_j <- e s_j + coupling_j x + su_j u + s1_j`.
#[derive(Clone, Debug)]
pub(super) struct Flow<const N: usize> {
    /// Whether column `j`'s coupling block is nonzero.
    coupled: [bool; N_PARAMS],
    pub(super) e: Mat<N>,
    xu: Vector<N>,
    x1: Vector<N>,
    pub(super) coupling: [Mat<N>; N_PARAMS],
    pub(super) su: [Vector<N>; N_PARAMS],
    pub(super) s1: [Vector<N>; N_PARAMS],
}

impl<const N: usize> Flow<N> {
    /// The flow of `mode` over `tau`, sensitivities scaled by `scale`: the
    /// exponential of `[[A, 0], [scale_j A_j, A]] tau` and its integral for every `j`
    /// (see `coupled`), applied to the inputs `[b, scale_j b_j]` and `[c, scale_j c_j]`.
    /// Only the `active` sensitivities are carried (the others stay 0).
    pub fn new(
        p: &[f64; N_PARAMS],
        scale: &[f64; N_PARAMS],
        mode: Mode,
        tau: f64,
        active: &[bool; N_PARAMS],
    ) -> Self {
        let sys = system::<N>(p, mode);
        let der: [System<N>; N_PARAMS] =
            std::array::from_fn(|j| system_derivative(p, mode, j).scaled(scale[j]));
        let ex = coupled_expm(&sys.a, &der.map(|d| d.a), tau, active);
        let (fb, fc) = (matvec(&ex.f, &sys.b), matvec(&ex.f, &sys.c));
        let input = |j: usize, v: &Vector<N>, dv: &Vector<N>| {
            let (kv, fdv) = (matvec(&ex.k[j], v), matvec(&ex.f, dv));
            std::array::from_fn(|i| kv[i] + fdv[i])
        };
        Flow {
            coupled: std::array::from_fn(|j| ex.c[j].iter().flatten().any(|&v| v != 0.0)),
            e: ex.e,
            xu: fb,
            x1: fc,
            su: std::array::from_fn(|j| input(j, &sys.b, &der[j].b)),
            s1: std::array::from_fn(|j| input(j, &sys.c, &der[j].c)),
            coupling: ex.c,
        }
    }

    /// Column `j`'s sensitivity `s` advanced in place by the flow under torque `u`
    /// from the state `x` at the span's start. A column whose coupling is zero
    /// (`theta`'s: `A` does not depend on it) skips that product.
    #[inline(always)]
    fn step_column(&self, j: usize, s: &mut Vector<N>, x: &Vector<N>, u: f64) {
        let es = matvec(&self.e, s);
        let cx = if self.coupled[j] {
            matvec(&self.coupling[j], x)
        } else {
            [0.0; N]
        };
        for i in 0..N {
            s[i] = es[i] + cx[i] + self.su[j][i] * u + self.s1[j][i];
        }
    }

    /// The state of `z` advanced in place by the flow under torque `u`.
    #[inline]
    fn apply_state(&self, z: &mut Augmented<N>, u: f64) {
        let ex = matvec(&self.e, &z.x);
        for i in 0..N {
            z.x[i] = ex[i] + self.xu[i] * u + self.x1[i];
        }
    }

    /// `z` advanced in place by the flow under torque `u`: the carried sensitivities
    /// `cols` first (they need the state at the span's start), then the state.
    #[inline]
    pub fn apply(&self, z: &mut Augmented<N>, u: f64, cols: &[usize]) {
        for &j in cols {
            self.step_column(j, &mut z.s[j], &z.x, u);
        }
        self.apply_state(z, u);
    }
}
