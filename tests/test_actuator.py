"""The current loop (``CurrentLoop``): exact first-order lag of the motor torque."""

from __future__ import annotations

import math

import numpy as np
import pytest

import backlashkit as bk
from backlashkit.actuator import CurrentLoop
from backlashkit.errors import InputError
from backlashkit.io import read_actuator_toml, read_drive_toml

PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)


def test_free_motor_follows_the_closed_form():
    # Inside a wide gap the motor is alone: T = u (1 - exp(-t/tau)) from T(0) = 0, and
    # J w' = T - f w gives w = u/f [1 - (a e^{-t/tau} - b e^{-a t}) / (a - b)] with
    # a = f/J (as 1/s) and b = 1/tau.
    drive = bk.TwoMassDrive(**PAPER, theta=10.0)
    tau, u = 2e-3, 0.3
    t = np.arange(201) * 1e-3
    resp = drive.simulate(t, np.full(t.size, u), actuator=CurrentLoop(tau),
                          initial_state=[0.0, 0.0, 0.0, 0.0])
    assert resp.events == ()
    a, b = PAPER["f_M"] / PAPER["J_M"], 1.0 / tau
    torque = u * (1.0 - np.exp(-t / tau))
    w = u / PAPER["f_M"] * (1.0 - (a * np.exp(-b * t) - b * np.exp(-a * t)) / (a - b))
    np.testing.assert_allclose(resp.motor_torque, torque, rtol=0, atol=1e-14)
    np.testing.assert_allclose(resp.w_motor, w, rtol=1e-12, atol=1e-14)
    assert resp.states.shape == (t.size, 3)
    np.testing.assert_array_equal(resp.w_load, 0.0)


def test_loop_starts_settled_and_lags_a_step():
    drive = bk.TwoMassDrive(**PAPER, theta=0.03)
    t = np.arange(101) * 1e-3
    u = np.where(t < 0.05, 0.2, -0.1)
    resp = drive.simulate(t, u, actuator=CurrentLoop(1e-3))
    # default initial motor torque: the first set-point (the loop settled)
    assert resp.motor_torque[0] == 0.2
    np.testing.assert_allclose(resp.motor_torque[:50], 0.2, rtol=0, atol=1e-15)
    # after the step at 50 ms: -0.1 + 0.3 exp(-(t - 0.05)/tau)
    after = t >= 0.05
    expect = -0.1 + 0.3 * np.exp(-(t[after] - 0.05) / 1e-3)
    np.testing.assert_allclose(resp.motor_torque[after], expect, rtol=0, atol=1e-14)


def test_zero_time_constant_is_exact():
    drive = bk.TwoMassDrive(**PAPER, theta=0.03)
    t = np.arange(3001) * 1e-3
    u = np.where(t < 1.5, 0.157, 0.0)
    exact = drive.simulate(t, u)
    same = drive.simulate(t, u, actuator=CurrentLoop(0.0))
    np.testing.assert_array_equal(same.states, exact.states)
    assert same.loop_torque is None
    np.testing.assert_array_equal(same.motor_torque, u)
    # a fast loop converges to the exact run (its lag shifts the response by ~tau)
    fast = drive.simulate(t, u, actuator=CurrentLoop(1e-6))
    scale = np.abs(exact.speeds).max()
    assert np.abs(fast.speeds - exact.speeds).max() < 1e-4 * scale


@pytest.mark.parametrize("law", ["paper", "no-pull", "modelica"])
def test_numpy_twin_matches_kernel(law):
    chain = bk.DriveChain(J=[0.01, 0.03, 0.2], f=[0.01, 0.02, 0.05], k=[60.0, 150.0],
                          d=[0.2, 0.5], theta=[0.02, 0.01])
    t = np.arange(601) * 1e-3
    u = np.where((t // 0.1) % 2 == 0, 1.5, -1.5)
    kw = dict(law=law, actuator=CurrentLoop(1.5e-3))
    a = bk.simulate_drive(chain, t, u, **kw)
    b = bk.simulate_drive(chain, t, u, backend="numpy", **kw)
    assert len(a.events) > 5
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-10)
    np.testing.assert_allclose(a.motor_torque, b.motor_torque, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.event_array, b.event_array, rtol=0, atol=1e-12)


def test_initial_motor_torque_can_be_given():
    drive = bk.TwoMassDrive(**PAPER, theta=0.03)
    t = np.arange(11) * 1e-3
    resp = drive.simulate(t, np.zeros(t.size), actuator=CurrentLoop(1e-3),
                          initial_state=[0.0, 0.0, 0.0, 0.5])
    np.testing.assert_allclose(resp.motor_torque, 0.5 * np.exp(-t / 1e-3), rtol=1e-13)
    with pytest.raises(InputError, match="initial_state must have 3 entries"):
        drive.simulate(t, np.zeros(t.size), initial_state=[0.0, 0.0, 0.0, 0.5])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -1e-3, "1e-3", True])
def test_bad_time_constant_is_refused(bad):
    with pytest.raises(InputError, match="tau_i") as info:
        CurrentLoop(bad)
    assert "\n" not in str(info.value)


def test_actuator_table(tmp_path):
    path = tmp_path / "drive.toml"
    drive_table = "[drive]\n" + "".join(f"{k} = {v!r}\n" for k, v in PAPER.items())
    path.write_text(drive_table + "theta = 0.03\n[actuator]\ntau_i = 1.2e-3\n")
    assert read_actuator_toml(path) == CurrentLoop(1.2e-3)
    assert read_drive_toml(path).theta == 0.03  # the drive table reads as before
    path.write_text(drive_table + "theta = 0.03\n")
    assert read_actuator_toml(path) is None
    for body, match in [("tau_i = nan", "tau_i must be finite"),
                        ("tau_i = -1.0", "tau_i must be a finite time constant >= 0"),
                        ("tau = 1e-3", r"\[actuator\] takes exactly the key")]:
        path.write_text(drive_table + f"theta = 0.03\n[actuator]\n{body}\n")
        with pytest.raises(InputError, match=match):
            read_actuator_toml(path)
