//! Bindings of the drive-chain simulator.

use backlashkit_core::bare::bare_recurrence3;
use backlashkit_core::chain::{self, ChainOutput, ChainParams, Law};
use backlashkit_core::hybrid::{Event, Graze};
use backlashkit_core::linalg::expm_and_integral;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

fn value_error(e: backlashkit_core::Error) -> PyErr {
    PyValueError::new_err(e.to_string())
}

type RawOutput<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<i8>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// Convert a trajectory into numpy arrays: states (n, S), modes (n, M),
/// events (E, 4) = [time, shaft, from, to], grazes (G, 3) = [time, shaft, margin].
fn to_numpy<'py>(
    py: Python<'py>,
    out: ChainOutput,
    s: usize,
    m: usize,
) -> PyResult<RawOutput<'py>> {
    let n = out.states.len() / s;
    let shape_err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    let states = Array2::from_shape_vec((n, s), out.states).map_err(shape_err)?;
    let modes = Array2::from_shape_vec((n, m), out.modes).map_err(shape_err)?;
    let (events, grazes) = event_arrays(py, &out.events, &out.grazes)?;
    Ok((
        states.into_pyarray(py),
        modes.into_pyarray(py),
        events,
        grazes,
    ))
}

/// Simulate one chain; see `backlashkit.simulate.simulate_drive`. `fc` and `fs` are
/// the Coulomb and breakaway torques per inertia (empty: none), `tau_i` the current
/// loop's time constant (0: none). States have `2N - 1` columns, plus the motor torque
/// with a current loop, plus the motor angle with `track_angle`; modes one column per
/// shaft and per inertia with `fs > 0`.
#[pyfunction]
#[pyo3(signature = (j, f, k, d, theta, law, t0, ts, u, x0, fc=None, fs=None, tau_i=0.0, track_angle=false))]
#[allow(clippy::too_many_arguments)]
fn simulate_chain<'py>(
    py: Python<'py>,
    j: PyReadonlyArray1<'py, f64>,
    f: PyReadonlyArray1<'py, f64>,
    k: PyReadonlyArray1<'py, f64>,
    d: PyReadonlyArray1<'py, f64>,
    theta: PyReadonlyArray1<'py, f64>,
    law: i64,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
    fc: Option<PyReadonlyArray1<'py, f64>>,
    fs: Option<PyReadonlyArray1<'py, f64>>,
    tau_i: f64,
    track_angle: bool,
) -> PyResult<RawOutput<'py>> {
    let vec_of = |a: Option<PyReadonlyArray1<'py, f64>>| -> PyResult<Vec<f64>> {
        Ok(match a {
            Some(a) => a.as_slice()?.to_vec(),
            None => Vec::new(),
        })
    };
    let p = ChainParams {
        j: j.as_slice()?.to_vec(),
        f: f.as_slice()?.to_vec(),
        k: k.as_slice()?.to_vec(),
        d: d.as_slice()?.to_vec(),
        theta: theta.as_slice()?.to_vec(),
        fc: vec_of(fc)?,
        fs: vec_of(fs)?,
        tau_i,
        track_angle,
    };
    p.validate().map_err(value_error)?;
    let law = Law::from_code(law).map_err(value_error)?;
    let (u, x0) = (u.as_slice()?, x0.as_slice()?);
    let out = py
        .detach(|| chain::simulate_chain(&p, law, t0, ts, u, x0))
        .map_err(value_error)?;
    to_numpy(py, out, p.n_states(), p.n_switches())
}

/// A pair of 2-D float arrays (events and grazes; or E and F of the exponential).
type EventArrays<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>);

fn event_arrays<'py>(
    py: Python<'py>,
    events: &[Event],
    grazes: &[Graze],
) -> PyResult<EventArrays<'py>> {
    let shape_err = |e: numpy::ndarray::ShapeError| PyValueError::new_err(e.to_string());
    let ev: Vec<f64> = events
        .iter()
        .flat_map(|e| [e.time, e.index as f64, e.from as f64, e.to as f64])
        .collect();
    let gr: Vec<f64> = grazes
        .iter()
        .flat_map(|g| [g.time, g.index as f64, g.margin])
        .collect();
    Ok((
        Array2::from_shape_vec((events.len(), 4), ev)
            .map_err(shape_err)?
            .into_pyarray(py),
        Array2::from_shape_vec((grazes.len(), 3), gr)
            .map_err(shape_err)?
            .into_pyarray(py),
    ))
}

type BatchOutput<'py> = (
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<i8>>,
    Vec<EventArrays<'py>>,
);

