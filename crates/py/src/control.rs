//! Bindings of the backlash play operator, the ZOH recurrence and the adaptive
//! backlash-inverse closed loop (paper B). Conversion only; errors become `ValueError`.

use backlashkit_core::control::{self, AdaptiveProblem, InverseKind, Lti, Reference};
use backlashkit_core::play;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn value_error(e: backlashkit_core::Error) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Play operator (paper B, (2.1)) on samples; see `backlashkit.Backlash.apply`.
#[pyfunction]
fn play_operator<'py>(
    py: Python<'py>,
    v: PyReadonlyArray1<'py, f64>,
    m: f64,
    c_r: f64,
    c_l: f64,
    u0: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let v = v.as_slice()?;
    let out = py
        .detach(|| play::play_operator(v, m, c_r, c_l, u0))
        .map_err(value_error)?;
    Ok(out.into_pyarray(py))
}

/// States (N, n) of `x_{k+1} = A_d x_k + b_d u_k`.
#[pyfunction]
fn zoh_recurrence<'py>(
    py: Python<'py>,
    ad: PyReadonlyArray2<'py, f64>,
    bd: PyReadonlyArray1<'py, f64>,
    u: PyReadonlyArray1<'py, f64>,
    x0: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let ad_v: Vec<f64> = ad.as_array().iter().copied().collect();
    let (bd, u, x0) = (bd.as_slice()?, u.as_slice()?, x0.as_slice()?);
    let n = x0.len();
    let out = py
        .detach(|| play::zoh_recurrence(&ad_v, bd, u, x0))
        .map_err(value_error)?;
    let rows = u.len();
    Ok(Array2::from_shape_vec((rows, n), out)
        .map_err(|e| PyValueError::new_err(e.to_string()))?
        .into_pyarray(py))
}

fn item<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?.ok_or_else(|| {
        PyValueError::new_err(format!("missing key '{key}' in the closed-loop problem"))
    })
}

fn f(d: &Bound<'_, PyDict>, key: &str) -> PyResult<f64> {
    item(d, key)?.extract()
}

fn vecf(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Vec<f64>> {
    let a: PyReadonlyArray1<f64> = item(d, key)?.extract()?;
    Ok(a.as_array().iter().copied().collect())
}

fn matf(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Vec<f64>> {
    let a: PyReadonlyArray2<f64> = item(d, key)?.extract()?;
    Ok(a.as_array().iter().copied().collect())
}

fn arr3(d: &Bound<'_, PyDict>, key: &str) -> PyResult<[f64; 3]> {
    vecf(d, key)?
        .try_into()
        .map_err(|_| PyValueError::new_err(format!("'{key}' must have 3 entries")))
}

fn lti(d: &Bound<'_, PyDict>, a: &str, b: &str, c: Option<&str>) -> PyResult<Lti> {
    Ok(Lti {
        a: matf(d, a)?,
        b: vecf(d, b)?,
        c: match c {
            Some(k) => vecf(d, k)?,
            None => vec![],
        },
    })
}

/// Adaptive backlash-inverse closed loop; `args` is the dict built by
/// `backlashkit.control.closed_loop.build_problem`. Returns a dict of arrays.
#[pyfunction]
fn simulate_adaptive<'py>(
    py: Python<'py>,
    args: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let table_t = vecf(args, "table_t")?;
    let reference = if table_t.is_empty() {
        Reference::Sines {
            amps: vecf(args, "amps")?,
            freqs: vecf(args, "freqs")?,
            phases: vecf(args, "phases")?,
        }
    } else {
        Reference::Table {
            t: table_t,
            r: vecf(args, "table_r")?,
        }
    };
    let kind: i64 = item(args, "kind")?.extract()?;
    let p = AdaptiveProblem {
        plant: lti(args, "ap", "bp", Some("cp"))?,
        xp0: vecf(args, "xp0")?,
        m: f(args, "m")?,
        c_r: f(args, "c_r")?,
        c_l: f(args, "c_l")?,
        u0: f(args, "u0")?,
        filt: lti(args, "al", "bl", None)?,
        th1: vecf(args, "th1")?,
        th2: vecf(args, "th2")?,
        th3: f(args, "th3")?,
        refmodel: lti(args, "am", "bm", Some("cm"))?,
        hfilt: lti(args, "ah", "bh", Some("ch"))?,
        gamma: arr3(args, "gamma")?,
        sigma: f(args, "sigma")?,
        sigma_bound: f(args, "sigma_bound")?,
        m0: f(args, "m0")?,
        thb0: arr3(args, "thb0")?,
        kind: InverseKind::from_code(kind, f(args, "p1")?, f(args, "p2")?).map_err(value_error)?,
        reference,
        h: f(args, "h")?,
        n_steps: item(args, "n_steps")?.extract()?,
        n_sub: item(args, "n_sub")?.extract()?,
        noise: vecf(args, "noise")?,
        dist: vecf(args, "dist")?,
    };
    let out = py
        .detach(|| control::simulate_adaptive(&p))
        .map_err(value_error)?;
    let d = PyDict::new(py);
    d.set_item("t", out.t.into_pyarray(py))?;
    d.set_item("r", out.r.into_pyarray(py))?;
    d.set_item("y", out.y.into_pyarray(py))?;
    d.set_item("ym", out.ym.into_pyarray(py))?;
    d.set_item("ud", out.ud.into_pyarray(py))?;
    d.set_item("v", out.v.into_pyarray(py))?;
    d.set_item("u", out.u.into_pyarray(py))?;
    d.set_item("thb", out.thb.into_pyarray(py))?;
    d.set_item("xp", out.xp.into_pyarray(py))?;
    d.set_item("n_switches", out.n_switches)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(play_operator, m)?)?;
    m.add_function(wrap_pyfunction!(zoh_recurrence, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_adaptive, m)?)?;
    Ok(())
}
