"""The compiled forward sensitivities (issue 24) against their NumPy twin.

Both follow the same recurrence along the contact changes of the compiled simulator;
they differ in the matrix exponential (Taylor in the kernel, Pade in SciPy) and in the
kernel's scaling of the sensitivities per log-parameter, so they agree to rounding,
amplified by the saltation jumps near grazing.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import backlashkit as bk
from _differences import agreement, check_bar, near_grazing
from _random_drives import FRICTIONS, KINDS, LEVELS, LOG_FACTORS, drive_record
from backlashkit import _core
from backlashkit._numpy_sensitivity import sensitivities as numpy_sensitivities
from backlashkit._sensitivity import (
    LINEAR_AND_THETA,
    PARAMS,
    default_params,
    jacobian_rows,
    jacobian_rows_along,
    sensitivities,
    sensitivities_along,
    sensitivity_at_end_along,
    trajectory_and_information,
    trajectory_and_sensitivities,
)
from backlashkit.papers.ravanbod2002 import A2, P_TRUE, THETA

#: Agreement asked of the two on paper A's drive (1.8e-10; ``-s`` prints the figures)...
RTOL = 1e-8
#: ... and on random drives: a median of 3e-10, but up to 1.4e-8: the jumps at changes
#: of low relative speed amplify the two exponentials' differing rounding (``-s``
#: prints the figures).
RANDOM_RTOL = 1e-7
#: Paper A's model's parameters, as the kernel indexes them.
LINEAR = list(range(len(LINEAR_AND_THETA)))


def _relative_error(drive, t, u) -> float:
    """Largest over the parameters of max |compiled - NumPy| / max |NumPy|."""
    fast, ref = sensitivities(drive, t, u), numpy_sensitivities(drive, t, u)
    assert fast.shape == ref.shape == (t.size, 2, len(default_params(drive)))
    return float(np.max(np.max(np.abs(fast - ref), axis=(0, 1))
                        / np.max(np.abs(ref), axis=(0, 1))))


def test_paper_drive_matches_numpy_twin():
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(3.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=1.5)
    err = _relative_error(drive, t, u)
    print(f"paper A's drive: compiled vs NumPy, largest relative difference {err:.2e}")
    assert err < RTOL


#: Issue 20's current loop, a time constant of 1 ms.
LOOP = bk.CurrentLoop(1e-3)
#: The current loop's time constants of the random drives, in s: a decade about a
#: drive's millisecond.
TAUS = st.floats(3e-4, 3e-3)
#: Random drives behind a loop, each kind's draws and least count checked away from
#: grazing (``-s`` prints the counts: the Coulomb kind comes near grazing more often,
#: 20 of 80 at its first draws). A clean-clone CI run at 7067943 checked 29 of the
#: Coulomb kind's 150 draws, where the same test alone checks 41 (why was not traced):
#: 200 draws leave that margin.
LOOP_KINDS = {"viscous": (st.just((0.0, 0.0)), 40, 25), "coulomb": (FRICTIONS, 200, 30)}


def _loop_error(drive, t, u, loop, **start) -> float:
    """Largest over the parameters of max |compiled - NumPy| / max |NumPy| behind
    ``loop``."""
    fast = sensitivities(drive, t, u, actuator=loop, **start)
    ref = numpy_sensitivities(drive, t, u, actuator=loop, **start)
    assert fast.shape == ref.shape == (t.size, 2, len(default_params(drive, loop)))
    return float(np.max(np.max(np.abs(fast - ref), axis=(0, 1))
                        / np.max(np.abs(ref), axis=(0, 1))))


def test_a_current_loop_matches_numpy_twin():
    """Behind issue 20's 1 ms loop, paper A's drive with its Coulomb torques: every
    column, ``tau_i``'s too, compiled against the twin, from the default start (rest,
    the loop settled at the first torque) and from the steady state with a
    sensitivity."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = bk.signals.time_grid(3.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=1.5)
    names = default_params(drive, LOOP)
    assert names[-1] == "tau_i"
    x0 = np.r_[drive.steady_state(A2), A2]
    values = np.array([LOOP.tau_i if n == "tau_i" else getattr(drive, n) for n in names])
    s0 = np.random.default_rng(5).standard_normal((4, len(names))) / values
    for start in ({}, {"initial_state": x0, "initial_sensitivity": s0}):
        err = _loop_error(drive, t, u, LOOP, **start)
        print(f"behind a 1 ms loop{', from a start' if start else ''}: compiled vs NumPy "
              f"{err:.2e}")
        assert err < RTOL


