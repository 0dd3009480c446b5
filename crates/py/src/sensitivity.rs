//! Bindings of the forward sensitivities of the two-mass drive.

use backlashkit_core::hybrid::Event;
use backlashkit_core::sensitivity::{self, state_count, N_PARAMS};
use numpy::ndarray::{Array2, Array3};
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// The states `(n, s)`, the sensitivities `(n, s, m)` (`s` 3, or 4 behind a current
/// loop) and the near-grazing passes `(G, 3)`.
type SensitivityOutput<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// The states `(len(u), n)` and sensitivities `dx/dp` of a two-mass drive, shape
/// `(len(u), n, len(wanted))`: state `[w_M, w_L, phi]` (and `T`) by parameter, the
/// parameters `wanted` (indices into `[J_M, J_L, k_sh, f_M, f_L, f_sh, theta, fc_M,
/// fc_L, tau_i]`,
/// the values `params` in that order), on the grid `t0 + i ts` under the held torque
/// `u`, from `x0` with the sensitivity `s0` (`(n, len(wanted))`, default zero, `n` 3
/// or 4 behind a current loop; paper A's law, Coulomb friction with the breakaway
/// torques equal to it);
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
    let p = param_array(&params)?;
    let (u, x0) = (u.as_slice()?, x0.as_slice()?);
    let s0 = s0.as_ref().map(|s| s.as_slice()).transpose()?;
    let out = py
        .detach(|| sensitivity::drive_sensitivities_from(&p, t0, ts, u, x0, s0, &wanted))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let shape_err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    Ok((
        Array2::from_shape_vec((u.len(), state_count(&p)), out.states)
            .map_err(shape_err)?
            .into_pyarray(py),
        Array3::from_shape_vec((u.len(), state_count(&p), wanted.len()), out.values)
            .map_err(shape_err)?
            .into_pyarray(py),
        graze_rows(py, &out.grazes)?,
    ))
}

/// The states `(len(u), n)` of a two-mass drive and the sums `sum_k s_c s_c^T` of the
/// outer products of each speed's sensitivities `s_c` (motor, load), shape
/// `(2, len(wanted), len(wanted))`, arguments as `drive_sensitivities`; and the run's
/// near-grazing passes. The white-noise Fisher information without the sensitivities
/// written out.
#[pyfunction]
#[pyo3(signature = (params, t0, ts, u, x0, wanted, s0=None))]
#[allow(clippy::too_many_arguments)]
fn drive_information<'py>(
    py: Python<'py>,
    params: PyReadonlyArray1<'py, f64>,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
    wanted: Vec<usize>,
    s0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<SensitivityOutput<'py>> {
    let p = param_array(&params)?;
    let (u, x0) = (u.as_slice()?, x0.as_slice()?);
    let s0 = s0.as_ref().map(|s| s.as_slice()).transpose()?;
    let out = py
        .detach(|| sensitivity::drive_information(&p, t0, ts, u, x0, s0, &wanted))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    let shape_err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    let m = wanted.len();
    Ok((
        Array2::from_shape_vec((u.len(), state_count(&p)), out.states)
            .map_err(shape_err)?
            .into_pyarray(py),
        Array3::from_shape_vec((2, m, m), out.gram)
            .map_err(shape_err)?
            .into_pyarray(py),
        graze_rows(py, &out.grazes)?,
    ))
}

/// Near-grazing passes as rows `[time, shaft, margin]`.
fn graze_rows<'py>(
    py: Python<'py>,
    grazes: &[backlashkit_core::hybrid::Graze],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = grazes
        .iter()
        .flat_map(|g| [g.time, g.index as f64, g.margin])
        .collect();
    Ok(Array2::from_shape_vec((grazes.len(), 3), flat)
        .map_err(|e| PyValueError::new_err(e.to_string()))?
        .into_pyarray(py))
}

