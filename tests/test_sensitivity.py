"""Forward sensitivities of the NumPy reference (issue 24) against extrapolated central
differences of the compiled simulator, whose contact changes are located independently
(``tests/_differences.py`` says how the differences are made and which samples they
leave out).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import backlashkit as bk
from _differences import BAR, agreement, check_bar, near_grazing
from _random_drives import FRICTIONS, KINDS, LEVELS, LOG_FACTORS, drive_record
from backlashkit._numpy_sensitivity import LOOP_STATES, PARAMS, sensitivities
from backlashkit._sensitivity import default_params
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
    assert sens.shape == (t.size, 2, len(PARAMS) - 1)  # no tau_i without a loop
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
    """Every parameter but the loop's is the drive's; ``tau_i`` the current loop's."""
    owner = bk.CurrentLoop(1e-3) if name == "tau_i" else bk.TwoMassDrive(**P_TRUE, theta=THETA)
    assert hasattr(owner, name)


#: The current loop's time constants drawn, in s: about a millisecond is a drive's
#: (backlashkit.actuator), a decade around it.
TAUS = st.floats(3e-4, 3e-3)
#: Each kind of record drawn behind a current loop: ``(Coulomb torques, reversing,
#: draws, least count checked)``, as ``_random_drives.KINDS`` with fewer draws (ten
#: columns, each differenced at every step). Checked at the draws here: 6 of 8, 13 of
#: 30 and 7 of 60 from rest, 8, 10 and 6 from a given start (``-s`` prints them).
LOOP_KINDS = {
    "viscous": (st.just((0.0, 0.0)), False, 8, 5),
    "coulomb": (FRICTIONS, False, 30, 5),
    "coulomb-reversing": (FRICTIONS, True, 60, 4),
}
#: A given start's speeds in rad/s without Coulomb friction: both inertias moving
#: forwards, far enough from 0 that the differences' largest steps of the state
#: (:func:`given_start`) keep them so.
START_SPEEDS = (1.0, 5.0)
#: A given start's load speed as a share of the motor's, its twist as a share of the
#: backlash (inside the gap, clear of the flanks) and its motor torque in N m, or with
#: Coulomb friction as a share of the motor's Coulomb torque (the motor stuck).
START_LOAD, START_TWIST, START_TORQUE = (0.8, 1.2), (-0.5, 0.5), (-0.5, 0.5)
#: How far a given start's sensitivity moves each state, per unit relative step of a
#: parameter (one standard deviation; the twist's in units of the backlash, the torque's
#: of :data:`START_TORQUE`'s): at the differences' largest step (0.1) a tenth of the
#: speeds' least, of the twist's margin to a flank and of the torques drawn.
START_MOVES = np.array([1.0, 1.0, 0.5, 0.5])
#: Rest behind a current loop with the loop's torque at 0: ``[w_M, w_L, phi, T]`` all 0
#: (the default, as the simulator's, settles ``T`` at the first set-point instead).
REST = np.zeros(len(LOOP_STATES))


