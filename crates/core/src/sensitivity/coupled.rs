//! The exponential of the block lower-triangular `M_j = [[A, 0], [D_j, A]]` over a
//! span, and its integral, for several couplings `D_j` at once: the flow of a state
//! and its sensitivities. Each power keeps the structure,
//! `M_j^k = [[A^k, 0], [C_jk, A^k]]`, so the diagonal blocks are shared and only the
//! coupling blocks are per `j`: a third of the work of exponentiating each `2 N x 2 N`
//! matrix in turn (the contact changes' split samples need a fresh flow each).
//!
//! The drive's `A` is badly scaled in the state's units (`k / J_M`, some 1e4 1/s on
//! paper A's drive, beside rows of order 1), so its 1-norm is about a hundred times its
//! spectral radius; a diagonal similarity by powers of two (Parlett–Reinsch balancing,
//! exact in floating point) brings the norm down to the radius first, and a sample's
//! span then needs no squaring. Then, as [`crate::linalg::expm_and_integral`]: scaling
//! by `2^-s` until the 1-norm is at most 1/2, Taylor by Horner, then squaring; but the
//! series is that of the integral alone, whose degree follows from the norm, and the
//! exponential follows from it, `exp(X) = I + X G(X)`.

use crate::linalg::{identity, matmul, norm1, Mat};

/// Largest truncation error of the integral's series, relative: far under rounding.
const TOLERANCE: f64 = 1e-18;
/// Largest 1-norm of the scaled argument.
const MAX_NORM: f64 = 0.5;
/// Balancing's radix: a power of two, so that the similarity rounds nothing.
const RADIX: f64 = 2.0;
/// A balancing step is kept where it shrinks a row and column's norm below this
/// share of what they were (LAPACK's `gebal`).
const BALANCE_GAIN: f64 = 0.95;
/// Balancing sweeps at most: a bound on the loop, which stops once a sweep changes
/// nothing.
const BALANCE_SWEEPS: usize = 10;

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

/// `diag(d)^-1 a diag(d)` (`inverse`: `diag(d) a diag(d)^-1`).
fn similar<const N: usize>(a: &Mat<N>, d: &[f64; N], inverse: bool) -> Mat<N> {
    std::array::from_fn(|i| {
        std::array::from_fn(|k| {
            if inverse {
                a[i][k] * d[i] / d[k]
            } else {
                a[i][k] * d[k] / d[i]
            }
        })
    })
}

/// Powers of two `d` such that `diag(d)^-1 a diag(d)` has each row and column of
/// about equal off-diagonal norms (Parlett and Reinsch's balancing; a zero row or
/// column, such as a stuck inertia's, is left as it is).
fn balancing<const N: usize>(a: &Mat<N>) -> [f64; N] {
    let mut d = [1.0; N];
    let mut b = *a;
    for _ in 0..BALANCE_SWEEPS {
        let mut done = true;
        for i in 0..N {
            let c: f64 = (0..N).filter(|&k| k != i).map(|k| b[k][i].abs()).sum();
            let r: f64 = (0..N).filter(|&k| k != i).map(|k| b[i][k].abs()).sum();
            if c == 0.0 || r == 0.0 {
                continue;
            }
            // The power of two `f` nearest to balancing `c f` against `r / f`.
            let (mut f, mut cf2, total) = (1.0, c, c + r);
            while cf2 < r / RADIX {
                f *= RADIX;
                cf2 *= RADIX * RADIX;
            }
            while cf2 > r * RADIX {
                f /= RADIX;
                cf2 /= RADIX * RADIX;
            }
            if (cf2 + r) / f < BALANCE_GAIN * total {
                done = false;
                d[i] *= f;
                for k in 0..N {
                    b[k][i] *= f;
                    b[i][k] /= f;
                }
            }
        }
        if done {
            break;
        }
    }
    d
}

