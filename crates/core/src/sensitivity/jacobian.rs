//! The joint fit's Jacobian rows along a run, written by the walk itself.
//!
//! The fit's residual is `(y_c(k) - x_c(k)) / s_c` for the selected samples `k` of
//! each speed `c`, so its Jacobian in the estimated values `z` has the rows
//! `(S_c(k) * f) / s_c`, `f = -dp/dz` per column. Each sample's row of the walk goes to
//! [`JacobianRows`], which writes the selected samples' two rows where the Jacobian
//! keeps them: no array of `(samples, 3, m)` sensitivities to write and read again,
//! and the two products in the order the fit's NumPy arithmetic takes them (a
//! multiply, then a divide, no fused multiply-add), so the same values to the bit.

use super::lanes::{Row, Sink};
use super::run::{checked_along, walk, Along};
use super::{N_PARAMS, N_STATES};
use crate::Error;

/// Speeds with rows in the Jacobian: `w_M` then `w_L`, the rows 0 and 1 of a [`Row`].
const SPEEDS: usize = 2;

/// What makes Jacobian rows of the sensitivities: the samples selected, strictly
/// increasing; a factor per column (`-dp/dz`); and each speed's noise level, which
/// the product is divided by.
#[derive(Clone, Copy, Debug)]
pub struct RowWeights<'a> {
    /// The samples whose rows are written, strictly increasing.
    pub selected: &'a [usize],
    /// One multiplier per column (the fit's `-dp/dz`).
    pub factor: &'a [f64],
    /// The motor speed's and the load speed's noise levels, in rad/s.
    pub level: [f64; SPEEDS],
}

/// The Jacobian rows of a run's sensitivities, row-major `(2 n, m)` into `out`, for
/// `n = weights.selected.len()` and the `m` parameters `wanted`: the motor speed's
/// row of each selected sample `k`, `(dw_M(k)/dp * factor) / level[0]`, then the load
/// speed's. The run, `s0` and `wanted` as in
/// [`drive_sensitivities_along`](super::drive_sensitivities_along), whose values
/// these rows are made of.
///
/// Errors: as [`drive_sensitivities_along`](super::drive_sensitivities_along); samples
/// not strictly increasing or beyond the grid; factors not one finite value per
/// column; levels not finite and positive; `out` of another size.
#[allow(clippy::too_many_arguments)]
pub fn drive_jacobian_rows_along(
    p: &[f64; N_PARAMS],
    t0: f64,
    ts: f64,
    u: &[f64],
    run: &Along<'_>,
    s0: Option<&[f64]>,
    wanted: &[usize],
    weights: &RowWeights<'_>,
    out: &mut [f64],
) -> Result<(), Error> {
    let (active, sticky) = checked_along(p, t0, ts, u, run, s0, wanted)?;
    check_weights(weights, u.len(), wanted.len(), out.len())?;
    let Some(&last) = weights.selected.last() else {
        return Ok(());
    };
    let mut rows = JacobianRows {
        weights,
        out,
        m: wanted.len(),
        sample: 0,
        next: 0,
    };
    // The samples past the last selected one give no row: the walk stops there.
    walk(
        p,
        &sticky,
        t0,
        ts,
        &u[..=last],
        run,
        s0,
        wanted,
        active,
        &mut rows,
    )
}

fn check_weights(w: &RowWeights<'_>, n: usize, m: usize, out: usize) -> Result<(), Error> {
    let bad = |what: String| Err(Error::InvalidArgument(what));
    if !w.selected.windows(2).all(|k| k[0] < k[1]) || w.selected.last().is_some_and(|&k| k >= n) {
        return bad(format!(
            "the selected samples must increase strictly and lie below the grid's {n}"
        ));
    }
    if w.factor.len() != m || !w.factor.iter().all(|f| f.is_finite()) {
        return bad(format!(
            "the factors must be {m} finite values, one per column, got {:?}",
            w.factor
        ));
    }
    if !w.level.iter().all(|s| s.is_finite() && *s > 0.0) {
        return bad(format!(
            "the noise levels must be finite and > 0, got {:?}",
            w.level
        ));
    }
    if out != SPEEDS * w.selected.len() * m {
        return bad(format!(
            "the output must hold {SPEEDS} x {} x {m} values, got {out}",
            w.selected.len()
        ));
    }
    Ok(())
}

/// The selected samples' rows written into the Jacobian's block, in order.
struct JacobianRows<'a, 'b> {
    weights: &'b RowWeights<'b>,
    out: &'a mut [f64],
    m: usize,
    /// The sample the walk hands next, and the next selected one's place in
    /// `weights.selected`.
    sample: usize,
    next: usize,
}

impl<const N: usize> Sink<N> for JacobianRows<'_, '_> {
    #[inline(always)]
    fn take(&mut self, row: &Row<N>) {
        let w = self.weights;
        if w.selected.get(self.next) == Some(&self.sample) {
            let (m, n) = (self.m, w.selected.len());
            for (c, speed) in row[..SPEEDS].iter().enumerate() {
                let at = (c * n + self.next) * m;
                let dst = &mut self.out[at..at + m];
                for ((d, &s), &f) in dst.iter_mut().zip(speed).zip(w.factor) {
                    *d = s * f / w.level[c];
                }
            }
            self.next += 1;
        }
        self.sample += 1;
    }
}

// The speeds are the first rows of a `Row`.
const _: () = assert!(SPEEDS <= N_STATES);
