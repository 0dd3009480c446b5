//! The backlash of Tao & Kokotović (1995), eq. (2.1), on sampled signals, and the
//! zero-order-hold state recurrence of a linear plant.
//!
//! * [`play_operator`] -- `u_k = min(max(u_{k-1}, m (v_k - c_r)), m (v_k - c_l))`,
//!   exact at the samples when `v` is monotone between samples (e.g. held).
//! * [`zoh_recurrence`] -- `x_{k+1} = A_d x_k + b_d u_k`, exact for a held `u`.

use crate::Error;

fn check_backlash(m: f64, c_r: f64, c_l: f64) -> Result<(), Error> {
    if !(m.is_finite() && m > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "m must be finite and > 0, got {m}"
        )));
    }
    if !(c_r.is_finite() && c_l.is_finite() && c_l < c_r) {
        return Err(Error::InvalidArgument(format!(
            "c_l must be < c_r (both finite), got c_l={c_l}, c_r={c_r}"
        )));
    }
    Ok(())
}

/// One step of the play operator: the output for input `v` given the previous output.
#[inline]
pub fn play_step(u_prev: f64, v: f64, m: f64, c_r: f64, c_l: f64) -> f64 {
    u_prev.max(m * (v - c_r)).min(m * (v - c_l))
}

/// Backlash (play operator) applied to the samples `v`, starting from output `u0`.
pub fn play_operator(v: &[f64], m: f64, c_r: f64, c_l: f64, u0: f64) -> Result<Vec<f64>, Error> {
    check_backlash(m, c_r, c_l)?;
    if !u0.is_finite() {
        return Err(Error::InvalidArgument(format!(
            "u0 must be finite, got {u0}"
        )));
    }
    let mut u = u0;
    Ok(v.iter()
        .map(|&vk| {
            u = play_step(u, vk, m, c_r, c_l);
            u
        })
        .collect())
}

/// States `x_0 .. x_{N-1}` (row-major, N x n) of `x_{k+1} = A_d x_k + b_d u_k`.
/// `ad` is n x n row-major.
pub fn zoh_recurrence(ad: &[f64], bd: &[f64], u: &[f64], x0: &[f64]) -> Result<Vec<f64>, Error> {
    let n = x0.len();
    if ad.len() != n * n || bd.len() != n {
        return Err(Error::InvalidArgument(format!(
            "A_d must be {n}x{n} and b_d of length {n} (the length of x0), got {} and {} entries",
            ad.len(),
            bd.len()
        )));
    }
    let mut out = Vec::with_capacity(u.len() * n);
    let mut x = x0.to_vec();
    let mut xn = vec![0.0; n];
    for &uk in u {
        out.extend_from_slice(&x);
        for i in 0..n {
            let row = &ad[i * n..(i + 1) * n];
            xn[i] = row.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>() + bd[i] * uk;
        }
        std::mem::swap(&mut x, &mut xn);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn play_follows_sides_and_holds_inside() {
        // up along m (v - c_r), then back down through the gap, then down along m (v - c_l)
        let v = [0.0, 2.0, 3.0, 2.5, 1.5, 0.0];
        let u = play_operator(&v, 0.7, 1.3, -0.5, 0.0).unwrap();
        let exp = [
            0.0,
            0.7 * (2.0 - 1.3),
            0.7 * (3.0 - 1.3),
            0.7 * 1.7,
            0.7 * 1.7,
            0.7 * 0.5,
        ];
        for (a, b) in u.iter().zip(exp) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn play_rejects_bad_parameters() {
        assert!(play_operator(&[0.0], 0.0, 1.0, -1.0, 0.0).is_err());
        assert!(play_operator(&[0.0], 1.0, -1.0, 1.0, 0.0).is_err());
    }

    #[test]
    fn zoh_scalar_integrator() {
        let x = zoh_recurrence(&[1.0], &[0.5], &[1.0, 1.0, 1.0], &[0.0]).unwrap();
        assert_eq!(x, vec![0.0, 0.5, 1.0]);
        assert!(zoh_recurrence(&[1.0, 0.0], &[0.5], &[1.0], &[0.0]).is_err());
    }
}
