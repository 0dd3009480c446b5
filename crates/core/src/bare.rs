//! The latency bound of a sequential simulation: the bare per-sample recurrence
//! `x <- E x + fb u + fc` of a three-state system, with no event checks at all,
//! hand-written with the same arithmetic as the simulator's flow (`hybrid::flow`).
//! Benchmarks compare the simulator against it; it is not used to simulate.

/// Run `x <- E x + fb u_k + fc` over `u`, storing every state (row-major `n x 3`).
pub fn bare_recurrence3(
    e: &[[f64; 3]; 3],
    fb: &[f64; 3],
    fc: &[f64; 3],
    u: &[f64],
    x0: &[f64; 3],
) -> Vec<f64> {
    let n = u.len();
    let mut out = vec![0.0; 3 * n];
    if n == 0 {
        return out;
    }
    let mut x = *x0;
    out[..3].copy_from_slice(&x);
    for k in 0..n - 1 {
        let uk = u[k];
        x = [
            (e[0][0] * x[0] + e[0][2] * x[2]) + e[0][1] * x[1] + (fb[0] * uk + fc[0]),
            (e[1][0] * x[0] + e[1][2] * x[2]) + e[1][1] * x[1] + (fb[1] * uk + fc[1]),
            (e[2][0] * x[0] + e[2][2] * x[2]) + e[2][1] * x[1] + (fb[2] * uk + fc[2]),
        ];
        out[3 * (k + 1)..3 * (k + 2)].copy_from_slice(&x);
    }
    out
}
