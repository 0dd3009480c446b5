"""Backlash operator of paper B (2.1) and its exact inverse (2.2)/(2.4)."""

import numpy as np
import pytest

from backlashkit import Backlash, InputError
from backlashkit._numpy_control import play_operator as play_ref
from backlashkit.nonlinearities import (
    SmoothFilterInverse,
    SmoothRampInverse,
    backlash_inverse,
    inverse_from_name,
)

# Paper B, Section IV: m = 0.7, c_r = 1.3, c_l = -0.5, theta_b* = (0.91, 0.7, -0.35)
PAPER_B = Backlash(0.7, 1.3, -0.5)


def test_theta_b_of_the_paper_example():
    np.testing.assert_allclose(PAPER_B.theta_b, [0.91, 0.7, -0.35], rtol=1e-12)


def test_sides_and_inner_segment_by_hand():
    v = np.array([0.0, 2.0, 3.0, 2.5, 1.5, 0.0, -1.0])
    u = PAPER_B.apply(v)
    expected = [0.0, 0.7 * 0.7, 0.7 * 1.7, 0.7 * 1.7, 0.7 * 1.7, 0.7 * 0.5, 0.7 * -0.5]
    np.testing.assert_allclose(u, expected, atol=1e-15)


@pytest.mark.parametrize("seed", range(5))
def test_rust_matches_numpy_reference_on_random_inputs(seed):
    rng = np.random.default_rng(seed)
    v = np.cumsum(rng.normal(size=5000))
    b = Backlash(rng.uniform(0.1, 3), rng.uniform(0, 2), rng.uniform(-2, 0) - 1e-3)
    u0 = rng.normal()
    np.testing.assert_array_equal(b.apply(v, u0=u0), b.apply(v, u0=u0, backend="numpy"))
    np.testing.assert_array_equal(b.apply(v, u0=u0), play_ref(v, b.m, b.c_r, b.c_l, u0))


def test_output_stays_between_the_two_sides():
    rng = np.random.default_rng(1)
    v = rng.normal(scale=5, size=2000)
    u = PAPER_B.apply(v)
    assert np.all(u >= PAPER_B.m * (v - PAPER_B.c_r) - 1e-12)
    assert np.all(u <= PAPER_B.m * (v - PAPER_B.c_l) + 1e-12)


def test_exact_inverse_is_a_right_inverse_lemma_2_1():
    t = np.linspace(0, 20, 4001)
    u_d = 3 * np.sin(1.3 * t) + np.sin(0.4 * t)
    v = PAPER_B.inverse(u_d)
    np.testing.assert_allclose(PAPER_B.apply(v, u0=u_d[0]), u_d, atol=1e-12)
    # and without the inverse the output is wrong
    assert np.max(np.abs(PAPER_B.apply(u_d, u0=u_d[0]) - u_d)) > 0.5


def test_inverse_jumps_by_the_gap_at_reversals():
    u_d = np.array([0.0, 1.0, 2.0, 1.5, 1.0])
    v = backlash_inverse(u_d, m=0.7, c_r=1.3, c_l=-0.5)
    assert v[3] - (1.5 / 0.7 - 0.5) == pytest.approx(0.0)
    assert v[2] - v[3] == pytest.approx(0.5 / 0.7 + 1.3 + 0.5)


@pytest.mark.parametrize(
    "args, msg",
    [
        ((0.0, 1.0, -1.0), "m must be > 0"),
        ((1.0, -1.0, 1.0), "c_l must be < c_r"),
        ((1.0, float("nan"), 0.0), "c_r must be finite"),
    ],
)
def test_bad_parameters(args, msg):
    with pytest.raises(InputError, match=msg):
        Backlash(*args)


def test_inverse_configuration_objects():
    assert inverse_from_name("smooth-filter", alpha=3.0) == SmoothFilterInverse(alpha=3.0)
    assert SmoothRampInverse(beta_r=2, beta_l=1).params() == (2.0, 1.0)
    with pytest.raises(InputError, match="alpha must be > 0"):
        SmoothFilterInverse(alpha=-1)
    with pytest.raises(InputError, match=r"inverse must be one of .*, got 'bogus'$"):
        inverse_from_name("bogus")
    with pytest.raises(InputError, match=r"got 'exakt' \(did you mean 'exact'\?\)$"):
        inverse_from_name("exakt")


def test_nonfinite_input_rejected():
    with pytest.raises(InputError, match="non-finite"):
        PAPER_B.apply([0.0, np.nan])
