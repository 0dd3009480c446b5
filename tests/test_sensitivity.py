"""Forward sensitivities of the NumPy reference (issue 24) against central differences
of the compiled simulator, whose contact changes are located independently.

Central differences are themselves only so accurate: the error of a step ``h`` falls
like ``h`` while the simulator's rounding and event location grow like ``1 / h``. Each
column is compared with the best of three steps.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

import backlashkit as bk
from _random_drives import LEVELS, LOG_FACTORS, drive_record
from backlashkit._numpy_sensitivity import PARAMS, sensitivities
from backlashkit.papers.ravanbod2002 import A2, P_TRUE, THETA

#: Relative steps of the central differences.
STEPS = (1e-5, 1e-6, 1e-7, 1e-8)
#: A drive whose shaft meets or leaves a flank at a relative speed below this share of
#: its largest is near grazing, where the speeds are not smooth in the parameters and
#: the differences scatter (3e-3 at every step on one such drive, 2.6 %): not checked.
GRAZING = 0.05
#: Issue 24's bar, met on paper A's drive (``-s`` prints the largest error)...
PAPER_RTOL = 1e-6
#: ... and, on random drives, what the best of the differences resolves: up to 1e-4
#: where the sensitivities are large and curved (the O(h) error of the differences
#: grows with the curvature), a median of 2e-6 (``-s`` prints both).
RANDOM_RTOL, RANDOM_MEDIAN_RTOL = 3e-4, 1e-5
#: Random drives checked (issue 24: at least 100), of EXAMPLES drawn (some are near
#: grazing, and how many varies between pytest invocations: the draw leaves a margin).
N_DRIVES, EXAMPLES = 100, 150


def _worst_error(drive: bk.TwoMassDrive, t, u) -> float | None:
    """Largest over the parameters of the best step's max |FD - S| / max |S|; None near
    grazing (:data:`GRAZING`, or a step changes the number of contact changes)."""
    sens = sensitivities(drive, t, u)
    res = drive.simulate(t, u)
    n_events = len(res.contact_events)
    rel = res.w_motor - res.w_load
    if min(abs(np.interp(e.time, t, rel)) for e in res.contact_events) < GRAZING * np.max(
            np.abs(rel)):
        return None
    values = {n: getattr(drive, n) for n in PARAMS}
    worst = 0.0
    for j, name in enumerate(PARAMS):
        best = np.inf
        for h in STEPS:
            runs = [bk.TwoMassDrive(**{**values, name: values[name] * (1 + s * h)})
                    .simulate(t, u) for s in (1.0, -1.0)]
            if any(len(r.contact_events) != n_events for r in runs):
                return None
            fd = np.stack([runs[0].w_motor - runs[1].w_motor,
                           runs[0].w_load - runs[1].w_load], axis=1) / (2 * h * values[name])
            best = min(best, np.max(np.abs(fd - sens[:, :, j])) / np.max(np.abs(sens[:, :, j])))
        worst = max(worst, best)
    return worst


def test_paper_drive_within_issue_24_bar():
    """Paper A's drive, stepped down from 0.942 N m: every parameter's sensitivity
    within 1e-6 of the central differences, across 46 contact changes."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(3.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=1.5)
    assert len(drive.simulate(t, u).contact_events) == 46
    err = _worst_error(drive, t, u)
    print(f"paper A's drive: largest error {err:.2e}")
    assert err < PAPER_RTOL


def test_random_drives():
    """Random drives (each parameter within a factor 2 of paper A's, a random torque
    level): the sensitivities agree with the differences; the count of drives checked
    is printed and at least N_DRIVES."""
    checked: list[float] = []

    @settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS)
    def check(logs, level):
        drive, t, u = drive_record(logs, level)
        err = _worst_error(drive, t, u)
        if err is not None:
            assert err < RANDOM_RTOL, f"{drive} {level} {err:.2e}"
            checked.append(err)

    check()
    print(f"{len(checked)} of {EXAMPLES} random drives checked (the others near grazing), "
          f"largest error {max(checked):.2e}, median {np.median(checked):.2e}")
    assert len(checked) >= N_DRIVES
    assert np.median(checked) < RANDOM_MEDIAN_RTOL


def test_saltation_matters():
    """Without the jumps at the contact changes the sensitivities are wrong (the test
    above could not pass with them dropped)."""
    import backlashkit._numpy_sensitivity as ns

    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(1.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=0.5)
    good = sensitivities(drive, t, u)
    real = ns.saltation
    ns.saltation = lambda p, z, *args: z
    try:
        bad = sensitivities(drive, t, u)
    finally:
        ns.saltation = real
    theta_col = PARAMS.index("theta")
    # paper A's damper is light, so the field jumps by little
    moved = np.max(np.abs(bad[:, :, theta_col] - good[:, :, theta_col])) / np.max(
        np.abs(good[:, :, theta_col]))
    print(f"without the saltation, dw/dtheta moves by {moved:.1%} of its largest value")
    assert moved > 1e-2


@pytest.mark.parametrize("name", PARAMS)
def test_params_order_is_the_drives(name):
    assert hasattr(bk.TwoMassDrive(**P_TRUE, theta=THETA), name)
