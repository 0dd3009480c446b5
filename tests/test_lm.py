"""The joint estimator's Levenberg-Marquardt (``backlashkit.identify._lm``): its step
doubling, tried only where the parabola along the step says it pays."""

from __future__ import annotations

import numpy as np
import pytest

from backlashkit.identify._lm import LMState, _doubling_pays, lm


@pytest.mark.parametrize("curvature", [0.05, 0.2, 1.0 / 3.0 - 1e-9, 1.0 / 3.0 + 1e-9, 0.5, 2.0])
def test_the_parabola_tells_whether_twice_the_step_is_lower(curvature):
    # on an exact parabola c(t) = c0 + 2 s t + k t^2 the test is the truth: c(2) < c(1)
    c0, slope = 10.0, -1.0
    cost = lambda t: c0 + 2.0 * slope * t + curvature * t * t  # noqa: E731
    assert _doubling_pays(c0, slope, cost(1.0)) == (cost(2.0) < cost(1.0))


def counted(fun):
    calls = []

    def call(z):
        calls.append(z.copy())
        return fun(z)

    return call, calls


def test_a_step_that_lands_on_the_minimum_is_not_doubled():
    # linear least squares: the first (lightly damped) step lands on the minimum, so the
    # parabola through it predicts a rise at twice the step, and no simulation is spent
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=50)
    fun, calls = counted(lambda z: a @ z - b)
    st = lm(fun, lambda z, r: a, np.zeros(3), max_iter=1)
    assert len(calls) == 2  # the start and the step
    assert np.allclose(st.z, np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-2)


def test_a_heavily_damped_step_is_doubled_and_lowers_the_cost():
    # a damping of 3 (a run that has had steps rejected) makes the step a quarter of
    # Gauss-Newton's: the parabola says twice the step is lower, and it is
    a, b = np.diag([1.0, 1e-2]), np.array([1.0, 1e-2])
    fun, calls = counted(lambda z: a @ z - b)
    r0 = fun(np.zeros(2))
    start = LMState(np.zeros(2), r0, float(r0 @ r0), None, mu=3.0)
    st = lm(fun, lambda z, r: a, np.zeros(2), max_iter=1, state=start)
    assert len(calls) >= 3  # the start, the step and at least one doubling
    single = fun(calls[1])
    assert st.cost < float(single @ single)
    # twice a quarter of the way to z = 1, where the longest step (0.5) stops it
    assert np.allclose(st.z, 0.5, rtol=1e-12)
