"""LTI conversion and the plant with input backlash y = G[B(v)] (paper B (3.1))."""

import control  # a test dependency: paper B's checks fail, not skip, without it
import numpy as np
import pytest
import scipy.signal

from backlashkit import Backlash, InputError, LinearPlantWithBacklash
from backlashkit.lti import as_state_space, as_transfer_function

G_NUM, G_DEN = [1.0, 2.0], [1.0, 0.5, -1.5, 0.3]


def _rand_v(n, seed):
    rng = np.random.default_rng(seed)
    return np.repeat(rng.normal(scale=3, size=n // 20 + 1), 20)[:n] + 0.1 * rng.normal(size=n)


@pytest.mark.parametrize(
    "plant",
    [
        (G_NUM, G_DEN),
        scipy.signal.lti(G_NUM, G_DEN),
        scipy.signal.lti(*scipy.signal.tf2ss(G_NUM, G_DEN)),
        control.tf(G_NUM, G_DEN),
        control.ss(control.tf(G_NUM, G_DEN)),
    ],
)
def test_all_representations_give_the_same_transfer_function(plant):
    num, den = as_transfer_function(plant)
    np.testing.assert_allclose(num, G_NUM, atol=1e-9)
    np.testing.assert_allclose(den, G_DEN, atol=1e-9)


@pytest.mark.parametrize("backend", ["rust", "numpy"])
def test_zoh_simulation_matches_python_control_forced_response(backend):
    t = np.arange(3000) * 1e-2
    v = _rand_v(t.size, 0)
    b = Backlash(0.7, 1.3, -0.5)
    res = LinearPlantWithBacklash((G_NUM, G_DEN), b).simulate(t, v, backend=backend)
    u = b.apply(v, backend="numpy")
    np.testing.assert_array_equal(res.u, u)
    # independent method: exact discretisation by python-control, then dlsim on u = B(v)
    sysd = control.c2d(control.tf(G_NUM, G_DEN), 1e-2, method="zoh")
    ref = control.forced_response(sysd, T=t, U=u)
    np.testing.assert_allclose(
        res.y, ref.outputs, rtol=1e-7, atol=1e-9 * np.max(np.abs(ref.outputs))
    )


def test_zoh_simulation_matches_scipy_dlsim_and_parity():
    t = np.arange(2000) * 5e-3
    v = _rand_v(t.size, 3)
    b = Backlash(1.2, 0.2, -0.9)
    plant = LinearPlantWithBacklash(scipy.signal.lti([2.0], [1.0, 3.0, 2.0]), b)
    x0 = np.array([0.3, -0.2])
    rr = plant.simulate(t, v, initial_state=x0)
    rn = plant.simulate(t, v, initial_state=x0, backend="numpy")
    np.testing.assert_allclose(rr.y, rn.y, rtol=1e-12, atol=1e-14)
    dsys = scipy.signal.cont2discrete((plant.a, plant.b[:, None], plant.c[None, :], [[0.0]]), 5e-3)
    _, yd, _ = scipy.signal.dlsim(dsys[:4] + (5e-3,), rr.u, t=t, x0=x0)
    np.testing.assert_allclose(rr.y, yd[:, 0], rtol=1e-8, atol=1e-10)


def test_response_plot_returns_figure():
    t = np.arange(100) * 0.01
    res = LinearPlantWithBacklash(([1.0], [1.0, 1.0]), Backlash(1, 0.1, -0.1)).simulate(
        t, np.sin(t)
    )
    fig = res.plot()
    assert fig.axes


@pytest.mark.parametrize(
    "plant, msg",
    [
        (([1.0, 0, 0], [1.0, 1.0]), "proper"),
        (([1.0], [0.0, 0.0]), "zero polynomial"),
        (([1.0],), r"\(num, den\)"),
        ("G", "must be"),
    ],
)
def test_bad_plants(plant, msg):
    with pytest.raises(InputError, match=msg):
        as_state_space(plant)


def test_discrete_time_plant_refused():
    with pytest.raises(InputError, match="continuous-time"):
        as_state_space(control.tf([1.0], [1.0, -0.5], 0.1))


def test_non_uniform_time_refused():
    p = LinearPlantWithBacklash(([1.0], [1.0, 1.0]), Backlash(1, 0.1, -0.1))
    with pytest.raises(InputError, match="uniformly sampled"):
        p.simulate([0.0, 0.1, 0.3], [0.0, 0.0, 0.0])
