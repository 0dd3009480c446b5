//! Bindings of the forward sensitivities of the two-mass drive.

use backlashkit_core::sensitivity::{self, N_PARAMS, N_STATES};
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Sensitivities `dx/dp` of a two-mass drive, shape `(len(u), 3, 7)`: state
/// `[w_M, w_L, phi]` by parameter `[J_M, J_L, k_sh, f_M, f_L, f_sh, theta]`, on the grid
/// `t0 + i ts` under the held torque `u`, from `x0` with zero sensitivity (paper A's
/// law, no Coulomb friction, no current loop). See `backlashkit._sensitivity`.
#[pyfunction]
fn drive_sensitivities<'py>(
    py: Python<'py>,
    params: PyReadonlyArray1<'py, f64>,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let params = params.as_slice()?;
    let p: [f64; N_PARAMS] = params.try_into().map_err(|_| {
        PyValueError::new_err(format!(
            "params must have {N_PARAMS} entries, got {}",
            params.len()
        ))
    })?;
    let (u, x0) = (u.as_slice()?, x0.as_slice()?);
    let out = py
        .detach(|| sensitivity::drive_sensitivities(&p, t0, ts, u, x0))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(Array3::from_shape_vec((u.len(), N_STATES, N_PARAMS), out)
        .map_err(|e| PyValueError::new_err(e.to_string()))?
        .into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(drive_sensitivities, m)?)?;
    Ok(())
}