@pytest.mark.parametrize("kind", LOOP_KINDS)
def test_random_drives_behind_a_loop_match_numpy_twin(kind):
    """Random drives behind a random current loop, drawn as the others, compiled
    against the twin (which ``tests/test_sensitivity.py`` checks against the
    differences of the simulator with that loop)."""
    checked: list[float] = []
    frictions, draws, least = LOOP_KINDS[kind]

    @settings(max_examples=draws, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions, TAUS)
    def check(logs, level, friction, tau_i):
        drive, t, u = drive_record(logs, level, friction)
        loop = bk.CurrentLoop(tau_i)
        if near_grazing(drive.simulate(t, u, actuator=loop)):
            return
        err = _loop_error(drive, t, u, loop)
        assert err < RANDOM_RTOL
        checked.append(err)

    check()
    print(f"{kind} behind a loop: {len(checked)} of {draws} random drives checked, "
          f"largest difference {max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) >= least


def test_a_start_with_its_sensitivity_matches_numpy_twin():
    """From a moving state with a given sensitivity (a run that continues another):
    paper A's drive with Coulomb friction, kernel against twin, every column carrying
    its start."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = bk.signals.time_grid(1.5, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=0.5)
    x0 = drive.steady_state(A2)
    names = default_params(drive)
    s0 = np.random.default_rng(7).standard_normal((3, len(names)))
    s0 /= np.array([getattr(drive, n) for n in names])  # dx/dp of a relative step
    fast = sensitivities(drive, t, u, initial_state=x0, initial_sensitivity=s0)
    ref = numpy_sensitivities(drive, t, u, initial_state=x0, initial_sensitivity=s0)
    err = float(np.max(np.max(np.abs(fast - ref), axis=(0, 1))
                       / np.max(np.abs(ref), axis=(0, 1))))
    print(f"from a start with its sensitivity: compiled vs NumPy {err:.2e}")
    assert err < RTOL
    np.testing.assert_allclose(fast[0], s0[:2], rtol=1e-15)
    plain = sensitivities(drive, t, u, initial_state=x0)
    assert np.max(np.abs(fast - plain)) > 0.1 * np.max(np.abs(plain))


@pytest.mark.parametrize("kind", KINDS)
def test_random_drives_match_numpy_twin(kind):
    """Random drives drawn as in test_sensitivity.py, of each kind (with Coulomb
    friction, the stick, slip and breakaway changes too)."""
    checked: list[float] = []
    frictions, reversing, draws, least = KINDS[kind]

    @settings(max_examples=draws, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions)
    def check(logs, level, friction):
        drive, t, u = drive_record(logs, level, friction, reversing=reversing)
        if near_grazing(drive.simulate(t, u)):  # the jumps amplify rounding there
            return
        err = _relative_error(drive, t, u)
        assert err < RANDOM_RTOL
        checked.append(err)

    check()
    print(f"{kind}: {len(checked)} of {draws} random drives checked, largest "
          f"difference {max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) >= least


@pytest.mark.parametrize("kind", KINDS)
def test_random_drives_match_differences(kind):
    """The compiled sensitivities, the ones the fits and the bound use, against the
    extrapolated differences of ``tests/_differences.py`` on the random drives of each
    kind, within issue 24's bar; ``-s`` prints the count checked (how many are near
    grazing varies between pytest invocations: 79 of 100 in one, 97 of 120 in a
    clean CI clone, without friction, so ``_random_drives.KINDS`` leaves a margin)."""
    checked = []
    frictions, reversing, draws, least = KINDS[kind]

    @settings(max_examples=draws, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions)
    def check(logs, level, friction):
        drive, t, u = drive_record(logs, level, friction, reversing=reversing)
        with warnings.catch_warnings():  # near-grazing drives are skipped by agreement
            warnings.simplefilter("ignore", bk.SensitivityWarning)
            found = agreement(drive, t, u, sensitivities(drive, t, u))
        if found is not None:
            checked.append(found.error)

    check()
    print(f"{kind}: {len(checked)} of {draws} random drives checked against the "
          f"differences, largest error {max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) >= least
    check_bar(checked)


def _products(sens: np.ndarray) -> np.ndarray:
    """``sum_k s_c s_c^T`` of the sensitivities ``(n, 2, m)``: ``(2, m, m)``."""
    return np.einsum("kca,kcb->cab", sens, sens)


def _gram_error(got: np.ndarray, ref: np.ndarray) -> float:
    """Largest ``|got - ref|`` of the products, each over ``sqrt(ref_aa ref_bb)``."""
    diag = np.sqrt(np.einsum("caa->ca", ref))
    return float(np.max(np.abs(got - ref) / (diag[:, :, None] * diag[:, None, :])))


@pytest.mark.parametrize("kind", KINDS)
def test_random_drives_information_matches_numpy_twins_products(kind):
    """The speeds' sums of outer products that the kernel accumulates as it walks
    (the white-noise bound's, without the sensitivities written out) against the
    same sums of the NumPy twin's sensitivities, on the random drives of each kind,
    all columns and a subset out of order; and the states of the same run."""
    checked: list[float] = []
    frictions, reversing, draws, least = KINDS[kind]

    @settings(max_examples=draws // 4, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions)
    def check(logs, level, friction):
        drive, t, u = drive_record(logs, level, friction, reversing=reversing)
        if near_grazing(drive.simulate(t, u)):
            return
        for params in (default_params(drive), ("k_sh", "theta", "J_M")):
            x, gram = trajectory_and_information(drive, t, u, params=params)
            x_ref, sens = trajectory_and_sensitivities(drive, t, u, params=params)
            np.testing.assert_array_equal(x, x_ref)
            assert gram.shape == (2, len(params), len(params))
            np.testing.assert_array_equal(gram, gram.transpose(0, 2, 1))
            ref = _products(numpy_sensitivities(drive, t, u, params=params))
            checked.append(_gram_error(gram, ref))
            assert checked[-1] < 2 * RANDOM_RTOL

    check()
    print(f"{kind}: {len(checked) // 2} drives checked, largest difference "
          f"{max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) // 2 >= least // 4  # two sets of columns per drive


def _run_of(drive, t, u):
    """The compiled simulator's run of ``drive`` from rest, as the fit keeps it."""
    from backlashkit.identify._model import packed_row
    from backlashkit.simulate import simulate_packed_runs

    return simulate_packed_runs(2, packed_row(drive)[np.newaxis, :], float(t[0]),
                                float(t[1] - t[0]), u[np.newaxis, :], np.zeros((1, 3)),
                                law="paper", workers=1).run(0)


@pytest.mark.parametrize("kind", KINDS)
def test_random_drives_jacobian_rows_match_numpy_twins(kind):
    """The fit's Jacobian rows that the kernel writes as it walks
    (``jacobian_rows_along``: each selected sample's speed rows times a factor per
    column, divided by the speed's noise level) against the same rows of the NumPy
    twin's sensitivities (``jacobian_rows``), on the random drives of each kind, for
    two windows and for every sample; to the bit against the rows of the compiled
    sensitivities written out, and the end of a run (``sensitivity_at_end_along``,
    a held torque's) to the bit against their last row."""
    checked: list[float] = []
    frictions, reversing, draws, least = KINDS[kind]
    rng = np.random.default_rng(24)

    @settings(max_examples=draws // 4, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions)
    def check(logs, level, friction):
        drive, t, u = drive_record(logs, level, friction, reversing=reversing)
        if near_grazing(drive.simulate(t, u)):
            return
        run, names = _run_of(drive, t, u), default_params(drive)
        factor = -rng.uniform(0.5, 2.0, len(names))
        level2 = tuple(rng.uniform(1e-3, 1e-1, 2))
        sens = sensitivities_along(drive, run)
        twin = numpy_sensitivities(drive, t, u, params=names)
        scale = np.max(np.abs(jacobian_rows(twin, slice(None), factor, level2)), axis=0)
        n = t.size
        for selected in (np.r_[3 : n // 4, n // 2 : n // 2 + 40], np.arange(n)):
            out = np.full((2 * selected.size, len(names)), np.nan)
            got = jacobian_rows_along(drive, run, selected=selected, factor=factor,
                                      level=level2, out=out)
            assert got is out
            np.testing.assert_array_equal(got, jacobian_rows(sens, selected, factor, level2))
            ref = jacobian_rows(twin, selected, factor, level2)
            checked.append(float(np.max(np.abs(got - ref) / scale)))
            assert checked[-1] < RANDOM_RTOL
        np.testing.assert_array_equal(sensitivity_at_end_along(drive, run), sens[-1])

    check()
    print(f"{kind}: {len(checked) // 2} drives checked, largest difference "
          f"{max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) // 2 >= least // 4  # two selections per drive


def test_jacobian_rows_refuse_what_does_not_fit():
    """Samples out of order or past the run, a factor per column missing, a level of
    0 or an output of another shape or read-only: a one-line ValueError each."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = np.arange(400) * 2.0**-10
    run = _run_of(drive, t, bk.signals.step_down(t, A2, t_s=0.2))
    names = default_params(drive)
    good = {"selected": np.arange(5, 10), "factor": -np.ones(len(names)),
            "level": (0.01, 0.02), "out": np.empty((10, len(names)))}
    frozen = np.empty((10, len(names)))
    frozen.flags.writeable = False
    for change, match in (({"selected": np.arange(9, 4, -1)}, "increase strictly"),
                          ({"selected": np.r_[5:9, 400]}, "below the grid's 400"),
                          ({"factor": -np.ones(3)}, "7 finite values"),
                          ({"level": (0.0, 0.02)}, "finite and > 0"),
                          ({"out": np.empty((9, len(names)))}, r"shape \[10, 7\]"),
                          ({"out": frozen}, "writeable")):
        with pytest.raises(ValueError, match=match) as err:
            jacobian_rows_along(drive, run, **{**good, **change})
        assert "\n" not in str(err.value)


#: Relative steps of the twist's central differences (the best is kept per parameter:
#: the truncation falls with the step, the simulator's rounding grows as it shrinks)
#: and the agreement they resolve on the twist: under 1e-6 here, as on the speeds in
#: test_sensitivity.py (``-s`` prints it).
TWIST_STEPS, TWIST_RTOL = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8), 3e-6


def test_twist_matches_central_differences():
    """The twist's sensitivity (which the NumPy twin does not return) against central
    differences of the simulator; a given initial state at rest is the default."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(1.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=0.5)
    full = sensitivities(drive, t, u, states=True, initial_state=[0.0, 0.0, 0.0])
    assert full.shape == (t.size, 3, len(LINEAR_AND_THETA))
    np.testing.assert_array_equal(full[:, :2], sensitivities(drive, t, u))
    values = {n: getattr(drive, n) for n in LINEAR_AND_THETA}
    worst = 0.0
    for j, name in enumerate(LINEAR_AND_THETA):
        best = np.inf
        for h in TWIST_STEPS:
            hi, lo = (bk.TwoMassDrive(**{**values, name: values[name] * (1 + s * h)})
                      .simulate(t, u).states[:, 2] for s in (1.0, -1.0))
            fd = (hi - lo) / (2 * h * values[name])
            best = min(best, np.max(np.abs(fd - full[:, 2, j])) / np.max(np.abs(full[:, 2, j])))
        assert best < TWIST_RTOL, f"{name}: {best:.2e}"
        worst = max(worst, best)
    print(f"twist against central differences: largest error {worst:.2e}")


def test_a_subset_of_parameters_and_the_states():
    """The columns of some parameters are the full run's to the bit (the kernel carries
    only those), and the states the simulator's."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(3.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=1.5)
    full = sensitivities(drive, t, u, states=True)
    x, part = trajectory_and_sensitivities(drive, t, u, params=("theta", "f_M"))
    np.testing.assert_array_equal(part, full[:, :, [PARAMS.index("theta"),
                                                    PARAMS.index("f_M")]])
    np.testing.assert_array_equal(x, drive.simulate(t, u).states)


def test_bad_inputs_raise_value_error():
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(0.1, 1e-3)
    u = np.full(t.size, 0.1)
    p = np.array([*(getattr(drive, n) for n in PARAMS[:-1]), 0.0])  # tau_i 0: no loop
    with pytest.raises(ValueError, match=r"J\[0\] must be finite and > 0"):
        _core.drive_sensitivities(np.where(np.arange(10) == 0, -1.0, p), 0.0, 1e-3, u,
                                  np.zeros(3), LINEAR)
    with pytest.raises(ValueError, match="theta must be > 0"):
        _core.drive_sensitivities(np.where(np.arange(10) == 6, 0.0, p), 0.0, 1e-3, u,
                                  np.zeros(3), LINEAR)
    with pytest.raises(ValueError, match="tau_i must be finite and >= 0"):
        _core.drive_sensitivities(np.where(np.arange(10) == 9, -1.0, p), 0.0, 1e-3, u,
                                  np.zeros(3), LINEAR)
    with pytest.raises(ValueError, match="params must have 10 entries, got 6"):
        _core.drive_sensitivities(p[:6], 0.0, 1e-3, u, np.zeros(3), LINEAR)
    with pytest.raises(ValueError, match="initial state must have 3 entries"):
        _core.drive_sensitivities(p, 0.0, 1e-3, u, np.zeros(2), LINEAR)
    with pytest.raises(ValueError, match="sample time must be > 0"):
        _core.drive_sensitivities(p, 0.0, -1e-3, u, np.zeros(3), LINEAR)
    with pytest.raises(ValueError, match="distinct and below 10"):
        _core.drive_sensitivities(p, 0.0, 1e-3, u, np.zeros(3), [6, 6])
    with pytest.raises(ValueError, match="the sensitivity to fc_M needs fc_M > 0"):
        _core.drive_sensitivities(p, 0.0, 1e-3, u, np.zeros(3), [7])
    with pytest.raises(ValueError, match="the sensitivity to tau_i needs tau_i > 0"):
        _core.drive_sensitivities(p, 0.0, 1e-3, u, np.zeros(3), [9])
    loop = bk.CurrentLoop(1e-3)
    with pytest.raises(ValueError, match="the sensitivity to tau_i needs a current loop"):
        sensitivities(drive, t, u, params=("theta", "tau_i"))
    with pytest.raises(ValueError, match=r"initial_state must hold the 4 states \(w_M, w_L"):
        sensitivities(drive, t, u, actuator=loop, initial_state=np.zeros(3))
    with pytest.raises(ValueError, match=r"initial_sensitivity must have shape \(4, 8\)"):
        sensitivities(drive, t, u, actuator=loop, initial_sensitivity=np.zeros((3, 8)))
    with pytest.raises(ValueError, match="actuator must be None or a CurrentLoop"):
        sensitivities(drive, t, u, actuator=1e-3)
    with pytest.raises(ValueError, match="params must be distinct names"):
        sensitivities(drive, t, u, params=("theta", "k"))
    with pytest.raises(ValueError, match="one sample per time step"):
        sensitivities(drive, t, u[:-1])
    with pytest.raises(ValueError, match="fs_M equal to fc_M"):
        sensitivities(bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fs_M=0.02), t, u)
    with pytest.raises(ValueError, match="the sensitivity to fc_L needs fc_L > 0"):
        sensitivities(bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01), t, u,
                      params=("theta", "fc_L"))
    with pytest.raises(ValueError, match=r"initial_sensitivity must have shape \(3, 7\)"):
        sensitivities(drive, t, u, initial_sensitivity=np.zeros((2, 7)))
    with pytest.raises(ValueError, match="initial sensitivity must hold 3 x 1 finite values"):
        _core.drive_sensitivities(p, 0.0, 1e-3, u, np.zeros(3), [6], np.full((1, 1), 0.0))


def test_along_the_simulators_run_the_same_values_to_the_bit():
    """The joint fit's Jacobian follows the run its residual has just simulated
    (``sensitivities_along``): the same values to the bit as a run that simulates
    again, on paper A's step-down with both Coulomb torques (sticks and breakaways)
    and with the load's alone (its switch is the simulator's third), from a start with
    a sensitivity, and behind issue 20's current loop (four states); into an array
    given, as into a new one. A run that does not fit the drive, or an array of another
    shape, is a one-line ValueError."""
    from backlashkit.identify._model import packed_row
    from backlashkit.simulate import simulate_packed_runs

    ts = 2.0**-10  # a step that time_grid finds to the bit from the times
    t = np.arange(1537) * ts
    u = bk.signals.step_down(t, A2, t_s=0.75)
    cases = (({"fc_M": 0.01, "fc_L": 0.02}, None), ({"fc_L": 0.02}, None),
             ({"fc_M": 0.01, "fc_L": 0.02}, LOOP))
    for fc, loop in cases:
        drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, **fc)
        names = default_params(drive, loop)
        x0 = np.array([0.5, 0.4, 0.01, A2][: 3 if loop is None else 4])
        s0 = np.random.default_rng(3).standard_normal((x0.size, len(names)))
        row = packed_row(drive, 0.0 if loop is None else loop.tau_i)
        run = simulate_packed_runs(2, row[np.newaxis, :], 0.0, ts, u[np.newaxis, :],
                                   x0[np.newaxis, :], law="paper", workers=1).run(0)
        assert len(run.events) >= 4, run.events
        _, want = trajectory_and_sensitivities(drive, t, u, initial_state=x0,
                                               initial_sensitivity=s0, actuator=loop)
        got = sensitivities_along(drive, run, initial_sensitivity=s0, actuator=loop)
        assert np.array_equal(got, want), fc
        # into a kept array (NaN: every value is written), as the fit's Jacobians ask
        out = np.full(want.shape, np.nan)
        for _ in range(2):
            assert sensitivities_along(drive, run, initial_sensitivity=s0, out=out,
                                       actuator=loop) is out
            assert np.array_equal(out, want), fc
        end = sensitivity_at_end_along(drive, run, initial_sensitivity=s0, actuator=loop)
        assert np.array_equal(end, want[-1]), fc
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_L=0.02)
    run = simulate_packed_runs(2, packed_row(drive)[np.newaxis, :], 0.0, ts,
                               u[np.newaxis, :], np.zeros((1, 3)), law="paper",
                               workers=1).run(0)
    shapes = r"^out must have shape \[1537, 3, 8\], got \[1537, 3, 7\]$"
    with pytest.raises(ValueError, match=shapes):
        sensitivities_along(drive, run, out=np.empty((1537, 3, 7)))
    frozen = np.empty((1537, 3, 8))
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="^out must be a writeable array"):
        sensitivities_along(drive, run, out=frozen)
    for bad, match in ((run._replace(events=run.events[::-1]), "out of order"),
                       (run._replace(states=run.states[1:]), "finite states"),
                       (run._replace(first_modes=run.first_modes[:1]), "first sample's 2 "
                                                                       "modes")):
        with pytest.raises(ValueError, match=f"^the run given .*{match}"):
            sensitivities_along(drive, bad)


def _angle_error(drive, t, u, loop=None, s0=None) -> float:
    """Largest over the parameters of max |compiled - NumPy| / max |NumPy| of the
    sensitivities of the speeds and the motor's angle, the compiled ones along the
    simulator's run that tracks the angle (as the fit of encoder angles takes them),
    from rest (behind ``loop`` settled at the first torque) with sensitivity ``s0``."""
    from backlashkit.identify._model import packed_row
    from backlashkit.simulate import simulate_packed_runs

    x0 = np.zeros(5 if loop else 4)
    if loop is not None:
        x0[3] = u[0]
    row = packed_row(drive, 0.0 if loop is None else loop.tau_i)
    run = simulate_packed_runs(2, row[np.newaxis, :], t[0], t[1] - t[0], u[np.newaxis, :],
                               x0[np.newaxis, :], law="paper", workers=1,
                               track_angle=True).run(0)
    fast = sensitivities_along(drive, run, initial_sensitivity=s0, actuator=loop)
    ref = numpy_sensitivities(drive, t, u, actuator=loop, motor_angle=True,
                              initial_sensitivity=s0)
    assert fast.shape == (t.size, x0.size, len(default_params(drive, loop)))
    fast = fast[:, [0, 1, -1], :]
    return float(np.max(np.max(np.abs(fast - ref), axis=(0, 1))
                        / np.max(np.abs(ref), axis=(0, 1))))


def test_the_motor_angle_matches_numpy_twin():
    """An encoder's record is fitted as angles: the sensitivity of the motor's angle
    (one more state, which the simulator's run tracks), compiled against the twin, on
    paper A's drive, with its Coulomb torques, behind its current loop (five states),
    and from a start with a sensitivity; and on random drives with and without
    Coulomb friction, behind a loop or not. The twin's angle is checked against
    extrapolated differences in ``tests/test_sensitivity.py``, the kernel's in
    ``crates/core`` (``the_motor_angle_matches_central_differences``)."""
    t = bk.signals.time_grid(3.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=1.5)
    coulomb = {"fc_M": 0.01, "fc_L": 0.02}
    for fc, loop in (({}, None), (coulomb, None), (coulomb, LOOP)):
        drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, **fc)
        names = default_params(drive, loop)
        values = np.array([loop.tau_i if n == "tau_i" else getattr(drive, n) for n in names])
        s0 = np.random.default_rng(4).standard_normal((5 if loop else 4, len(names))) / values
        for start in (None, s0):
            err = _angle_error(drive, t, u, loop, start)
            print(f"the motor angle, {'Coulomb' if fc else 'viscous'}, "
                  f"{'a loop' if loop else 'no loop'}"
                  f"{', from a start' if start is not None else ''}: {err:.2e}")
            assert err < RTOL
    checked: list[float] = []

    @settings(max_examples=40, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, st.one_of(st.just((0.0, 0.0)), FRICTIONS),
           st.one_of(st.just(0.0), TAUS))
    def check(logs, level, friction, tau_i):
        drive, t, u = drive_record(logs, level, friction)
        loop = bk.CurrentLoop(tau_i) if tau_i else None
        if near_grazing(drive.simulate(t, u, actuator=loop)):
            return
        err = _angle_error(drive, t, u, loop)
        assert err < RANDOM_RTOL
        checked.append(err)

    check()
    print(f"the motor angle: {len(checked)} of 40 random drives checked, largest "
          f"difference {max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) >= 15


def _tangent_case(margin_rel: float):
    """test_simulate.py's free flight towards the positive flank whose twist peaks at
    ``theta (1 - margin_rel)``, at 25.5 ms (no friction, constant torque)."""
    jm, w0, theta = 0.01, 1.0, 0.02
    a = jm * w0 / 0.0255
    drive = bk.TwoMassDrive(J_M=jm, J_L=1.0, k_sh=100.0, f_M=0.0, f_L=0.0, f_sh=0.0,
                            theta=theta)
    phi0 = theta - w0**2 * jm / (2 * a) - margin_rel * theta
    t = np.arange(50) * 1e-3
    return drive, t, np.full(t.size, -a), [w0, 0.0, phi0]


def test_near_grazing_warns_as_the_simulator():
    """A pass within 1e-9 of the flank warns; a clear miss does not, and its
    sensitivities (zero frictions: plain derivatives) are finite."""
    drive, t, u, x0 = _tangent_case(1e-9)
    with pytest.warns(bk.SensitivityWarning, match="grazing"):
        sensitivities(drive, t, u, initial_state=x0)
    drive, t, u, x0 = _tangent_case(1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = sensitivities(drive, t, u, initial_state=x0, states=True)
    assert np.isfinite(out).all()
