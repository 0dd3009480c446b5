//! PyO3 glue between `backlashkit-core` and the Python package (`backlashkit._core`).
//! No modelling here: argument conversion, GIL release, and Rust errors turned into
//! `ValueError`.

use pyo3::prelude::*;

mod control;
mod sensitivity;
mod sim;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    sim::register(m)?;
    control::register(m)?;
    sensitivity::register(m)?;
    Ok(())
}
