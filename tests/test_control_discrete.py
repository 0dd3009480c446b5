"""Sample-by-sample controller at 1 kHz vs the continuous-time loop (paper B example)."""

import numpy as np
import pytest

from backlashkit import (
    AdaptiveLaw,
    Backlash,
    DiscreteAdaptiveController,
    SmoothFilterInverse,
    SumOfSines,
    simulate_closed_loop,
)
from backlashkit.control import simulate_discrete_loop

# Paper B, Section IV
PLANT = ([1.0], [1.0, -0.5, -1.5])
TRUE_B = Backlash(0.7, 1.3, -0.5)
LAW = AdaptiveLaw(gamma=5.0, theta_b0=(1.51, 0.2, -0.55), m0=0.02)
REF = SumOfSines([10.0], [1.3])


@pytest.mark.parametrize("inverse", [None, SmoothFilterInverse(alpha=6.0)])
def test_1khz_discrete_controller_reproduces_continuous_time(inverse):
    cont = simulate_closed_loop(
        PLANT, TRUE_B, reference=REF, duration=60.0, ts=1e-3, adaptation=LAW, inverse=inverse
    )
    ctrl = DiscreteAdaptiveController(PLANT, ts=1e-3, adaptation=LAW, inverse=inverse)
    disc = simulate_discrete_loop(PLANT, TRUE_B, ctrl, reference=REF, duration=60.0)
    assert disc.t.size == cont.t.size
    scale = np.max(np.abs(cont.y_m))
    assert np.max(np.abs(disc.y - cont.y)) <= 0.01 * scale
    np.testing.assert_allclose(disc.y_m, cont.y_m, atol=1e-3 * scale)
    np.testing.assert_allclose(disc.theta_b[-1], cont.theta_b[-1], rtol=0.01)
    if inverse is None:
        assert disc.rms_error_last() <= 1e-3
        np.testing.assert_allclose(disc.theta_b[-1], [0.91, 0.7, -0.35], rtol=0.01)
    else:
        assert disc.rms_error_last() <= 2e-2


def test_step_api_and_reset():
    ctrl = DiscreteAdaptiveController(PLANT, ts=1e-3, adaptation=LAW)
    v1 = [ctrl.step(0.0, 10 * np.sin(1.3 * k * 1e-3)) for k in range(50)]
    ctrl.reset()
    v2 = [ctrl.step(0.0, 10 * np.sin(1.3 * k * 1e-3)) for k in range(50)]
    assert v1 == v2
    assert all(isinstance(v, float) for v in v1)
    np.testing.assert_array_equal(ctrl.theta_b.shape, (3,))