/// As `drive_sensitivities`, along the run the simulator has made of the same drive,
/// grid and torque (`simulate_chain_batch`'s row): its states `(len(u), n)` (with the
/// motor's angle last where the run tracked it: its sensitivity then comes last too),
/// its first sample's modes and its events `(E, 4)` = `[time, switch, from, to]`; the
/// run starts from its first state. The same values to the bit, without simulating
/// again.
/// Returns the sensitivities alone: in `out` where given (C-contiguous, of that shape;
/// a caller asking again and again for runs of one size keeps one array).
#[pyfunction]
#[pyo3(signature = (params, t0, ts, u, states, first_modes, events, wanted, s0=None, out=None))]
#[allow(clippy::too_many_arguments)]
fn drive_sensitivities_along<'py>(
    py: Python<'py>,
    params: PyReadonlyArray1<'py, f64>,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    states: PyReadonlyArray2<'py, f64>,
    first_modes: PyReadonlyArray1<'py, i8>,
    events: PyReadonlyArray2<'py, f64>,
    wanted: Vec<usize>,
    s0: Option<PyReadonlyArray2<'py, f64>>,
    out: Option<Bound<'py, PyArray3<f64>>>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let p = param_array(&params)?;
    let events = event_list(&events)?;
    let run = along(&p, &states, &first_modes, &events)?;
    let u = u.as_slice()?;
    let s0 = s0.as_ref().map(|s| s.as_slice()).transpose()?;
    if let Some(out) = out {
        let shape = [u.len(), run.state_count(&p), wanted.len()];
        if out.shape() != shape {
            return Err(PyValueError::new_err(format!(
                "out must have shape {shape:?}, got {:?}",
                out.shape()
            )));
        }
        {
            let mut view = out.try_readwrite().map_err(|e| {
                PyValueError::new_err(format!("out must be a writeable array: {e}"))
            })?;
            let slice = view.as_slice_mut()?;
            py.detach(|| {
                sensitivity::drive_sensitivities_along_into(&p, t0, ts, u, &run, s0, &wanted, slice)
            })
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        }
        return Ok(out);
    }
    let values = py
        .detach(|| sensitivity::drive_sensitivities_along(&p, t0, ts, u, &run, s0, &wanted))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(
        Array3::from_shape_vec((u.len(), run.state_count(&p), wanted.len()), values)
            .map_err(|e| PyValueError::new_err(e.to_string()))?
            .into_pyarray(py),
    )
}

/// The joint fit's Jacobian rows of the sensitivities along a run (as
/// `drive_sensitivities_along`'s), written into `out` `(2 len(selected), len(wanted))`
/// (C-contiguous, writeable): for each selected sample `k` (strictly increasing), the
/// motor speed's row `(dw_M(k)/dp * factor) / level[0]`, then in a second block the
/// load speed's, `/ level[1]`.
#[pyfunction]
#[pyo3(signature = (params, t0, ts, u, states, first_modes, events, wanted, selected, factor, level, out, s0=None))]
#[allow(clippy::too_many_arguments)]
fn drive_jacobian_rows_along<'py>(
    py: Python<'py>,
    params: PyReadonlyArray1<'py, f64>,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    states: PyReadonlyArray2<'py, f64>,
    first_modes: PyReadonlyArray1<'py, i8>,
    events: PyReadonlyArray2<'py, f64>,
    wanted: Vec<usize>,
    selected: PyReadonlyArray1<'py, i64>,
    factor: PyReadonlyArray1<'py, f64>,
    level: (f64, f64),
    out: Bound<'py, PyArray2<f64>>,
    s0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<()> {
    let p = param_array(&params)?;
    let events = event_list(&events)?;
    let run = along(&p, &states, &first_modes, &events)?;
    let selected = selected
        .as_slice()?
        .iter()
        .map(|&k| usize::try_from(k))
        .collect::<Result<Vec<usize>, _>>()
        .map_err(|_| PyValueError::new_err("selected samples must be >= 0"))?;
    let shape = [2 * selected.len(), wanted.len()];
    if out.shape() != shape {
        return Err(PyValueError::new_err(format!(
            "out must have shape {shape:?}, got {:?}",
            out.shape()
        )));
    }
    let weights = sensitivity::RowWeights {
        selected: &selected,
        factor: factor.as_slice()?,
        level: [level.0, level.1],
    };
    let (u, s0) = (
        u.as_slice()?,
        s0.as_ref().map(|s| s.as_slice()).transpose()?,
    );
    let mut view = out
        .try_readwrite()
        .map_err(|e| PyValueError::new_err(format!("out must be a writeable array: {e}")))?;
    let slice = view.as_slice_mut()?;
    py.detach(|| {
        sensitivity::drive_jacobian_rows_along(&p, t0, ts, u, &run, s0, &wanted, &weights, slice)
    })
    .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The sensitivities `(n, len(wanted))` at the last sample of a run, as the last row
/// of `drive_sensitivities_along`'s, without the others written out.
#[pyfunction]
#[pyo3(signature = (params, t0, ts, u, states, first_modes, events, wanted, s0=None))]
#[allow(clippy::too_many_arguments)]
fn drive_sensitivity_at_end_along<'py>(
    py: Python<'py>,
    params: PyReadonlyArray1<'py, f64>,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    states: PyReadonlyArray2<'py, f64>,
    first_modes: PyReadonlyArray1<'py, i8>,
    events: PyReadonlyArray2<'py, f64>,
    wanted: Vec<usize>,
    s0: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let p = param_array(&params)?;
    let events = event_list(&events)?;
    let run = along(&p, &states, &first_modes, &events)?;
    let (u, s0) = (
        u.as_slice()?,
        s0.as_ref().map(|s| s.as_slice()).transpose()?,
    );
    let m = wanted.len();
    let values = py
        .detach(|| sensitivity::drive_sensitivity_at_end_along(&p, t0, ts, u, &run, s0, &wanted))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(Array2::from_shape_vec((run.state_count(&p), m), values)
        .map_err(|e| PyValueError::new_err(e.to_string()))?
        .into_pyarray(py))
}

