"""Forward sensitivities of the NumPy reference (issue 24) against extrapolated central
differences of the compiled simulator, whose contact changes are located independently
(``tests/_differences.py`` says how the differences are made and which samples they
leave out).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

import backlashkit as bk
from _differences import BAR, agreement, check_bar
from _random_drives import KINDS, LEVELS, LOG_FACTORS, drive_record
from backlashkit._numpy_sensitivity import PARAMS, sensitivities
from backlashkit.errors import InputError
from backlashkit.papers.ravanbod2002 import A2, P_TRUE, THETA


def test_paper_drive_within_issue_24_bar():
    """Paper A's drive, stepped down from 0.942 N m: every parameter's sensitivity
    within 1e-6 of the differences, across 46 contact changes."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(3.0, 1e-3)
    u = bk.signals.step_down(t, A2, t_s=1.5)
    assert len(drive.simulate(t, u).contact_events) == 46
    found = agreement(drive, t, u, sensitivities(drive, t, u))
    print(f"paper A's drive: largest error {found.error:.2e}, {found.left_out} of "
          f"{found.samples} samples left out")
    assert found.error < BAR


def friction_changes(res: bk.DriveResponse) -> tuple[int, int]:
    """The sticks and breakaways among ``res``'s changes (rows of a friction switch:
    to 0, from 0)."""
    rows = res.event_array
    switch = rows[:, 1] > 0
    return int(np.sum(switch & (rows[:, 3] == 0))), int(np.sum(switch & (rows[:, 2] == 0)))


@pytest.mark.parametrize("kind", KINDS)
def test_random_drives(kind):
    """Random drives (each parameter within a factor 2 of paper A's, a random torque
    level, with or without Coulomb friction): the sensitivities agree with the
    differences within issue 24's bar; the count of drives checked is printed and at
    least the kind's (``_random_drives.KINDS``), and with friction the checked records
    stick or break away."""
    frictions, reversing, draws, least = KINDS[kind]
    checked, changes = [], np.zeros(2, int)

    @settings(max_examples=draws, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions)
    def check(logs, level, friction):
        drive, t, u = drive_record(logs, level, friction, reversing=reversing)
        found = agreement(drive, t, u, sensitivities(drive, t, u))
        if found is not None:
            checked.append(found)
            changes[:] += friction_changes(drive.simulate(t, u))

    check()
    errors = [c.error for c in checked]
    print(f"{kind}: {len(checked)} of {draws} random drives checked (the others near "
          f"grazing), largest error {max(errors):.2e}, median {np.median(errors):.2e}; "
          f"{sum(c.left_out for c in checked)} of {sum(c.samples for c in checked)} "
          "samples left out (a change crossed them between the differences' runs); "
          f"{changes[0]} sticks, {changes[1]} breakaways")
    assert len(checked) >= least
    check_bar(errors)
    if reversing:
        assert changes.min() > 0
    elif kind == "coulomb":
        assert changes[1] > 0


def test_coulomb_torques_column_on_the_paper_drive():
    """Paper A's drive with issue 20's Coulomb torques (0.01 and 0.02 N m), 0.3 N m for
    0.375 s from rest, -0.3 N m for as long, then 0 until 1.5 s: the nine columns, the
    Coulomb torques' too, within the bar across two sticks, two breakaways and 24
    contact changes."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = bk.signals.time_grid(1.5, 1e-3)
    u = np.select([t < 0.375, t < 0.75], [0.3, -0.3], 0.0)
    res = drive.simulate(t, u)
    assert friction_changes(res) == (2, 2) and len(res.contact_events) == 24
    sens = sensitivities(drive, t, u)
    assert sens.shape == (t.size, 2, len(PARAMS))
    found = agreement(drive, t, u, sens)
    print(f"paper A's drive with Coulomb friction: largest error {found.error:.2e}")
    assert found.error < BAR


def test_bad_inputs():
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01)
    t = bk.signals.time_grid(0.1, 1e-3)
    u = np.full(t.size, 0.1)
    with pytest.raises(InputError, match="fs_M = 0.02 differs from fc_M = 0.01"):
        sensitivities(bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fs_M=0.02), t, u)
    with pytest.raises(InputError, match="fc_L is 0"):
        sensitivities(drive, t, u, params=("theta", "fc_L"))
    with pytest.raises(InputError, match="params must be distinct names"):
        sensitivities(drive, t, u, params=("theta", "theta"))
    assert sensitivities(drive, t, u).shape == (t.size, 2, 8)  # fc_L left out


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