/// The smallest Taylor degree of the integral's series whose truncation,
/// `nu^(m+1) / (m+2)!` at a 1-norm `nu` of the argument, is under [`TOLERANCE`].
fn degree(nu: f64) -> usize {
    let (mut m, mut term) = (0, nu / 2.0);
    while term > TOLERANCE {
        m += 1;
        term *= nu / (m + 2) as f64;
    }
    m.max(1)
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
    // `M_j` balanced by `diag(s, s)`; its flow is the balanced one's, `diag(s, s)
    // X diag(s, s)^-1`, block by block.
    let s = balancing(a);
    let a = similar(a, &s, false);
    let d = d.map(|m| similar(&m, &s, false));
    // Each column of M_j sums at most a column of A and one of D_j.
    // Scaled by every coupling, carried or not: the carried blocks are then the same
    // to the bit whichever others are carried.
    let nrm = (norm1(&a) + d.iter().map(norm1).fold(0.0, f64::max)) * tau.abs();
    let squarings = if nrm > MAX_NORM {
        (nrm / MAX_NORM).log2().ceil() as i32
    } else {
        0
    };
    let t = tau / 2f64.powi(squarings);
    let nu = nrm / 2f64.powi(squarings);
    let mut out = taylor(
        &scale(&a, t),
        &d.map(|m| scale(&m, t)),
        t,
        degree(nu),
        active,
    );
    for _ in 0..squarings {
        out = doubled(&out, active);
    }
    let back = |m: &Mat<N>| similar(m, &s, true);
    CoupledExp {
        e: back(&out.e),
        f: back(&out.f),
        c: out.c.map(|m| back(&m)),
        k: out.k.map(|m| back(&m)),
    }
}

/// Horner for `G = sum_{k <= m} (M t)^k / (k+1)!` by blocks, `(M t) X = [[At X, 0],
/// [Dt X + At X_c, At X]]` for `X = [[X, 0], [X_c, X]]`; then `F = t G` and `E = I +
/// (M t) G`.
fn taylor<const N: usize, const P: usize>(
    at: &Mat<N>,
    dt: &[Mat<N>; P],
    t: f64,
    m: usize,
    active: &[bool; P],
) -> CoupledExp<N, P> {
    let id = identity::<N>();
    let mut g = id;
    let mut gc = [[[0.0; N]; N]; P];
    for k in (1..=m).rev() {
        let kg = 1.0 / (k + 1) as f64;
        for j in (0..P).filter(|&j| active[j]) {
            gc[j] = scale(&add(&matmul(&dt[j], &g), &matmul(at, &gc[j])), kg);
        }
        g = add(&id, &scale(&matmul(at, &g), kg));
    }
    let mut c = [[[0.0; N]; N]; P];
    for j in (0..P).filter(|&j| active[j]) {
        c[j] = add(&matmul(&dt[j], &g), &matmul(at, &gc[j]));
    }
    CoupledExp {
        e: add(&id, &matmul(at, &g)),
        f: scale(&g, t),
        c,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::spectral_radius_estimate;

    #[test]
    fn balancing_brings_the_norm_near_the_spectral_radius() {
        // Paper A's drive on a flank: `k / J_M` = 1.6e4 1/s beside rows of order 1, a
        // 1-norm over 100 times the spectral radius; balanced, within 1.2 times it.
        // The similarity is by powers of two, so it rounds nothing.
        let (jm, jl, k, fm, fl, d) = (0.00488, 0.068, 78.0, 0.005, 0.005, 0.01575);
        let a = [
            [-(fm + d) / jm, d / jm, -k / jm],
            [d / jl, -(fl + d) / jl, k / jl],
            [1.0, -1.0, 0.0],
        ];
        let radius = spectral_radius_estimate(&a);
        assert!(norm1(&a) > 100.0 * radius);
        let s = balancing(&a);
        assert!(s.iter().all(|v| v.log2().fract() == 0.0), "{s:?}");
        let b = similar(&a, &s, false);
        assert!(norm1(&b) < 1.2 * radius, "{} against {radius}", norm1(&b));
        assert!(similar(&b, &s, true) == a);
        // A stuck inertia's zero row is left alone.
        let stuck = [a[0], [0.0; 3], a[2]];
        let s = balancing(&stuck);
        assert!(similar(&similar(&stuck, &s, false), &s, true) == stuck);
    }

    #[test]
    fn the_degree_meets_the_tolerance_and_no_more() {
        for nu in [0.0, 1e-6, 0.1, 0.3, MAX_NORM] {
            let m = degree(nu);
            let tail = |m: usize| nu.powi(m as i32 + 1) / (1..=m + 2).product::<usize>() as f64;
            assert!(tail(m) <= TOLERANCE, "{nu}: {m}");
            assert!(m == 1 || tail(m - 1) > TOLERANCE, "{nu}: {m}");
        }
        assert_eq!(degree(MAX_NORM), 15);
    }
}
