//! Fixed-size dense linear algebra for the small systems of the drive models:
//! matrix-vector products, the matrix exponential and its integral.

/// Row-major `S x S` matrix.
pub type Mat<const S: usize> = [[f64; S]; S];
/// Vector of length `S`.
pub type Vector<const S: usize> = [f64; S];

#[inline(always)]
pub fn matvec<const S: usize>(a: &Mat<S>, x: &Vector<S>) -> Vector<S> {
    let mut y = [0.0; S];
    for i in 0..S {
        let mut acc = 0.0;
        for j in 0..S {
            acc += a[i][j] * x[j];
        }
        y[i] = acc;
    }
    y
}

#[inline(always)]
pub fn dot<const S: usize>(a: &Vector<S>, b: &Vector<S>) -> f64 {
    let mut acc = 0.0;
    for i in 0..S {
        acc += a[i] * b[i];
    }
    acc
}

pub fn matmul<const S: usize>(a: &Mat<S>, b: &Mat<S>) -> Mat<S> {
    let mut c = [[0.0; S]; S];
    for i in 0..S {
        for k in 0..S {
            let aik = a[i][k];
            if aik == 0.0 {
                continue;
            }
            for j in 0..S {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

pub fn identity<const S: usize>() -> Mat<S> {
    let mut m = [[0.0; S]; S];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

/// Induced 1-norm (largest absolute column sum).
pub fn norm1<const S: usize>(a: &Mat<S>) -> f64 {
    (0..S)
        .map(|j| (0..S).map(|i| a[i][j].abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Row vector `h' A`.
pub fn vecmat<const S: usize>(h: &Vector<S>, a: &Mat<S>) -> Vector<S> {
    let mut r = [0.0; S];
    for i in 0..S {
        for j in 0..S {
            r[j] += h[i] * a[i][j];
        }
    }
    r
}

/// `(E, F) = (exp(A tau), integral_0^tau exp(A s) ds)`.
///
/// Scaling and squaring of a degree-20 Taylor series: the argument is scaled by
/// `2^-s` until its 1-norm is at most 1/2 (truncation error below 1e-25 relative),
/// then `E(2 t) = E(t)^2` and `F(2 t) = F(t) + E(t) F(t)`.
pub fn expm_and_integral<const S: usize>(a: &Mat<S>, tau: f64) -> (Mat<S>, Mat<S>) {
    const DEGREE: usize = 20;
    let nrm = norm1(a) * tau.abs();
    let squarings = if nrm > 0.5 {
        (nrm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let t = tau / 2f64.powi(squarings);
    let mut at = *a;
    for row in at.iter_mut() {
        for x in row.iter_mut() {
            *x *= t;
        }
    }
    // Horner for E = sum (At)^k/k! and G = sum (At)^k/(k+1)!, F = t G.
    let id = identity::<S>();
    let mut e = id;
    let mut g = id;
    for k in (1..=DEGREE).rev() {
        // e <- I + At e / k ; g <- I + At g / (k+1)
        let ae = matmul(&at, &e);
        let ag = matmul(&at, &g);
        for i in 0..S {
            for j in 0..S {
                e[i][j] = id[i][j] + ae[i][j] / k as f64;
                g[i][j] = id[i][j] + ag[i][j] / (k + 1) as f64;
            }
        }
    }
    let mut f = g;
    for row in f.iter_mut() {
        for x in row.iter_mut() {
            *x *= t;
        }
    }
    for _ in 0..squarings {
        let ef = matmul(&e, &f);
        for i in 0..S {
            for j in 0..S {
                f[i][j] += ef[i][j];
            }
        }
        e = matmul(&e, &e);
    }
    (e, f)
}

/// Estimate of the spectral radius by Gelfand's formula, `||A^128||^(1/128)`
/// (within a few percent of the true value for moderately non-normal matrices).
pub fn spectral_radius_estimate<const S: usize>(a: &Mat<S>) -> f64 {
    let mut b = *a;
    let mut log_scale = 0.0f64;
    const P: i32 = 7;
    for _ in 0..P {
        let n = norm1(&b);
        if n == 0.0 {
            return 0.0;
        }
        for row in b.iter_mut() {
            for x in row.iter_mut() {
                *x /= n;
            }
        }
        b = matmul(&b, &b);
        log_scale = 2.0 * (log_scale + n.ln());
    }
    let n = norm1(&b);
    if n == 0.0 {
        return 0.0;
    }
    ((log_scale + n.ln()) / 2f64.powi(P)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expm_of_rotation_generator() {
        // A = [[0, -w], [w, 0]] -> rotation by w tau.
        let w = 3.0;
        let a = [[0.0, -w], [w, 0.0]];
        let tau = 0.7;
        let (e, f) = expm_and_integral(&a, tau);
        let (c, s) = ((w * tau).cos(), (w * tau).sin());
        let want_e = [[c, -s], [s, c]];
        // integral of rotation: [[sin, cos-1], [1-cos, sin]] / w
        let want_f = [[s / w, (c - 1.0) / w], [(1.0 - c) / w, s / w]];
        for i in 0..2 {
            for j in 0..2 {
                assert!((e[i][j] - want_e[i][j]).abs() < 1e-14, "E[{i}][{j}]");
                assert!((f[i][j] - want_f[i][j]).abs() < 1e-14, "F[{i}][{j}]");
            }
        }
    }

    #[test]
    fn expm_of_stiff_diagonal_with_large_norm() {
        let a = [[-2000.0, 0.0, 0.0], [0.0, -0.5, 0.0], [0.0, 0.0, 0.0]];
        let tau = 1e-3;
        let (e, f) = expm_and_integral(&a, tau);
        for i in 0..3 {
            let l: f64 = a[i][i];
            let want_e = (l * tau).exp();
            let want_f = if l == 0.0 {
                tau
            } else {
                (l * tau).exp_m1() / l
            };
            assert!(
                (e[i][i] - want_e).abs() < 1e-14 * want_e.abs(),
                "E {i}: {} vs {want_e}",
                e[i][i]
            );
            assert!(
                (f[i][i] - want_f).abs() < 1e-14 * want_f.abs(),
                "F {i}: {} vs {want_f}",
                f[i][i]
            );
        }
        assert_eq!(e[0][1], 0.0);
    }

    #[test]
    fn spectral_radius_of_rotation_and_jordan_like() {
        let a = [[0.0, -131.0], [131.0, 0.0]];
        let r = spectral_radius_estimate(&a);
        assert!((r - 131.0).abs() < 1e-9 * 131.0);
        // non-normal: eigenvalues -1, -2 with a large coupling
        let b = [[-1.0, 1e4], [0.0, -2.0]];
        let r = spectral_radius_estimate(&b);
        assert!(r > 2.0 && r < 2.0 * 1.2, "{r}");
    }
}
