"""Model-reference design (paper B, Section III-A, Diophantine equation (3.3))."""

import control  # a test dependency: paper B's checks fail, not skip, without it
import numpy as np
import pytest
import scipy.signal

from backlashkit import InputError, design_mrc

# Paper B, Section IV: G = 1/((s-1.5)(s+1)), Lambda = (s+2)^2, W_m = 1/((s+2)(s+3)):
# theta_11 = -32.25, theta_12 = -5.5, theta_21 = -78.375, theta_22 = -76.375, theta_3 = 1
PAPER_THETA = (-32.25, -5.5, -78.375, -76.375, 1.0)
PAPER_PLANT = ([1.0], np.polymul([1.0, -1.5], [1.0, 1.0]))


@pytest.mark.parametrize(
    "plant",
    [PAPER_PLANT, control.tf(*PAPER_PLANT), scipy.signal.lti(*PAPER_PLANT)],
)
def test_paper_controller_parameters_section_iv(plant):
    d = design_mrc(plant, reference_model=[1, 5, 6], filter=[1, 4, 4])
    got = (*d.theta_1, *d.theta_2, d.theta_3)
    np.testing.assert_allclose(got, PAPER_THETA, rtol=0, atol=1e-12)


def test_defaults_reproduce_the_paper_choice():
    d = design_mrc(PAPER_PLANT)
    np.testing.assert_allclose((*d.theta_1, *d.theta_2, d.theta_3), PAPER_THETA, atol=1e-12)


def _random_plant(rng):
    n = int(rng.integers(1, 5))
    m = int(rng.integers(0, n))
    zeros = -rng.uniform(0.3, 5, size=m)
    poles = rng.uniform(-4, 3, size=n)
    k_p = rng.choice([-1, 1]) * rng.uniform(0.2, 5)
    return (k_p * np.poly(zeros), np.poly(poles)), n, n - m


@pytest.mark.parametrize("seed", range(20))
def test_diophantine_on_random_plants_by_expanding_both_sides(seed):
    rng = np.random.default_rng(seed)
    plant, n, n_star = _random_plant(rng)
    r_m = np.poly(-rng.uniform(0.5, 5, size=n_star)) * rng.uniform(0.5, 2)
    lam = np.poly(-rng.uniform(0.5, 5, size=n))
    d = design_mrc(plant, reference_model=r_m, filter=lam)
    # expand (3.3): theta_1' a R + theta_2' a k_p Z = Lambda (R - k_p theta_3 Z R_m)
    lhs = np.polyadd(
        np.polymul(d.theta_1[::-1], d.poles_poly),
        np.polymul(d.theta_2[::-1], d.k_p * d.zeros_poly),
    )
    rhs = np.polymul(
        lam, np.polysub(d.poles_poly, d.k_p * d.theta_3 * np.polymul(d.zeros_poly, r_m))
    )
    diff = np.polysub(lhs, rhs)
    assert np.max(np.abs(diff)) <= 1e-8 * max(1.0, np.max(np.abs(rhs)))
    assert d.diophantine_residual() < 1e-8
    # and the matched closed loop is the reference model: y = 1/R_m r when u = u_d
    s = control.tf("s")
    G = control.tf(*plant)
    a = [s**i for i in range(n)]
    P = sum(d.theta_1[i] * a[i] for i in range(n)) / control.tf(lam, [1])
    Q = sum(d.theta_2[i] * a[i] for i in range(n)) / control.tf(lam, [1])
    cl = d.theta_3 * G / (1 - P - Q * G)
    w = np.array([0.3, 1.0, 3.0])
    np.testing.assert_allclose(cl(1j * w), 1 / np.polyval(r_m, 1j * w), rtol=1e-6)


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        ({"plant": ([1.0, -1.0], [1.0, 2.0, 3.0])}, "A1"),
        ({"plant": ([1.0, 0.0], [1.0, 2.0, 3.0])}, "A1"),
        ({"plant": PAPER_PLANT, "reference_model": [1.0, 2.0]}, "A2"),
        ({"plant": PAPER_PLANT, "reference_model": [1.0, -2.0, 1.0]}, "Hurwitz"),
        ({"plant": PAPER_PLANT, "filter": [1.0, -4.0, 4.0]}, "Hurwitz"),
        ({"plant": PAPER_PLANT, "filter": [1.0, 4.0]}, "degree n = 2"),
        ({"plant": ([1.0, 0.0, 0.0, 1.0], [1.0, 2.0, 3.0])}, "proper"),
        ({"plant": ([1.0, 1.0], [1.0, 2.0])}, "strictly proper"),
        ({"plant": ([1.0, 1.0], np.polymul([1.0, 1.0], [1.0, 3.0, 1.0]))}, "cancellation"),
    ],
)
def test_assumption_violations_refused(kwargs, msg):
    with pytest.raises(InputError, match=msg):
        design_mrc(**kwargs)


@pytest.mark.parametrize("plant", [([1.0], np.poly([-300.0, -600.0])),
                                   ([1e12], [1.0, -0.5, -1.5]), ([1e-12], [1.0, -0.5, -1.5])])
def test_a_badly_scaled_plant_is_designed_not_called_a_cancellation(plant):
    """Poles at hundreds of rad/s, or a gain of 1e12, scale (3.3)'s Sylvester matrix
    apart: its condition number passed 1e12 and the plant was refused as a pole-zero
    cancellation it does not have. Solved with its rows and columns equilibrated, the
    matched closed loop is the reference model."""
    d = design_mrc(plant)
    assert d.diophantine_residual() < 1e-8
    s = control.tf("s")
    n = len(plant[1]) - 1
    lam = control.tf(d.filter, [1])
    P = sum(d.theta_1[i] * s**i for i in range(n)) / lam
    Q = sum(d.theta_2[i] * s**i for i in range(n)) / lam
    G = control.tf(*plant)
    w = np.array([0.3, 1.0, 3.0])
    np.testing.assert_allclose((d.theta_3 * G / (1 - P - Q * G))(1j * w),
                               1 / np.polyval(d.reference_model, 1j * w), rtol=1e-6)


def test_a_design_that_cannot_match_is_refused():
    """Poles from 10 to 6000 rad/s with a zero at 2: (3.3) solves to its residual
    check, but the gains (1e16) leave the matched loop 3 % off the reference model."""
    with pytest.raises(InputError, match=r"too ill-conditioned for this plant: its matched "
                                         r"closed loop departs from the reference model "
                                         r"by 0.0\d+ \(relative"):
        design_mrc(([1.0, 2.0], np.poly([-3000.0, -6000.0, -10.0])))


def test_a_cancellation_names_the_common_root():
    with pytest.raises(InputError, match=r"common root of numerator and denominator near "
                                         r"s = -2 \(pole-zero cancellation\)"):
        design_mrc(([1.0, 2.0 + 1e-12], [1.0, 3.0, 2.0]))