/// A run of the simulator as the kernel follows it: its states, first sample's modes
/// and changes; states with a column more than the drive of `params` has end with the
/// motor's angle (the simulator's `track_angle`).
fn along<'a>(
    params: &[f64; N_PARAMS],
    states: &'a PyReadonlyArray2<'_, f64>,
    first_modes: &'a PyReadonlyArray1<'_, i8>,
    events: &'a [Event],
) -> PyResult<sensitivity::Along<'a>> {
    Ok(sensitivity::Along {
        states: states.as_slice()?,
        first_modes: first_modes.as_slice()?,
        events,
        motor_angle: states.shape()[1] == state_count(params) + 1,
    })
}

fn param_array(params: &PyReadonlyArray1<'_, f64>) -> PyResult<[f64; N_PARAMS]> {
    let params = params.as_slice()?;
    params.try_into().map_err(|_| {
        PyValueError::new_err(format!(
            "params must have {N_PARAMS} entries, got {}",
            params.len()
        ))
    })
}

/// Events `(E, 4)` = `[time, switch, from, to]` as the simulator's bindings give them.
fn event_list(events: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<Event>> {
    let a = events.as_array();
    if a.ncols() != 4 && a.nrows() > 0 {
        return Err(PyValueError::new_err(format!(
            "events must have 4 columns [time, switch, from, to], got {}",
            a.ncols()
        )));
    }
    a.rows()
        .into_iter()
        .map(|r| {
            let whole = |v: f64| v.fract() == 0.0 && v.abs() < 128.0;
            if !(whole(r[1]) && r[1] >= 0.0 && whole(r[2]) && whole(r[3])) {
                return Err(PyValueError::new_err(format!(
                    "an event's switch and modes must be small whole numbers, got {r}"
                )));
            }
            Ok(Event {
                time: r[0],
                index: r[1] as usize,
                from: r[2] as i8,
                to: r[3] as i8,
            })
        })
        .collect()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(drive_sensitivities, m)?)?;
    m.add_function(wrap_pyfunction!(drive_sensitivities_along, m)?)?;
    m.add_function(wrap_pyfunction!(drive_information, m)?)?;
    m.add_function(wrap_pyfunction!(drive_jacobian_rows_along, m)?)?;
    m.add_function(wrap_pyfunction!(drive_sensitivity_at_end_along, m)?)?;
    Ok(())
}