def given_start(drive: bk.TwoMassDrive, loop: bk.CurrentLoop, seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """A start ``[w_M, w_L, phi, T]`` and a random sensitivity ``(4, len(params))`` to
    the default parameters (:data:`START_MOVES`), drawn from ``seed``: without Coulomb
    friction mid-motion (:data:`START_SPEEDS` and the ranges after it); with it both
    inertias stuck (their speeds and the speeds' sensitivities 0) and the motor torque
    within its Coulomb torque, so that the loop's rise breaks the motor away at a time
    that the start's sensitivity moves."""
    rng = np.random.default_rng(seed)
    w_m = rng.uniform(*START_SPEEDS)
    x0 = np.array([w_m, w_m * rng.uniform(*START_LOAD),
                   rng.uniform(*START_TWIST) * drive.theta, rng.uniform(*START_TORQUE)])
    units = np.array([1.0, 1.0, drive.theta, 1.0])
    if drive.fc_M > 0:
        units = np.array([0.0, 0.0, drive.theta, drive.fc_M])
        x0[:2], x0[3] = 0.0, x0[3] * drive.fc_M
    names = default_params(drive, loop)
    values = np.array([loop.tau_i if n == "tau_i" else getattr(drive, n) for n in names])
    moves = (START_MOVES * units)[:, None] / values
    return x0, rng.normal(size=(len(LOOP_STATES), len(names))) * moves


def loop_draws(kind: str, start: bool) -> list[tuple]:
    """The random drives of ``kind`` (:data:`LOOP_KINDS`) behind a random current loop,
    from rest (:data:`REST`, ``T = 0`` too) or from :func:`given_start`: each
    checked one's agreement with the differences, contact changes, and (sticks,
    breakaways)."""
    frictions, reversing, draws, _ = LOOP_KINDS[kind]
    checked = []

    @settings(max_examples=draws, derandomize=True, deadline=None, database=None)
    @given(LOG_FACTORS, LEVELS, frictions, TAUS, st.integers(0, 2**32 - 1))
    def check(logs, level, friction, tau_i, seed):
        drive, t, u = drive_record(logs, level, friction, reversing=reversing)
        loop = bk.CurrentLoop(tau_i)
        x0, s0 = given_start(drive, loop, seed) if start else (REST, None)
        res = drive.simulate(t, u, actuator=loop, initial_state=x0)
        if near_grazing(res):  # agreement leaves it out: the twin's run spared
            return
        sens = sensitivities(drive, t, u, actuator=loop, initial_state=x0,
                             initial_sensitivity=s0)
        found = agreement(drive, t, u, sens, actuator=loop, initial_state=x0,
                          initial_sensitivity=s0)
        if found is not None:
            checked.append((found, len(res.contact_events), friction_changes(res)))

    check()
    return checked


#: The kinds drawn, each from rest and from a given start (:func:`given_start`).
LOOP_DRAWS = [(kind, start) for start in (False, True) for kind in LOOP_KINDS]
#: The contact changes each checked record must cross: several (the records drawn and
#: checked cross 18 to 68).
SEVERAL_CONTACTS = 5


@pytest.mark.parametrize(("kind", "start"), LOOP_DRAWS,
                         ids=[f"{k}-{'start' if s else 'rest'}" for k, s in LOOP_DRAWS])
def test_current_loop_random_drives(kind, start):
    """Random drives behind a current loop of 0.3 to 3 ms, from rest or from a given
    state and sensitivity: every column, ``tau_i``'s too, within issue 24's bar of the
    differences of the simulator with that loop; several contact changes each, and
    with friction sticks and breakaways (the loop's torque crossing the breakaway
    torque, located)."""
    checked = loop_draws(kind, start)
    errors = [found.error for found, _, _ in checked]
    tau_i = max(found.columns["tau_i"] for found, _, _ in checked)
    others = max(max(e for n, e in found.columns.items() if n != "tau_i")
                 for found, _, _ in checked)
    contacts = [n for _, n, _ in checked]
    changes = np.sum([c for _, _, c in checked], axis=0)
    print(f"{kind} behind a loop from {'a given start' if start else 'rest'}: "
          f"{len(checked)} of {LOOP_KINDS[kind][2]} checked, largest error {max(errors):.2e} "
          f"(tau_i {tau_i:.2e}, the others {others:.2e}); {min(contacts)} to "
          f"{max(contacts)} contact changes; {changes[0]} sticks, {changes[1]} breakaways")
    assert len(checked) >= LOOP_KINDS[kind][3]
    check_bar(errors)
    assert min(contacts) >= SEVERAL_CONTACTS
    if LOOP_KINDS[kind][1]:  # reversing
        assert changes.min() > 0
    elif kind == "coulomb":
        assert changes[1] > 0


def test_current_loop_on_the_paper_drive():
    """Paper A's drive with issue 20's Coulomb torques behind a 1 ms loop, from rest
    (``T = 0``), 0.3 N m for 0.375 s, -0.3 N m for as long, then 0 until 1.5 s: the ten
    columns within the bar across two sticks, three breakaways and 24 contact
    changes."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = bk.signals.time_grid(1.5, 1e-3)
    u = np.select([t < 0.375, t < 0.75], [0.3, -0.3], 0.0)
    loop = bk.CurrentLoop(1e-3)
    res = drive.simulate(t, u, actuator=loop, initial_state=REST)
    assert friction_changes(res) == (2, 3) and len(res.contact_events) == 24
    sens = sensitivities(drive, t, u, actuator=loop, initial_state=REST)
    assert sens.shape == (t.size, 2, len(PARAMS))
    # the default start is the simulator's: rest with the loop settled at u[0]
    settled = sensitivities(drive, t, u, actuator=loop, initial_state=np.r_[0, 0, 0, u[0]])
    assert sensitivities(drive, t, u, actuator=loop).tobytes() == settled.tobytes()
    found = agreement(drive, t, u, sens, actuator=loop, initial_state=REST)
    print(f"paper A's drive behind a 1 ms loop: largest error {found.error:.2e}, tau_i's "
          f"{found.columns['tau_i']:.2e}")
    assert found.error < BAR


def test_the_motor_angle_on_the_paper_drive():
    """The motor's angle (an encoder's record, fitted as angles), one more state:
    paper A's step-down, and its drive with issue 20's Coulomb torques behind a 1 ms
    loop through sticks and breakaways (the record of
    :func:`test_current_loop_on_the_paper_drive`); every column of the speeds and the
    angle within the bar of the simulator's extrapolated differences (its angle tracked
    in the run), and the speeds' columns those of the twin without the angle, to
    rounding."""
    rough = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    long, short = bk.signals.time_grid(3.0, 1e-3), bk.signals.time_grid(1.5, 1e-3)
    cases = (("paper A's step-down", bk.TwoMassDrive(**P_TRUE, theta=THETA), None, long,
              bk.signals.step_down(long, A2, t_s=1.5)),
             ("Coulomb, a 1 ms loop", rough, bk.CurrentLoop(1e-3), short,
              np.select([short < 0.375, short < 0.75], [0.3, -0.3], 0.0)))
    for what, drive, loop, t, u in cases:
        x0 = None if loop is None else REST  # the loop's record from T = 0, as there
        with_angle = None if x0 is None else np.r_[x0, 0.0]
        sens = sensitivities(drive, t, u, actuator=loop, motor_angle=True,
                             initial_state=with_angle)
        assert sens.shape == (t.size, 3, len(default_params(drive, loop)))
        plain = sensitivities(drive, t, u, actuator=loop, initial_state=x0)
        # to rounding (SciPy's exponential of a larger matrix; 5e-10 at the sticks)
        np.testing.assert_allclose(sens[:, :2], plain, rtol=0, atol=1e-8 * np.max(np.abs(plain)))
        found = agreement(drive, t, u, sens, actuator=loop, motor_angle=True,
                          initial_state=x0)
        print(f"the motor angle, {what}: largest error {found.error:.2e}")
        assert found.error < BAR


def test_without_a_loop_unchanged():
    """No actuator, ``actuator=None`` and ``CurrentLoop(0.0)`` (the set-point applied
    exactly): the same sensitivities to the bit, the three-state run's (the twin at
    70b711b, before the loop, gave these very values from both starts, and on 16 other
    records)."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = bk.signals.time_grid(1.5, 1e-3)
    u = np.select([t < 0.375, t < 0.75], [0.3, -0.3], 0.0)
    x0, s0 = [0.5, 0.4, 0.01], np.linspace(-0.1, 0.1, 27).reshape(3, 9)
    for start in ({}, {"initial_state": x0, "initial_sensitivity": s0}):
        plain = sensitivities(drive, t, u, **start)
        for actuator in (None, bk.CurrentLoop(0.0)):
            same = sensitivities(drive, t, u, actuator=actuator, **start)
            assert same.tobytes() == plain.tobytes()


