//! Bindings of the forward sensitivities of the two-mass drive.

use backlashkit_core::sensitivity::{self, N_PARAMS, N_STATES};
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The states `(n, 3)`, the sensitivities `(n, 3, m)` and the near-grazing passes
/// `(G, 3)`.
type SensitivityOutput<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// The states `(len(u), 3)` and sensitivities `dx/dp` of a two-mass drive, shape
/// `(len(u), 3, len(wanted))`: state `[w_M, w_L, phi]` by parameter, the parameters
/// `wanted` (indices into `[J_M, J_L, k_sh, f_M, f_L, f_sh, theta, fc_M, fc_L]`,
/// the values `params` in that order), on the grid `t0 + i ts` under the held torque
/// `u`, from `x0` with the sensitivity `s0` (`(3, len(wanted))`, default zero; paper
/// A's law, Coulomb friction with the breakaway torques equal to it, no current loop);
/// and the run's near-grazing passes
/// `(G, 3)` = `[time, shaft, margin]` as `simulate_chain` gives them. See
/// `backlashkit._sensitivity`.
#[pyfunction]
#[pyo3(signature = (params, t0, ts, u, x0, wanted, s0=None))]
#[allow(clippy::too_many_arguments)]
fn drive_sensitivities<'py>(
    py: Python<'py>,
    params: PyReadonlyArray1<'py, f64>,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
    wanted: Vec<usize>,
    s0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<SensitivityOutput<'py>> {
    let params = params.as_slice()?;
    let p: [f64; N_PARAMS] = params.try_into().map_err(|_| {
        PyValueError::new_err(format!(
            "params must have {N_PARAMS} entries, got {}",
            params.len()
        ))
    })?;
    let (u, x0) = (u.as_slice()?, x0.as_slice()?);
    let s0 = s0.as_ref().map(|s| s.as_slice()).transpose()?;
    let out = py
        .detach(|| sensitivity::drive_sensitivities_from(&p, t0, ts, u, x0, s0, &wanted))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let shape_err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    let grazes: Vec<f64> = out
        .grazes
        .iter()
        .flat_map(|g| [g.time, g.index as f64, g.margin])
        .collect();
    Ok((
        Array2::from_shape_vec((u.len(), N_STATES), out.states)
            .map_err(shape_err)?
            .into_pyarray(py),
        Array3::from_shape_vec((u.len(), N_STATES, wanted.len()), out.values)
            .map_err(shape_err)?
            .into_pyarray(py),
        Array2::from_shape_vec((out.grazes.len(), 3), grazes)
            .map_err(shape_err)?
            .into_pyarray(py),
    ))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(drive_sensitivities, m)?)?;
    Ok(())
}
