"""Encoders: exact absolute angles from the simulator, counts and difference speeds."""

from __future__ import annotations

import math

import numpy as np
import pytest

import backlashkit as bk
from backlashkit.encoder import Encoder, measure_encoders
from backlashkit.errors import InputError

PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)


def test_angles_are_exact_for_a_free_motor():
    # Inside a wide gap, from rest under u: phi_M = (u/f)(t - (J/f)(1 - exp(-f t/J))),
    # the load stays at -phi_d(0) (its twist start).
    drive = bk.TwoMassDrive(**PAPER, theta=100.0)  # no contact within the record
    u, (J, f) = 0.2, (PAPER["J_M"], PAPER["f_M"])
    t = np.arange(1001) * 1e-3
    resp = drive.simulate(t, np.full(t.size, u), initial_state=[0.0, 0.0, 0.5],
                          positions=True)
    exact = (u / f) * (t + (J / f) * np.expm1(-f * t / J))
    # (the closed form itself cancels to ~1e-15 rad at small t)
    np.testing.assert_allclose(resp.phi_motor, exact, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(resp.phi_load, -0.5, rtol=0, atol=1e-12)


def test_angles_on_demand_match_the_tracked_run():
    drive = bk.TwoMassDrive(**PAPER, theta=0.0349)
    t = np.arange(20001) * 1e-3
    u = np.where(t < 10.0, 0.157, 0.0)
    tracked = drive.simulate(t, u, positions=True)
    plain = drive.simulate(t, u)
    assert plain.angle is None
    np.testing.assert_allclose(plain.phi_motor, tracked.phi_motor, rtol=1e-12, atol=1e-12)
    # the tracked run's other states are those of the plain run, to rounding
    np.testing.assert_allclose(tracked.states, plain.states, rtol=0, atol=1e-12)
    # the angle is the integral of the speed: trapezoid rule error O(ts^2 w'')
    trap = np.concatenate([[0.0], np.cumsum(0.5 * (tracked.w_motor[1:] + tracked.w_motor[:-1]))
                           * 1e-3])
    assert np.abs(trap - tracked.phi_motor).max() < 1e-3
    np.testing.assert_allclose(tracked.phi_motor - tracked.phi_load, tracked.phi_d, atol=1e-12)


def test_numpy_twin_tracks_the_angle_too():
    drive = bk.TwoMassDrive(**PAPER, theta=0.0349)
    t = np.arange(2001) * 1e-3
    u = np.where(t < 1.0, 0.157, -0.1)
    a = bk.simulate_drive(drive, t, u, positions=True)
    b = bk.simulate_drive(drive, t, u, positions=True, backend="numpy")
    np.testing.assert_allclose(a.phi_motor, b.phi_motor, rtol=1e-12, atol=1e-12)


def test_batch_angle_matches_the_numpy_twin_on_random_drives():
    """The batch kernel's motor angle (``simulate_packed(track_angle=True)``, what the
    joint estimator fits encoder angles with) equals the NumPy twin's, run by run, on
    random drives with Coulomb friction and a current loop."""
    from backlashkit.simulate import simulate_packed

    rng = np.random.default_rng(5)
    t = np.arange(1501) * 1e-3
    u = np.where(t < 0.8, 0.6, 0.0)
    rows, drives = [], []
    for _ in range(6):
        p = {k: x * rng.uniform(0.7, 1.4) for k, x in PAPER.items()}
        theta, fc, tau = rng.uniform(0.01, 0.05), rng.uniform(0.0, 0.02, 2), rng.uniform(2e-4, 2e-3)
        drives.append((bk.TwoMassDrive(**p, theta=theta, fc_M=fc[0], fc_L=fc[1]), tau))
        rows.append([p["J_M"], p["J_L"], p["f_M"], p["f_L"], p["k_sh"], p["f_sh"], theta,
                     *fc, *fc, tau])
    x0 = np.tile([0.0, 0.0, 0.0, u[0], 0.0], (len(rows), 1))  # rest, loop torque, angle
    states = simulate_packed(2, np.array(rows), 0.0, 1e-3, u[np.newaxis, :], x0,
                             law="paper", workers=1, track_angle=True)
    for (drive, tau), x in zip(drives, states, strict=True):
        twin = bk.simulate_drive(drive, t, u, positions=True, backend="numpy",
                                 actuator=bk.CurrentLoop(tau))
        np.testing.assert_allclose(x[:, -1], twin.phi_motor, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(x[:, :2], twin.states[:, :2], rtol=1e-9, atol=1e-12)


def test_counts_and_difference_speed():
    enc = Encoder(1000)
    t = np.arange(1001) * 1e-3
    w = 7.3  # rad/s
    reading = enc.measure(t, w * t + 0.001)
    np.testing.assert_array_equal(reading.counts,
                                  np.floor((w * t + 0.001) / (2 * np.pi / 1000)))
    # each speed sample is a whole number of counts per sample time ...
    steps = reading.speed / (enc.resolution / 1e-3)
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    # ... and their mean is the true speed to one count over the record
    assert abs(reading.speed[1:].mean() - w) <= enc.resolution / 1.0 + 1e-12
    assert reading.speed[0] == reading.speed[1]
    np.testing.assert_allclose(reading.angle, reading.counts * enc.resolution)


def test_speed_filter_is_the_exact_first_order_lag():
    # A speed that jumps from 0 to a constant: the filter output is
    # w (1 - exp(-k ts / tau)) after k samples of the new value.
    tau, ts = 5e-3, 1e-3
    enc = Encoder(4096, tau_w=tau)
    t = np.arange(101) * ts
    counts_per_sample = 3
    angle = np.where(t < 0.02, 0.0, (np.round((t - 0.02) / ts) * counts_per_sample + 0.5)
                     * enc.resolution)
    reading = enc.measure(t, angle)
    raw = Encoder(4096).measure(t, angle).speed
    k0 = int(np.argmax(raw > 0))
    level = raw[k0]
    assert level == pytest.approx(counts_per_sample * enc.resolution / ts)
    k = np.arange(t.size - k0)
    np.testing.assert_allclose(reading.speed[k0:], level * (1 - np.exp(-(k + 1) * ts / tau)),
                               rtol=1e-12)
    np.testing.assert_array_equal(reading.speed[:k0], 0.0)


def test_measure_encoders_gives_identify_columns():
    drive = bk.TwoMassDrive(**PAPER, theta=0.0349)
    t = np.arange(5001) * 1e-3
    u = np.where(t < 2.5, 0.157, 0.0)
    resp = drive.simulate(t, u, positions=True)
    cols = measure_encoders(resp, Encoder(10000))
    assert list(cols) == ["t", "torque", "w_motor", "w_load", "count_motor", "count_load"]
    # at 10000 counts/rev and 1 ms a count is 0.63 rad/s of speed: the encoder speed
    # stays within one count of the mean true speed over the sample
    tol = 2 * np.pi / 10000 / 1e-3
    mean_w = np.diff(resp.phi_motor) / 1e-3
    assert np.abs(cols["w_motor"][1:] - mean_w).max() <= tol + 1e-9


@pytest.mark.parametrize("bad", [0.5, 0, -3, math.nan, "many"])
def test_encoder_needs_a_count_per_revolution(bad):
    with pytest.raises(InputError, match="counts_per_rev") as info:
        Encoder(bad)
    assert "\n" not in str(info.value)


def test_negative_speed_filter_is_refused():
    with pytest.raises(InputError, match="tau_w must be >= 0"):
        Encoder(1000, tau_w=-1.0)
