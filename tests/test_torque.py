"""A noisy measured torque (``backlashkit.identify.torque``): detected, refused, or levelled.

The records: paper A's drive, step 1 (0.157 N m held 40 s from rest, then 0; 80 s at
1 ms), 30 dB on both speeds, as ``backlashkit simulate`` writes them; the torque with
white noise added as a current sensor would.
"""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

import backlashkit as bk
import backlashkit.identify.torque as torque_module
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.errors import InputError
from backlashkit.identify import find_step_down
from backlashkit.identify.torque import check_torque_noise, torque_levels, torque_noise_std
from backlashkit.io import write_csv

P = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
PRIOR = bk.TwoMassDrive(**P)
THETA = 3.49e-2
DRIVE_TOML = str(__import__("pathlib").Path(__file__).resolve().parents[1] / "examples"
                 / "paper_drive.toml")


@pytest.fixture(scope="module")
def step1():
    t = signals.time_grid(80.0, 1e-3)
    r = PRIOR.with_theta(THETA).simulate(t, signals.step_down(t, 0.157, t_s=40.0))
    sm, sl = np.random.SeedSequence(1).spawn(2)
    return bk.Record(t, r.torque, signals.add_noise(r.w_motor, 30.0, rng=sm),
                     signals.add_noise(r.w_load, 30.0, rng=sl), name="step1")


def _noisy(rec, std, seed=11, name="noisy"):
    u = rec.torque + std * np.random.default_rng(seed).standard_normal(rec.t.size)
    return bk.Record(rec.t, u, rec.w_motor, rec.w_load, name=name)


def test_noise_std_of_steps_sines_and_noise():
    t = np.arange(0.0, 10.0, 1e-3)
    steps = np.where(t < 5.0, 0.157, 0.0)
    assert torque_noise_std(steps) == 0.0
    ramp = np.clip(0.157 * (5.05 - t) / 0.05, 0.0, 0.157)  # a 50 ms ramp-down
    assert torque_noise_std(ramp) == 0.0
    assert torque_noise_std(0.2 * np.sin(2.0 * t)) < 1e-5 * 0.2  # 4e-6 A in second differences
    noisy = steps + 1e-3 * np.random.default_rng(0).standard_normal(t.size)
    assert torque_noise_std(noisy) == pytest.approx(1e-3, rel=0.05)


def test_noisy_torque_is_refused_by_every_identifier(step1):
    rec = _noisy(step1, 1e-3)
    message = (r"^noisy: the torque is noisy \(std about 0\.001\d* N m, 0\.6\d % of its largest "
               r"value\): the model takes the torque as its exact input .*levels "
               r"\(backlashkit\.torque_levels\)$")
    for est in (bk.JointIdentifier(PRIOR), bk.TwoStepIdentifier(PRIOR),
                bk.RegressionIdentifier(PRIOR)):
        with pytest.raises(InputError, match=message):
            est.fit(rec)
    check_torque_noise(_noisy(step1, 0.5e-3 * 0.157 * 0.9))  # just under the limit


#: The least share of the fit's standard error without torque noise that 0.3 mN m of it
#: leaves (:func:`test_why_the_limit`): where the model begins to rattle on the noise.
SHRUNK_BY_HALF = 0.5
#: 1 mN m of it: a standard error below this share of the fit's without noise, with
#: the truth more than BROKEN_MISS of them away, is an interval that means nothing
#: (x0.0021 and 164 of them at 4f56782; x0.084 and 23 with the packages of 2026-12-07,
#: at 70b711b's build as at 5b16e0a's: where the search ends among the rattle's contact
#: changes moves with the machine's rounding).
BROKEN_SHARE = 0.2
BROKEN_MISS = 10.0


