//! The exponential of the block lower-triangular `M_j = [[A, 0], [D_j, A]]` over a
//! span, and its integral, for several couplings `D_j` at once: the flow of a state
//! and its sensitivities. Each power keeps the structure,
//! `M_j^k = [[A^k, 0], [C_jk, A^k]]`, so the diagonal blocks are shared and only the
//! coupling blocks are per `j`: a third of the work of exponentiating each `2 N x 2 N`
//! matrix in turn (the contact changes' split samples need a fresh flow each).
//!
//! Same method as [`crate::linalg::expm_and_integral`]: scaling by `2^-s` until the
//! 1-norm is at most 1/2, Taylor by Horner, then squaring.

use crate::linalg::{identity, matmul, norm1, Mat};

/// Taylor degree: at a 1-norm of 1/2 the remainder is below `0.5^17 / 17! < 1e-19`
/// relative, far under rounding.
const DEGREE: usize = 16;
/// Largest 1-norm of the scaled argument.
const MAX_NORM: f64 = 0.5;

/// `exp(M_j tau) = [[e, 0], [c_j, e]]` and `int_0^tau exp(M_j s) ds = [[f, 0], [k_j, f]]`.
#[derive(Clone, Debug)]
pub(super) struct CoupledExp<const N: usize, const P: usize> {
    pub e: Mat<N>,
    pub f: Mat<N>,
    pub c: [Mat<N>; P],
    pub k: [Mat<N>; P],
}

fn add<const N: usize>(a: &Mat<N>, b: &Mat<N>) -> Mat<N> {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] + b[i][j]))
}

fn scale<const N: usize>(a: &Mat<N>, s: f64) -> Mat<N> {
    a.map(|row| row.map(|v| v * s))
}

/// The exponentials of `M_j tau` for the couplings `d`, and their integrals; only for
/// the `active` couplings (the others' blocks stay 0: a column nobody asked for costs
/// nothing).
pub(super) fn coupled_expm<const N: usize, const P: usize>(
    a: &Mat<N>,
    d: &[Mat<N>; P],
    tau: f64,
    active: &[bool; P],
) -> CoupledExp<N, P> {
    // Each column of M_j sums at most a column of A and one of D_j.
    // Scaled by every coupling, carried or not: the carried blocks are then the same
    // to the bit whichever others are carried.
    let nrm = (norm1(a) + d.iter().map(norm1).fold(0.0, f64::max)) * tau.abs();
    let squarings = if nrm > MAX_NORM {
        (nrm / MAX_NORM).log2().ceil() as i32
    } else {
        0
    };
    let t = tau / 2f64.powi(squarings);
    let mut out = taylor(&scale(a, t), &d.map(|m| scale(&m, t)), t, active);
    for _ in 0..squarings {
        out = doubled(&out, active);
    }
    out
}

/// Horner for `E = sum (M t)^k / k!` and `G = sum (M t)^k / (k+1)!`, `F = t G`, by
/// blocks: `(M t) X = [[At X, 0], [Dt X + At X_c, At X]]` for `X = [[X, 0], [X_c, X]]`.
fn taylor<const N: usize, const P: usize>(
    at: &Mat<N>,
    dt: &[Mat<N>; P],
    t: f64,
    active: &[bool; P],
) -> CoupledExp<N, P> {
    let id = identity::<N>();
    let (mut e, mut g) = (id, id);
    let (mut ec, mut gc) = ([[[0.0; N]; N]; P], [[[0.0; N]; N]; P]);
    for k in (1..=DEGREE).rev() {
        let (ke, kg) = (1.0 / k as f64, 1.0 / (k + 1) as f64);
        for j in (0..P).filter(|&j| active[j]) {
            ec[j] = scale(&add(&matmul(&dt[j], &e), &matmul(at, &ec[j])), ke);
            gc[j] = scale(&add(&matmul(&dt[j], &g), &matmul(at, &gc[j])), kg);
        }
        e = add(&id, &scale(&matmul(at, &e), ke));
        g = add(&id, &scale(&matmul(at, &g), kg));
    }
    CoupledExp {
        e,
        f: scale(&g, t),
        c: ec,
        k: gc.map(|m| scale(&m, t)),
    }
}

/// The flow over twice the span: `E' = E E`, `C' = C E + E C`, `F' = F + E F`,
/// `K' = K + C F + E K`.
fn doubled<const N: usize, const P: usize>(
    x: &CoupledExp<N, P>,
    active: &[bool; P],
) -> CoupledExp<N, P> {
    let c = std::array::from_fn(|j| {
        if !active[j] {
            return x.c[j];
        }
        add(&matmul(&x.c[j], &x.e), &matmul(&x.e, &x.c[j]))
    });
    let k = std::array::from_fn(|j| {
        if !active[j] {
            return x.k[j];
        }
        let ck = add(&matmul(&x.c[j], &x.f), &matmul(&x.e, &x.k[j]));
        add(&x.k[j], &ck)
    });
    CoupledExp {
        e: matmul(&x.e, &x.e),
        f: add(&x.f, &matmul(&x.e, &x.f)),
        c,
        k,
    }
}
