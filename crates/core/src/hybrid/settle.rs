//! Settling: the rest of a held input without a guard check, once the run provably
//! stays in its mode.
//!
//! In a mode `dx/dt = A x + b u + c` under a held input `u`, a Hurwitz `A` has the
//! equilibrium `x_eq = -A^-1 (b u + c)`, and with the eigenvectors `r_j` of `A` and the
//! rows `l_j` of their inverse,
//!
//! `x(t) = x_eq + sum_j r_j (l_j . v) exp(lambda_j t)`,  `v = x(0) - x_eq`.
//!
//! A guard function `g = h.x + hu u + d` therefore stays within
//! `g(x_eq) +- sum_j |h . r_j| |l_j . v|` for all `t >= 0` (every `|exp(lambda_j t)| <= 1`).
//! Where every guard of the mode has a function kept below `-MARGIN` by that bound, no
//! guard can fire until the input changes, and the engine runs the mode's flow alone,
//! the same arithmetic as its checked path (so the same states to the bit). On a long
//! hold (paper A's records hold a torque for 40 s) this skips checking thousands of
//! steps once the start's contact changes are over.
//!
//! The modal form is computed once per mode, the bound at each try in `O(S^2)`.

use nalgebra::linalg::Schur;
use nalgebra::{Complex, DMatrix};

use super::mode::ModeData;
use crate::linalg::{matvec, Mat, Vector};

/// Guard functions (normalised by their scales) must stay this far below their
/// boundary for the rest of the hold: a thousand times the grazing tolerance, so the
/// engine would not even report a near-graze there.
const MARGIN: f64 = 1e-3;
/// Factor on the modal bound: it covers the rounding of the eigenvectors and their
/// inverse (refused beyond [`MAX_CONDITION`]), which perturbs the bound by far less.
const SAFETY: f64 = 2.0;
/// Eigenvector bases worse conditioned than this (a mode close to defective) give no
/// certificate: their rounding could exceed the safety factor.
const MAX_CONDITION: f64 = 1e8;

/// Iterations of the Schur decomposition before a mode is given up on (no certificate):
/// a handful per eigenvalue converge on the small matrices here.
const MAX_SCHUR_ITERATIONS: usize = 1000;

/// The modal form of a Hurwitz mode: what the bound needs.
#[derive(Clone, Debug)]
pub(super) struct Modal<const S: usize> {
    /// `-A^-1`.
    neg_inv: Mat<S>,
    /// Rows `l_j` of the inverse eigenvector matrix.
    l: Vec<Vec<Complex<f64>>>,
    /// Per guard function (the mode's order): `|h . r_j|` for every `j`.
    hr: Vec<Vec<f64>>,
}

impl<const S: usize> Modal<S> {
    /// The modal form of `md`, or `None` where `A` is not Hurwitz (an integrator, a
    /// stuck inertia) or its eigenvectors are too close to dependent.
    pub(super) fn new<const W: usize>(md: &ModeData<S, W>) -> Option<Self> {
        if !md.a.iter().flatten().all(|v| v.is_finite()) {
            return None;
        }
        let a = DMatrix::from_fn(S, S, |i, j| md.a[i][j]);
        let lambdas =
            Schur::try_new(a.clone(), f64::EPSILON, MAX_SCHUR_ITERATIONS)?.complex_eigenvalues();
        if !lambdas.iter().all(|l| l.re < 0.0 && l.re.is_finite()) {
            return None;
        }
        let inv = a.clone().try_inverse()?;
        let ac = a.map(|v| Complex::new(v, 0.0));
        let mut r = DMatrix::<Complex<f64>>::zeros(S, S);
        for (j, &lambda) in lambdas.iter().enumerate() {
            r.set_column(j, &null_vector(&ac, lambda)?);
        }
        let l = r.clone().try_inverse()?;
        if r.norm() * l.norm() > MAX_CONDITION {
            return None;
        }
        let hr = md
            .funcs
            .iter()
            .map(|f| {
                (0..S)
                    .map(|j| {
                        (0..S)
                            .map(|i| r[(i, j)] * f.h[i])
                            .sum::<Complex<f64>>()
                            .norm()
                    })
                    .collect()
            })
            .collect();
        Some(Modal {
            neg_inv: std::array::from_fn(|i| std::array::from_fn(|j| -inv[(i, j)])),
            l: (0..S).map(|j| l.row(j).iter().copied().collect()).collect(),
            hr,
        })
    }

    /// Whether no guard of `md` can fire from `x` while the input is held at `u`.
    pub(super) fn stays<const W: usize>(&self, md: &ModeData<S, W>, x: &Vector<S>, u: f64) -> bool {
        let forced: Vector<S> = std::array::from_fn(|i| md.b[i] * u + md.c[i]);
        let x_eq = matvec(&self.neg_inv, &forced);
        let v: Vector<S> = std::array::from_fn(|i| x[i] - x_eq[i]);
        let amp: Vec<f64> = self
            .l
            .iter()
            .map(|row| {
                row.iter()
                    .zip(&v)
                    .map(|(l, vi)| l * vi)
                    .sum::<Complex<f64>>()
                    .norm()
            })
            .collect();
        let stays_below = |fi: usize| {
            let f = &md.funcs[fi];
            let g_eq: f64 = f.h.iter().zip(&x_eq).map(|(h, x)| h * x).sum::<f64>() + f.hu * u + f.d;
            let spread: f64 = self.hr[fi].iter().zip(&amp).map(|(h, a)| h * a).sum();
            g_eq + SAFETY * spread < -MARGIN
        };
        md.guards.iter().all(|g| g.funcs.clone().any(stays_below))
    }
}

/// A unit vector spanning the null space of `a - lambda I` (the right singular vector
/// of its smallest singular value).
fn null_vector(
    a: &DMatrix<Complex<f64>>,
    lambda: Complex<f64>,
) -> Option<nalgebra::DVector<Complex<f64>>> {
    let n = a.nrows();
    let shifted = a - DMatrix::<Complex<f64>>::identity(n, n) * lambda;
    let svd = shifted.svd(false, true);
    let v_t = svd.v_t?;
    let k = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?
        .0;
    Some(v_t.row(k).adjoint())
}