def test_current_loop_refusals():
    """``tau_i`` without a loop, and a start of the wrong size with one: one-line
    InputErrors that name what is wrong."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01)
    t = bk.signals.time_grid(0.1, 1e-3)
    u, loop = np.full(t.size, 0.1), bk.CurrentLoop(1e-3)
    wrong = [({"params": ("theta", "tau_i")}, "tau_i needs a current loop"),
             ({"params": ("tau_i",), "actuator": bk.CurrentLoop(0.0)},
              "tau_i needs a current loop"),
             ({"actuator": 1e-3}, "actuator must be a CurrentLoop or None, got float"),
             ({"actuator": loop, "initial_state": [0.1, 0.1, 0.0]},
              r"initial_state must have 4 entries \[w_M, w_L, phi, T\], got shape \(3,\)"),
             ({"initial_state": [0.1, 0.1, 0.0, 0.2]}, "initial_state must have 3 entries"),
             ({"actuator": loop, "initial_sensitivity": np.zeros((3, 9))},
              r"initial_sensitivity must have shape \(4, 9\) \(states \[w_M, w_L, phi, T\]")]
    for kwargs, message in wrong:
        with pytest.raises(InputError, match=message) as err:
            sensitivities(drive, t, u, **kwargs)
        assert "\n" not in str(err.value)
    assert sensitivities(drive, t, u, actuator=loop).shape == (t.size, 2, 9)  # fc_L out