def test_why_the_limit(step1, monkeypatch):
    """With the check lifted: 0.2 mN m of torque noise (0.13 % of the step) leaves the
    joint fit within a fraction of a standard error of the fit without noise and its
    standard error within 10 %; 0.3 mN m (0.19 %) still leaves theta there, but its
    standard error shrinks by up to half where the search's path ends among the
    contact changes the model makes of the noise, and the rounding of the machine
    decides that path (NumPy and its BLAS choose their kernels by processor): the same
    code, 59f9a66, gave x0.54 on the AVX-512 machine of 2026-12-06 and within 10 % on
    earlier sessions' machines (x0.62 before 0e5cc03); 1 mN m shrinks it ten to tens
    of thousands of times with the truth tens to thousands of them away (the model
    rattles on the noise; x0.0021 and 164 of them at 4f56782, x0.084 and 23 with the
    packages of 2026-12-07), which is why there is a limit, at 0.05 %.

    The standard error is from the exact sensitivities' Fisher information. Central
    differences across the rattling contact changes shrank it further, 4.4 times at
    0.3 mN m with numpy 2.4.6 (18 times with an earlier numpy): a step that adds or
    drops a change measures a jump, not a derivative. ``python -m pytest
    tests/test_torque.py -k why_the_limit -s`` prints the figures."""
    monkeypatch.setattr(torque_module, "TORQUE_NOISE_LIMIT", 1.0)
    fisher = bk.FisherInterval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bk.CorrelatedResidualsWarning)
        clean = bk.JointIdentifier(PRIOR, interval=fisher).fit(step1)
        fine = bk.JointIdentifier(PRIOR, interval=fisher).fit(_noisy(step1, 2e-4))
        shrunk = bk.JointIdentifier(PRIOR, interval=fisher).fit(_noisy(step1, 3e-4))
        broken = bk.JointIdentifier(PRIOR, interval=fisher).fit(_noisy(step1, 1e-3))
    for name, fit in (("0.2 mN m", fine), ("0.3 mN m", shrunk), ("1 mN m", broken)):
        print(f"\n{name}: theta moved {(fit.theta_ - clean.theta_) / clean.std_:+.3f} "
              f"standard errors, standard error x{fit.std_ / clean.std_:.4g}, the truth "
              f"{abs(fit.theta_ - THETA) / fit.std_:.3g} of its own away")
    assert abs(fine.theta_ - clean.theta_) < 0.25 * clean.std_
    assert fine.std_ == pytest.approx(clean.std_, rel=0.1)
    assert abs(shrunk.theta_ - clean.theta_) < 0.25 * clean.std_
    assert SHRUNK_BY_HALF * clean.std_ < shrunk.std_ < 1.1 * clean.std_
    assert broken.std_ < BROKEN_SHARE * clean.std_
    assert abs(broken.theta_ - THETA) > BROKEN_MISS * broken.std_


def test_levels_restore_the_clean_answer(step1):
    noisy = _noisy(step1, 3e-3)
    levelled = torque_levels(noisy)
    assert levelled.name == "noisy"
    assert np.unique(levelled.torque).size == 2
    assert find_step_down(levelled)[1] == 40.0
    assert np.max(np.abs(levelled.torque - step1.torque)) < 3e-4  # medians of 40 000
    assert torque_levels(step1) is step1  # already piecewise constant
    fisher = bk.FisherInterval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bk.CorrelatedResidualsWarning)
        clean = bk.JointIdentifier(PRIOR, interval=fisher).fit(step1)
        fit = bk.JointIdentifier(PRIOR, interval=fisher).fit(levelled)
    assert abs(fit.theta_ - clean.theta_) < 0.2 * clean.std_
    assert fit.std_ == pytest.approx(clean.std_, rel=0.05)


def test_a_noisy_step_up_has_no_step_down(step1):
    """Any noisy torque drops somewhere: a drop within the noise is no step-down."""
    t = step1.t
    up = np.where(t >= 1.0, 0.157, 0.0) + 3e-3 * np.random.default_rng(2).standard_normal(t.size)
    rec = bk.Record(t, up, step1.w_motor, step1.w_load, name="up")
    with pytest.raises(InputError, match=r"^up: the torque has no step-down beyond its noise "
                                         r"\(largest drop 0\.0\d+ N m at t = "):
        find_step_down(rec)
    with pytest.raises(InputError, match=r"^up: the torque has no step-down \(a drop"):
        find_step_down(torque_levels(rec))


def test_cli_refuses_a_noisy_torque_and_levels_it_on_request(step1, tmp_path, capsys):
    noisy = _noisy(step1, 3e-3)
    path = tmp_path / "measured.csv"
    write_csv(path, {"t": noisy.t, "torque": noisy.torque, "w_motor": noisy.w_motor,
                     "w_load": noisy.w_load})
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--interval", "fisher"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the torque is noisy" in err and "--torque-levels" in err
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--torque-levels", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert re.fullmatch(rf"{re.escape(str(path))}: torque replaced by its 2 piecewise-constant "
                        r"levels \(the removed noise has an rms of 0\.003\d* N m\)",
                        doc["notes"][0]), doc["notes"]
    assert abs(doc["theta"] - THETA) < 3 * doc["std"]


