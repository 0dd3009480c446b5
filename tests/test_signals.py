"""Experiment signals and measurement noise (backlashkit.signals)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from backlashkit import InputError
from backlashkit import signals as sg

T = sg.time_grid(1.0, 1e-3)


# --- time_grid ---------------------------------------------------------------------


def test_time_grid_includes_the_end_when_it_is_a_multiple():
    t = sg.time_grid(80.0, 1e-3)
    assert t.size == 80001 and t[0] == 0.0 and t[-1] == pytest.approx(80.0, abs=1e-12)
    np.testing.assert_allclose(np.diff(t), 1e-3, rtol=1e-9)


def test_time_grid_stops_before_a_non_multiple_end():
    t = sg.time_grid(1.0, 0.3)
    np.testing.assert_allclose(t, [0.0, 0.3, 0.6, 0.9])


@pytest.mark.parametrize(
    ("duration", "ts", "culprit"),
    [
        (0.0, 1e-3, "duration"),
        (-1.0, 1e-3, "duration"),
        (math.nan, 1e-3, "duration"),
        (1.0, 0.0, "ts"),
        (1.0, math.inf, "ts"),
        (1e-4, 1e-3, "duration must be at least one sample time"),
        (1e9, 1e-6, "limit"),
    ],
)
def test_time_grid_rejects(duration, ts, culprit):
    with pytest.raises(InputError, match=culprit):
        sg.time_grid(duration, ts)


# --- steps ---------------------------------------------------------------------------


def test_step_down_switches_exactly_at_t_s_on_the_grid():
    t = sg.time_grid(80.0, 1e-3)
    u = sg.step_down(t, 0.157, t_s=40.0)
    k = np.flatnonzero(u != 0.157)[0]
    assert k == 40000 and t[k] == pytest.approx(40.0)
    assert np.all(u[:k] == 0.157) and np.all(u[k:] == 0.0)


def test_step_down_between_samples_switches_at_the_next_sample():
    u = sg.step_down(T, 1.0, t_s=0.0105, b=-2.0)
    assert u[10] == 1.0 and u[11] == -2.0 and set(np.unique(u)) == {1.0, -2.0}


def test_step_from_zero():
    u = sg.step(T, 3.0, t_step=0.5)
    assert np.all(u[:500] == 0.0) and np.all(u[500:] == 3.0)
    assert np.all(sg.step(T, 3.0) == 3.0)


@pytest.mark.parametrize(
    ("call", "culprit"),
    [
        (lambda: sg.step(T, math.nan), "amplitude"),
        (lambda: sg.step(T, 1.0, t_step="x"), "t_step"),
        (lambda: sg.step_down(T, 1.0, t_s=math.inf), "t_s"),
        (lambda: sg.step_down(T, 1.0, t_s=1.0, b=math.nan), "b"),
        (lambda: sg.step([0.0, 0.1, 0.3], 1.0), "uniformly"),
        (lambda: sg.step([0.0, 0.2, 0.1], 1.0), "increasing"),
        (lambda: sg.step([0.0], 1.0), "at least 2"),
    ],
)
def test_step_rejects(call, culprit):
    with pytest.raises(InputError, match=culprit) as info:
        call()
    assert "np.float64" not in str(info.value)  # plain numbers in messages


# --- sine ----------------------------------------------------------------------------


def test_sine_frequency_is_in_rad_per_s():
    u = sg.sine(T, 2.0, 2 * np.pi, phase=0.5)
    np.testing.assert_allclose(u, 2.0 * np.sin(2 * np.pi * T + 0.5), atol=1e-15)
    # one full period per second: the value at t = 0 and t = 1 agree
    assert u[0] == pytest.approx(u[-1], abs=1e-12)


def test_sine_rejects_aliasing_and_negative_frequency():
    with pytest.raises(InputError, match=r"Nyquist.*rad/s"):
        sg.sine(T, 1.0, math.pi / 1e-3)
    with pytest.raises(InputError, match="frequency must be >= 0"):
        sg.sine(T, 1.0, -1.0)


# --- prbs ----------------------------------------------------------------------------


def test_prbs_is_binary_deterministic_and_seeded():
    t = sg.time_grid(10.0, 1e-3)
    a = sg.prbs(t, 0.3, bit_time=0.02, seed=7)
    b = sg.prbs(t, 0.3, bit_time=0.02, seed=7)
    c = sg.prbs(t, 0.3, bit_time=0.02, seed=8)
    assert set(np.unique(a)) == {-0.3, 0.3}
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    # Generators and integer seeds agree
    assert np.array_equal(a, sg.prbs(t, 0.3, bit_time=0.02, seed=np.random.default_rng(7)))


def test_prbs_changes_only_on_bit_boundaries():
    t = sg.time_grid(5.0, 1e-3)
    u = sg.prbs(t, 1.0, bit_time=0.02, seed=1)
    changes = np.flatnonzero(np.diff(u)) + 1
    assert changes.size > 50
    assert np.all(changes % 20 == 0)


def test_prbs_is_a_maximal_length_sequence():
    order = 5
    period = 2**order - 1
    t = np.arange(3 * period) * 1e-3
    u = sg.prbs(t, 1.0, bit_time=1e-3, seed=3, order=order)
    assert np.array_equal(u[:period], u[period : 2 * period])
    # within one period an MLS has 2**(order-1) ones and 2**(order-1) - 1 zeros
    assert np.sum(u[:period] > 0) == 2 ** (order - 1)
    # and no shorter period
    assert all(not np.array_equal(u[:period], np.roll(u[:period], k)) for k in range(1, period))


@pytest.mark.parametrize(
    ("kwargs", "culprit"),
    [
        (dict(bit_time=1e-4, seed=0), "bit_time must be at least the sample time"),
        (dict(bit_time=0.0, seed=0), "bit_time must be > 0"),
        (dict(bit_time=0.01, seed=None), "seed"),
        (dict(bit_time=0.01, seed=-1), "seed"),
        (dict(bit_time=0.01, seed=True), "seed"),
        (dict(bit_time=0.01, seed=0, order=40), "order"),
    ],
)
def test_prbs_rejects(kwargs, culprit):
    with pytest.raises(InputError, match=culprit):
        sg.prbs(T, 1.0, **kwargs)


# --- from_table ----------------------------------------------------------------------


def test_from_table_zero_order_hold():
    t = np.arange(7) * 0.5
    u = sg.from_table(t, [0.0, 1.0, 1.2, 3.0], [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(u, [1.0, 1.0, 2.0, 3.0, 3.0, 3.0, 4.0])


def test_from_table_linear():
    t = np.arange(5) * 0.5
    u = sg.from_table(t, [0.0, 2.0], [0.0, 4.0], hold="linear")
    np.testing.assert_allclose(u, [0.0, 1.0, 2.0, 3.0, 4.0])


@given(st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=50))
@settings(max_examples=50, deadline=None)
def test_from_table_on_its_own_grid_is_the_table(values):
    t = np.arange(len(values)) * 1e-3
    np.testing.assert_array_equal(sg.from_table(t, t, values), values)


@pytest.mark.parametrize(
    ("table_t", "values", "kwargs", "culprit"),
    [
        ([0.1, 2.0], [1.0, 2.0], {}, r"starts at 0\.0 s, before .*table_t\[0\]"),
        ([0.0, 0.5], [1.0, 2.0], {}, r"ends at 1\.0 s, after .*table_t\[-1\]"),
        ([0.0, 2.0, 1.0], [1.0, 2.0, 3.0], {}, "table_t must be strictly increasing"),
        ([0.0, 2.0], [1.0], {}, "table_values must have one value"),
        ([0.0, 2.0], [1.0, math.nan], {}, "table_values has a non-finite"),
        ([0.0, 2.0], [1.0, 2.0], dict(hold="cubic"), "hold must be"),
    ],
)
def test_from_table_rejects(table_t, values, kwargs, culprit):
    with pytest.raises(InputError, match=culprit):
        sg.from_table(T, table_t, values, **kwargs)


# --- noise ---------------------------------------------------------------------------


@pytest.mark.parametrize("snr_db", [-3.0, 6.43, 17.4, 35.6])
def test_add_noise_reaches_the_requested_snr(snr_db):
    t = sg.time_grid(400.0, 1e-3)
    clean = 10.0 + 3.0 * np.sin(2.0 * t)  # the mean counts in the signal power
    noisy = sg.add_noise(clean, snr_db, rng=np.random.default_rng(1))
    noise = noisy - clean
    measured = 10 * np.log10(np.mean(clean**2) / np.var(noise))
    assert abs(measured - snr_db) < 0.1
    assert abs(sg.measure_snr_db(clean, noisy) - snr_db) < 0.1
    assert abs(np.mean(noise)) < 5 * np.std(noise) / np.sqrt(noise.size)  # zero mean


def test_add_noise_is_deterministic_given_a_seed():
    clean = np.linspace(0.0, 1.0, 1000)
    a = sg.add_noise(clean, 20.0, rng=5)
    b = sg.add_noise(clean, 20.0, rng=5)
    c = sg.add_noise(clean, 20.0, rng=6)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    gen = np.random.default_rng(5)
    assert np.array_equal(sg.add_noise(clean, 20.0, rng=gen), a)
    assert not np.array_equal(sg.add_noise(clean, 20.0, rng=gen), a)  # the generator advanced
    np.testing.assert_array_equal(clean, np.linspace(0.0, 1.0, 1000))  # input untouched


@pytest.mark.parametrize(
    ("signal", "snr", "rng", "culprit"),
    [
        (np.zeros(10), 20.0, 0, "identically zero"),
        ([1.0, math.nan], 20.0, 0, "signal has a non-finite"),
        ([], 20.0, 0, "at least one sample"),
        (np.ones(10), math.inf, 0, "snr_db must be finite"),
        (np.ones(10), 20.0, None, "rng must be"),
        (np.ones(10), 20.0, 1.5, "rng must be"),
    ],
)
def test_add_noise_rejects(signal, snr, rng, culprit):
    with pytest.raises(InputError, match=culprit):
        sg.add_noise(signal, snr, rng=rng)


def test_measure_snr_of_identical_records_is_infinite():
    assert sg.measure_snr_db([1.0, 2.0], [1.0, 2.0]) == math.inf
