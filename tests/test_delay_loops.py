"""Delay margins of the toolkit's loops, checked against the SISO margin
``min_i PM_i / omega_i`` (python-control) of the loop broken at the delay."""

from __future__ import annotations

import numpy as np
import pytest

from backlashkit import TwoMassDrive
from backlashkit.control import design_mrc
from backlashkit.delay import margin_of_system
from backlashkit.delay.loops import (
    input_delay_loop,
    mrc_delay_margin,
    mrc_delay_system,
    pi_controller,
    siso_delay_margin,
    two_mass_contact,
)

pytest.importorskip("control")

#: Paper B, Section IV: G(s) = 1/((s - 1.5)(s + 1)), true m = 0.7, initial m_hat = 0.2.
PAPER_B_PLANT = ([1.0], [1.0, -0.5, -1.5])
GAIN_FROZEN_AT_THETA_B0 = 0.7 / 0.2


def paper_b_loop(gain: float):
    return mrc_delay_system(design_mrc(PAPER_B_PLANT), gain=gain)


@pytest.mark.parametrize("method", ["sweep", "kronecker"])
def test_paper_b_mrc_loop_matches_siso_margin(method):
    plant, ctrl, system = paper_b_loop(1.0)
    r = margin_of_system(system, method=method)
    siso, crossovers = siso_delay_margin(plant, ctrl, sign=+1.0)
    assert r.stable_at_zero and r.verification["passed"]
    assert r.h_max == pytest.approx(siso, rel=1e-9)
    assert len(crossovers) == 1 and r.omega == pytest.approx(crossovers[0][0], rel=1e-9)
    # the delay-free loop is the reference model times the filter: poles -2, -2, -2, -2, -3
    # and the plant's zero-free remainder; all in the left half-plane
    assert np.all(np.linalg.eigvals(system.delay_free_matrix()).real < 0)


def test_paper_b_margin_shrinks_with_the_loop_gain_and_vanishes_at_theta_b0():
    """With the estimates frozen at theta_b(0) the backlash and its inverse have gain
    m / m_hat = 3.5: the linear loop is unstable even without delay."""
    margins = []
    for gain in (1.0, 1.5, 2.0, 2.5):
        plant, ctrl, system = paper_b_loop(gain)
        r = margin_of_system(system)
        assert r.h_max == pytest.approx(siso_delay_margin(plant, ctrl, sign=+1.0)[0],
                                        rel=1e-9)
        margins.append(r.h_max)
    assert all(a > b for a, b in zip(margins[:-1], margins[1:], strict=True))
    _, _, frozen = paper_b_loop(GAIN_FROZEN_AT_THETA_B0)
    r = margin_of_system(frozen)
    assert r.h_max == 0.0 and not r.stable_at_zero
    assert np.max(np.linalg.eigvals(frozen.delay_free_matrix()).real) > 0


PAPER_A_DRIVE = TwoMassDrive(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2,
                             f_sh=1.575e-2, theta=np.deg2rad(2.0))


@pytest.mark.parametrize("method", ["sweep", "kronecker"])
@pytest.mark.parametrize("kp,ki", [(0.05, 0.5), (0.2, 2.0), (0.5, 10.0)])
def test_two_mass_pi_speed_loop_matches_siso_margin(method, kp, ki):
    """Paper A's drive in contact under a PI motor-speed controller with a computation
    delay: the lightly damped shaft resonance (~131 rad/s) sets the margin."""
    plant = two_mass_contact(PAPER_A_DRIVE)
    ctrl = pi_controller(kp, ki)
    r = margin_of_system(input_delay_loop(plant, ctrl), method=method)
    siso, crossovers = siso_delay_margin(plant, ctrl)
    assert r.verification["passed"]
    assert r.h_max == pytest.approx(siso, rel=1e-9)
    assert len(crossovers) == 3  # one low crossover, two around the resonance


def test_mrc_delay_margin_of_a_design():
    """What ``backlashkit control`` reports: the linear loop's margin, its own design."""
    # paper B's plant, and one with k_p != 1 and a zero
    for plant_tf in (PAPER_B_PLANT, ([2.0, 2.0], [1.0, 1.0, -2.0, 0.5])):
        design = design_mrc(plant_tf)
        plant, ctrl, _ = mrc_delay_system(design)
        r = mrc_delay_margin(design)
        assert r.verification["passed"]
        assert r.h_max == pytest.approx(siso_delay_margin(plant, ctrl, sign=+1.0)[0],
                                        rel=1e-9)