/// Simulate many chains in parallel with the GIL released, into one states array
/// `(B, n, S)` and one modes array `(B, n, M)` (as for `simulate_chain`). `params` has
/// one packed row `[J.., f.., k.., d.., theta..]` per chain, optionally followed by
/// `[fc.., fs.., tau_i]`; `u` one row shared by all chains or one
/// row per chain; `x0` one row per chain (ending with the motor angle with
/// `track_angle`). Returns the two arrays and, per chain, its events `(E, 4)` and
/// grazes `(G, 3)`.
#[pyfunction]
#[pyo3(signature = (n_inertias, params, law, t0, ts, u, x0, workers, track_angle=false))]
#[allow(clippy::too_many_arguments)]
fn simulate_chain_batch<'py>(
    py: Python<'py>,
    n_inertias: usize,
    params: PyReadonlyArray2<'py, f64>,
    law: i64,
    t0: f64,
    ts: f64,
    u: PyReadonlyArray2<'py, f64>,
    x0: PyReadonlyArray2<'py, f64>,
    workers: usize,
    track_angle: bool,
) -> PyResult<BatchOutput<'py>> {
    let law = Law::from_code(law).map_err(value_error)?;
    let rows: Vec<ChainParams> = params
        .as_array()
        .rows()
        .into_iter()
        .map(|r| {
            ChainParams::from_packed(n_inertias, &r.to_vec()).map(|mut p| {
                p.track_angle = track_angle;
                p
            })
        })
        .collect::<Result<_, _>>()
        .map_err(value_error)?;
    let (b, n) = (rows.len(), u.as_array().ncols());
    let (s, m) = rows.first().map_or(
        (2 * n_inertias - 1 + track_angle as usize, n_inertias - 1),
        |p| (p.n_states(), p.n_switches()),
    );
    let states = PyArray3::<f64>::zeros(py, [b, n, s], false);
    let modes = PyArray3::<i8>::zeros(py, [b, n, m], false);
    let (u, x0) = (u.as_slice()?, x0.as_slice()?);
    // SAFETY: both arrays were created above and are not shared with Python code yet.
    let (st, md) = unsafe { (states.as_slice_mut()?, modes.as_slice_mut()?) };
    let runs = py
        .detach(|| chain::simulate_chain_batch_into(&rows, law, t0, ts, n, u, x0, st, md, workers))
        .map_err(value_error)?;
    let events = runs
        .iter()
        .map(|(e, g)| event_arrays(py, e, g))
        .collect::<PyResult<Vec<_>>>()?;
    Ok((states, modes, events))
}

fn mat3(a: &PyReadonlyArray2<'_, f64>) -> PyResult<[[f64; 3]; 3]> {
    let a = a.as_array();
    if a.shape() != [3, 3] {
        return Err(PyValueError::new_err(format!(
            "expected a 3x3 matrix, got shape {:?}",
            a.shape()
        )));
    }
    Ok(std::array::from_fn(|i| std::array::from_fn(|j| a[[i, j]])))
}

fn vec3(v: &PyReadonlyArray1<'_, f64>) -> PyResult<[f64; 3]> {
    v.as_slice()?
        .try_into()
        .map_err(|_| PyValueError::new_err("expected a vector of length 3"))
}

/// The bare recurrence `x <- E x + fb u + fc` (benchmark baseline).
#[pyfunction]
fn bare_recurrence<'py>(
    py: Python<'py>,
    e: PyReadonlyArray2<'py, f64>,
    fb: PyReadonlyArray1<'py, f64>,
    fc: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (e, fb, fc, x0) = (mat3(&e)?, vec3(&fb)?, vec3(&fc)?, vec3(&x0)?);
    let u = u.as_slice()?;
    let out = py.detach(|| bare_recurrence3(&e, &fb, &fc, u, &x0));
    let n = out.len() / 3;
    Ok(Array2::from_shape_vec((n, 3), out)
        .map_err(|e| PyValueError::new_err(e.to_string()))?
        .into_pyarray(py))
}

/// `(exp(A tau), int_0^tau exp(A s) ds)` for a 3x3 `A` (exposed for parity tests).
#[pyfunction]
fn expm_and_integral3<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    tau: f64,
) -> PyResult<EventArrays<'py>> {
    let (e, f) = expm_and_integral(&mat3(&a)?, tau);
    let conv = |m: [[f64; 3]; 3]| Array2::from_shape_fn((3, 3), |(i, j)| m[i][j]).into_pyarray(py);
    Ok((conv(e), conv(f)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate_chain, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_chain_batch, m)?)?;
    m.add_function(wrap_pyfunction!(bare_recurrence, m)?)?;
    m.add_function(wrap_pyfunction!(expm_and_integral3, m)?)?;
    Ok(())
}
