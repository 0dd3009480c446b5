//! The latency bound of a sequential simulation: the bare per-sample recurrence
//! `x <- E x + fb u + fc` of a three-state system, with no event checks at all.
//! Benchmarks compare the simulator against it; it is not used to simulate.

/// Run `x <- E x + fb u_k + fc` over `u`, storing every state (row-major `n x 3`).
pub fn bare_recurrence3(e: &[[f64; 3]; 3], fb: &[f64; 3], fc: &[f64; 3], u: &[f64], x0: &[f64; 3]) -> Vec<f64> {
    let mut out = Vec::with_capacity(3 * u.len());
    let mut x = *x0;
    if u.is_empty() {
        return out;
    }
    out.extend_from_slice(&x);
    for &uk in &u[..u.len() - 1] {
        x = [
            e[0][0] * x[0] + e[0][1] * x[1] + e[0][2] * x[2] + fb[0] * uk + fc[0],
            e[1][0] * x[0] + e[1][1] * x[1] + e[1][2] * x[2] + fb[1] * uk + fc[1],
            e[2][0] * x[0] + e[2][1] * x[1] + e[2][2] * x[2] + fb[2] * uk + fc[2],
        ];
        out.extend_from_slice(&x);
    }
    out
}