def test_levels_of_a_slow_noisy_ramp_are_refused(step1, tmp_path, capsys):
    """A 50 ms ramp through 3 mN m of noise changes less per sample than the noise:
    --torque-levels cannot see the step and says so."""
    t = step1.t
    ramp = np.clip(0.157 * (40.05 - t) / 0.05, 0.0, 0.157)
    u = ramp + 3e-3 * np.random.default_rng(0).standard_normal(t.size)
    path = tmp_path / "ramp.csv"
    write_csv(path, {"t": t, "torque": u, "w_motor": step1.w_motor, "w_load": step1.w_load})
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--torque-levels"]) == 2
    err = capsys.readouterr().err
    assert "--torque-levels found one level only" in err and err.count("\n") == 1


def test_levels_refuse_a_ramp_inside_a_level(step1):
    """A torque that ramps up over 1 s and then steps down would be levelled into a
    step at t = 0 (the model driven by it starts 1 s early): refused with the span; a
    50 ms ramp through noise (one level) too. Steps through white or filtered noise
    are levelled (noise filtered over 10-200 samples: 4 x 10 records)."""
    from scipy.signal import lfilter

    t = step1.t
    rng = np.random.default_rng(5)
    up = np.clip(0.157 * t, 0.0, 0.157) * (t < 40.0) + 1e-3 * rng.standard_normal(t.size)
    with pytest.raises(InputError, match=r"^up: torque_levels cannot level the torque, and "
                       r"between t = 0 s and 1\.0\d+ s it departs from its level 0\.157 N m "
                       r"by up to 0\.15\d* N m .*give the torque command"):
        torque_levels(bk.Record(t, up, step1.w_motor, step1.w_load, name="up"))
    down = np.clip(0.157 * (40.05 - t) / 0.05, 0.0, 0.157) + 3e-3 * rng.standard_normal(t.size)
    with pytest.raises(InputError, match=r"found one level only.*between t = 0 s and 80 s"):
        torque_levels(bk.Record(t, down, step1.w_motor, step1.w_load, name="down"))
    # a step of 0.157 N m through noise of 0.02 N m: no sample-to-sample jump beyond 8
    # noise std, one level half-way (it was returned as the torque before)
    hidden = np.where(t < 40.0, 0.157, 0.0) + 0.02 * rng.standard_normal(t.size)
    with pytest.raises(InputError, match=r"found one level only.*a step too small for the "
                       r"noise"):
        torque_levels(bk.Record(t, hidden, step1.w_motor, step1.w_load, name="hidden"))
    for seed in range(10):
        for corr in (10, 40, 100, 200):
            white = 1e-3 * np.sqrt(2 * corr - 1) * np.random.default_rng(seed).standard_normal(
                t.size)
            noise = lfilter([1 / corr], [1, -(1 - 1 / corr)], white)  # std about 1e-3
            rec = bk.Record(t, step1.torque + noise, step1.w_motor, step1.w_load)
            assert np.unique(torque_levels(rec).torque).size == 2


def test_filtered_and_quantised_torque_noise(step1):
    """Noise through a first-order filter (40 samples) hides from second differences;
    the spread of the held level shows it. Quantised noise (2 mN m counts, most
    differences 0) is levelled too; an exact torque is left alone; a non-record is
    named."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(3)
    white = 4.7e-4 * np.sqrt(2 * 40 - 1) * rng.standard_normal(step1.t.size)
    filtered = lfilter([1 / 40], [1, -(1 - 1 / 40)], white)  # std about 4.7e-4
    u = step1.torque + filtered
    assert torque_noise_std(u) == pytest.approx(np.std(filtered), rel=0.2)
    with pytest.raises(InputError, match="the torque is noisy"):
        check_torque_noise(bk.Record(step1.t, u, step1.w_motor, step1.w_load, name="f"))
    q = 2e-3
    counts = np.round((step1.torque + 6e-4 * rng.standard_normal(step1.t.size)) / q) * q
    levelled = torque_levels(bk.Record(step1.t, counts, step1.w_motor, step1.w_load))
    assert np.unique(levelled.torque).size == 2
    assert np.max(np.abs(levelled.torque - step1.torque)) <= q / 2 + 1e-12  # the count
    assert torque_levels(step1) is step1
    with pytest.raises(InputError, match="torque_levels needs a Record, got str"):
        torque_levels("measured.csv")
