"""The joint estimator on drives as they are: Coulomb friction and a current loop.

Every record here is made by the independent scipy reference
(:func:`backlashkit.verify.reference_simulate`, adaptive integration with located
contact and friction changes), not by the compiled kernel the estimator fits with.
The drives start at their steady state under the held torque, as paper A's 40 s holds
do, and are stepped down to 0 (issue 20's records, shortened to 8 s).
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import backlashkit as bk
from backlashkit.cli.main import main as cli_main
from backlashkit.errors import InputError, PriorMismatchWarning
from backlashkit.identify import _search
from backlashkit.identify.joint import PRIOR_CONFLICT_Z
from backlashkit.identify.search import JointSearch, Restarts
from backlashkit.identify.terms import SCREEN_DROP
from backlashkit.io import write_csv
from backlashkit.papers.ravanbod2002 import A1, A2, P_TRUE, THETA
from backlashkit.parallel import task_seeds
from backlashkit.verify import reference_angles, reference_simulate

#: Issue 20's bar on theta for friction and current loop (not quantised).
THETA_RTOL = 0.03
T_END, T_STEP, TS, SNR = 8.0, 2.0, 1e-3, 40.0
#: An estimate this many standard errors off the truth happens once in 370 fits: one
#: record pair cannot test the interval's 95 % (benchmarks/real_drive.py
#: does, over hundreds), but it can catch a biased or overconfident one.
OUTLIER_STDS = 3.0
#: A second drive: stiffer, a lighter load, a smaller backlash.
OTHER = {"J_M": 2.0e-3, "J_L": 2.5e-2, "k_sh": 150.0, "f_M": 3e-3, "f_L": 4e-3,
         "f_sh": 1.0e-2}


def _records(linear, theta, *, fc=(0.0, 0.0), tau_i=0.0, seed=0, snr=SNR):
    """Two noisy step-down records (paper A's two torque levels) by the scipy reference;
    ``seed``: an int or a SeedSequence (``benchmarks/real_drive.py`` draws a trial's
    noise from its SeedSequence the same way)."""
    drive = bk.TwoMassDrive(**linear, theta=theta, fc_M=fc[0], fc_L=fc[1])
    loop = bk.CurrentLoop(tau_i=tau_i) if tau_i else None
    t = bk.signals.time_grid(T_END, TS)
    root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    out = []
    for a, ss in zip((A1, A2), root.spawn(2), strict=True):
        u = bk.signals.step_down(t, a, t_s=T_STEP)
        ref = reference_simulate(drive, t, u, actuator=loop, initial_state=drive.steady_state(a))
        s_m, s_l = ss.spawn(2)
        out.append(bk.Record(t, u, bk.signals.add_noise(ref.w_motor, snr, rng=s_m),
                             bk.signals.add_noise(ref.w_load, snr, rng=s_l), name=f"a={a:.3g}"))
    return out


def _m2ll(fit_or_drive, recs) -> float:
    """``-2 log L`` (less its constant) with white noise of unknown level in every
    channel, ``sum n log(SSE / n)``, of a fit's residuals or of a drive simulated by
    the compiled kernel from the records' steady start."""
    if isinstance(fit_or_drive, bk.TwoMassDrive):
        pairs = []
        for r in recs:
            sim = fit_or_drive.simulate(r.t, r.torque,
                                        initial_state=fit_or_drive.steady_state(r.torque[0]))
            pairs.append((r.w_motor - sim.w_motor, r.w_load - sim.w_load))
    else:
        pairs = fit_or_drive.residuals_
    return sum(e.size * math.log(float(np.mean(e ** 2))) for pair in pairs for e in pair)


def _fit(recs, linear, **kw):
    return bk.JointIdentifier(bk.TwoMassDrive(**linear), workers=1, **kw).fit(recs)


@pytest.fixture(scope="module")
def coulomb():
    return _records(P_TRUE, THETA, fc=(0.01, 0.02))


def test_coulomb_friction_found_and_theta_within_3_percent(coulomb):
    """Issue 20's first row: 1-2 % Coulomb friction, 40 dB. Today's viscous model moved
    J_M x0.007 and blamed the units; the default now fits the Coulomb torques."""
    fit = _fit(coulomb, P_TRUE)
    assert fit.friction_ == "coulomb" and fit.tau_i_ == 0.0
    assert fit.theta_ == pytest.approx(THETA, rel=THETA_RTOL)
    assert abs(fit.theta_ - THETA) < OUTLIER_STDS * fit.std_
    assert fit.fc_M_ == pytest.approx(0.01, rel=0.15)
    assert fit.fc_L_ == pytest.approx(0.02, rel=0.15)
    kept = {c.term: c.kept for c in fit.choices_}
    assert kept == {"friction": True, "actuator": False}
    for name in ("J_M", "J_L", "k_sh"):
        assert fit.params_[name] == pytest.approx(P_TRUE[name], rel=0.05), name


def test_a_fit_without_friction_that_stops_short_measures_no_shift(coulomb, monkeypatch):
    """Where the fit without the Coulomb torques stops at its iteration limit, far from
    its optimum, how far theta moves without them is not known: the test keeps them by
    their fall alone and says so (the QA pass's 80 s records from rest read "theta
    moves by 0 of its standard errors")."""
    from backlashkit.identify._problem import Problem

    without = Problem.without

    def stopped_short(self, params):  # the nested model's refits get one iteration
        other, keep = without(self, params)
        refine = other.refine
        object.__setattr__(other, "refine", lambda res, z, it, *a, **k: refine(res, z, 1))
        return other, keep

    monkeypatch.setattr(Problem, "without", stopped_short)
    (friction, *_) = _fit(coulomb, P_TRUE).choices_
    assert friction.term == "friction" and friction.kept and math.isnan(friction.shift)
    assert "stopped before converging" in friction.reason()


def test_viscous_model_on_friction_names_friction_not_units(coulomb):
    """Forced to the viscous model, the fit wanders off the prior; the refusal says the
    held speeds rule out a unit mistake and names the option that adds friction."""
    with pytest.raises(InputError) as err, warnings.catch_warnings():
        warnings.simplefilter("ignore", PriorMismatchWarning)
        _fit(coulomb, P_TRUE, friction="viscous", actuator=None)
    text = str(err.value)
    assert "units are likely right" in text and "friction='auto'" in text
    assert "w_motor and w_load swapped?" in text  # the held speeds cannot tell that
    assert "rpm" not in text


def test_a_fit_too_far_from_the_prior_is_refused_before_its_uncertainty(coulomb,
                                                                          monkeypatch):
    """The same refusal comes as soon as the search has chosen its model: the profile
    interval's refits and the second search (``Restarts.misfit``) from linear
    parameters that far off can take minutes; a bootstrap refit still answers."""

    def no_uncertainty(*args, **kwargs):
        raise AssertionError("the uncertainty ran at a point the prior refuses")

    monkeypatch.setattr(_search, "uncertainty", no_uncertainty)
    with pytest.raises(InputError, match="units are likely right"), \
            warnings.catch_warnings():
        warnings.simplefilter("ignore", PriorMismatchWarning)
        _fit(coulomb, P_TRUE, friction="viscous", actuator=None)
    refit = bk.JointIdentifier(bk.TwoMassDrive(**P_TRUE), friction="viscous",
                               actuator=None)._refit_params()
    assert refit["allow_far_from_prior"] is True


def _looks_past(monkeypatch) -> list[bool]:
    """Whether each side of the profile intervals fitted from now on looked past its
    end (``IntervalInputs.look_past``)."""
    from backlashkit.identify.intervals import ProfileLikelihood

    seen, end = [], ProfileLikelihood._end

    def recorded(self, rise, first, look_past, recheck=None, largest=None):
        seen.append(look_past)
        return end(self, rise, first, look_past, recheck, largest)

    monkeypatch.setattr(ProfileLikelihood, "_end", recorded)
    return seen


def test_current_loop_found_and_theta_within_3_percent(monkeypatch):
    """Issue 20's second row: a 1 ms current loop, 40 dB (today: +1.4 %, and an
    interval excluding the truth). The loop, added after the search, lets the profile
    of theta fall again past a crossing: its ends are looked past."""
    recs = _records(P_TRUE, THETA, tau_i=1e-3, seed=1)
    looked = _looks_past(monkeypatch)
    fit = _fit(recs, P_TRUE)
    assert looked == [True, True]
    assert fit.tau_i_ == pytest.approx(1e-3, rel=0.5)
    assert fit.friction_ == "viscous"
    assert fit.theta_ == pytest.approx(THETA, rel=THETA_RTOL)
    assert abs(fit.theta_ - THETA) < OUTLIER_STDS * fit.std_


def test_friction_and_loop_together_on_another_drive():
    theta = 0.02
    recs = _records(OTHER, theta, fc=(0.005, 0.01), tau_i=1.5e-3, seed=2)
    fit = _fit(recs, OTHER)
    assert fit.friction_ == "coulomb" and fit.tau_i_ > 0
    assert fit.theta_ == pytest.approx(theta, rel=THETA_RTOL)
    assert abs(fit.theta_ - theta) < OUTLIER_STDS * fit.std_


def test_friction_and_loop_nearly_noise_free():
    """Coulomb friction and a 1 ms loop together, speeds exact but for a 1e-4 rad/s
    ripple (a noise level is needed): the loop is added after the search from several
    starts (terms.TAU_START_SAMPLES), since from one (half a sample) the refit can walk
    the lag to its floor, a local minimum with theta well off."""
    recs = [bk.Record(r.t, r.torque, w_m, w_l) for r, (w_m, w_l) in zip(
        _records(P_TRUE, THETA, fc=(0.01, 0.02), tau_i=1e-3, seed=5), _exact_speeds(),
        strict=True)]
    fit = _fit(recs, P_TRUE, interval=bk.FisherInterval())
    assert fit.friction_ == "coulomb"
    assert fit.tau_i_ == pytest.approx(1e-3, rel=1e-4)
    assert fit.theta_ == pytest.approx(THETA, rel=1e-6)


def _exact_speeds():
    """The speeds of ``_records(..., fc=(0.01, 0.02), tau_i=1e-3)`` without noise, plus a
    1e-4 rad/s ripple."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = bk.signals.time_grid(T_END, TS)
    out = []
    for a in (A1, A2):
        ref = reference_simulate(drive, t, bk.signals.step_down(t, a, t_s=T_STEP),
                                 actuator=bk.CurrentLoop(tau_i=1e-3),
                                 initial_state=drive.steady_state(a))
        out.append((ref.w_motor + 1e-4 * np.sin(977 * t), ref.w_load + 1e-4 * np.cos(911 * t)))
    return out


def test_ideal_records_keep_paper_a_model_unchanged(monkeypatch):
    """On an ideal drive ``auto`` keeps the viscous model without a loop, and the
    estimate is that model's own fit; its profile does not look past its ends."""
    recs = _records(P_TRUE, THETA, seed=3)
    looked = _looks_past(monkeypatch)
    auto = _fit(recs, P_TRUE)
    assert looked == [False, False]
    plain = _fit(recs, P_TRUE, friction="viscous", actuator=None)
    assert (auto.friction_, auto.tau_i_) == ("viscous", 0.0)
    assert not any(c.kept for c in auto.choices_)
    # the same model, refitted from the larger one's optimum: the same point to a
    # small fraction of a standard error
    assert abs(auto.theta_ - plain.theta_) < 0.05 * plain.std_
    assert auto.estimated_ == plain.estimated_


def test_a_dropped_loop_widens_the_interval_by_the_lags_not_ruled_out():
    """Where the loop is dropped, the estimate is the model's without it, and its
    interval is that model's reaching out by the choice's widening: on paper A's ideal
    records the score test drops the loop unfitted, and a lag it does not rule out
    still moves theta."""
    recs = _records(P_TRUE, THETA, seed=3)
    auto = _fit(recs, P_TRUE, friction="viscous")
    plain = _fit(recs, P_TRUE, friction="viscous", actuator=None)
    (loop,) = auto.choices_
    assert not loop.kept and auto.tau_i_ == 0.0
    assert auto.theta_ == plain.theta_
    down, up = loop.widening
    assert down >= 0 and up >= 0 and max(down, up) > 0
    lo, hi = plain.ci95_
    lo, hi = lo * math.exp(-down), hi * math.exp(up)
    if loop.held_ci95 is not None:
        lo, hi = min(lo, loop.held_ci95[0]), max(hi, loop.held_ci95[1])
    assert auto.ci95_ == pytest.approx((lo, hi), rel=1e-12)
    with pytest.raises(AssertionError):  # the widening is no rounding
        assert auto.ci95_ == pytest.approx(plain.ci95_, rel=1e-4)


def test_a_drive_without_backlash_gets_an_interval_from_0(tmp_path, capsys, monkeypatch):
    """A drive with no backlash (theta = 0, the scipy reference at 40 dB; trials 2 and
    4 of the seed-7 trials of ``python benchmarks/small_backlash.py``): theta is fitted
    as a logarithm, which only approaches 0, so its interval was ``[theta_ / 10, 10
    theta_]``, the widest the profile's search in log theta reaches: about an estimate of
    8e-15 rad in trial 2, leaving out 0 and the standard error's 9e-6 rad alike. In
    trial 4 ``f_M`` moved x0.31 from the prior, which is the truth, with a warning that
    blamed swapped columns: without backlash the two speeds hardly tell the motor's
    viscous friction from the load's, and that move is within its own noise; so is the
    second drive's x0.2 (trial 1 of its seed-7 trials), where the prior's parameters fit
    the records about as well as the estimate. The
    interval now reaches 0 (the profile at theta = 0 stays below 3.84) and ends where
    the profile, followed in rad, crosses 3.84; no warning. The search's other ends
    along the friction split's flat floor (and at other thetas next to 0) were counted
    as 4 rival minima, with a note that the interval was wider than theta -+ 1.96 std
    for them; they lie within 0.003 of the estimate up its Fisher quadratic in natural
    units (``_search.bowl_rise``), so they are no rivals."""
    trials = np.random.SeedSequence(7).spawn(12)
    recs = _records(P_TRUE, 0.0, seed=trials[2])
    other = _records(OTHER, 0.0, seed=trials[1])
    seen = []  # the search's other ends that trial 2's uncertainty is handed

    def outside_bowl(jz, z, points, natural):
        seen.extend((_search.bowl_rise(jz, z, pt, natural), np.exp(pt - z)) for pt in points)
        return bowl(jz, z, points, natural)

    bowl = _search.outside_bowl
    with warnings.catch_warnings():
        warnings.simplefilter("error", PriorMismatchWarning)
        moved = _fit(_records(P_TRUE, 0.0, seed=trials[4]), P_TRUE)
        monkeypatch.setattr(_search, "outside_bowl", outside_bowl)
        fit = _fit(recs, P_TRUE)
        monkeypatch.setattr(_search, "outside_bowl", bowl)
        second = _fit(other, OTHER)
    with capsys.disabled():  # -s shows what the docstring quotes
        print(f"trial 4: f_M x{moved.params_['f_M'] / P_TRUE['f_M']:.3g}, the standard error of "
              f"its logarithm {moved.param_std_['f_M'] / moved.params_['f_M']:.3g} (x"
              f"{math.exp(moved.param_std_['f_M'] / moved.params_['f_M']):.3g}), its prior's "
              f"rise {moved._prior_rise:.3g}, ci95_ from {moved.ci95_[0]:.3g}")
        # the second drive: the friction's split moves far, in a curved valley whose Fisher
        # standard errors are small, yet the truth fits the records about as well
        print(f"the second drive, trial 1: f_M x{second.params_['f_M'] / OTHER['f_M']:.3g} "
              f"(standard error x"
              f"{math.exp(second.param_std_['f_M'] / second.params_['f_M']):.3g}), f_L x"
              f"{second.params_['f_L'] / OTHER['f_L']:.3g}; -2 log L of the truth "
              f"{_m2ll(bk.TwoMassDrive(**OTHER, theta=0.0), other) - _m2ll(second, other):+.3g} "
              f"from the estimate's, its prior's rise {second._prior_rise:.3g}")
    assert second.ci95_[0] == 0.0
    lo, hi = fit.ci95_
    with capsys.disabled():
        print(f"trial 2: theta_ {fit.theta_:.3g} rad, std_ {fit.std_:.3g}, ci95_ [{lo:.3g}, "
              f"{hi:.3g}]")
        for rise, ratio in seen:
            print(f"  the search's end at theta x{ratio[0]:.3g}, f_M x{ratio[4]:.3g}, f_L "
                  f"x{ratio[5]:.3g} of the estimate's: {rise:.2g} up its Fisher quadratic")
    assert len(seen) == 4 and all(rise < 0.01 for rise, _ in seen)
    assert moved.ci95_[0] == 0.0
    assert lo == 0.0 and fit.ci95_bounded_ == (True, True) and fit.rival_basins_ == 0
    at_0 = fit.profile_[fit.profile_[:, 0] == 0.0, 1]
    at_hi = fit.profile_[np.argmin(np.abs(fit.profile_[:, 0] - hi)), 1]
    assert at_0.size and np.all(at_0 < 3.84) and at_hi == pytest.approx(3.84, abs=0.25)
    assert fit.std_ < hi < fit.theta_ + 5.0 * fit.std_
    paths, prior = _files(recs, tmp_path)  # the command line says what it means
    capsys.readouterr()
    assert cli_main(["identify", *paths, "--drive", prior, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ci95"] == [0.0, pytest.approx(hi)]
    assert any(n.startswith("the 95% interval of theta reaches 0: these records are "
                            "consistent with a drive without backlash") for n in doc["notes"])
    assert doc["rival_basins"] == 0 and not any("other minima" in n for n in doc["notes"])


def test_a_drive_without_backlash_is_searched_for():
    """The second drive without backlash (trials 23 and 1 of the seed-7 trials of
    ``python benchmarks/small_backlash.py --drive other``): the grid's starts and the
    first window's bounds do not reach its basin, and without the restart from a
    thousandth of the solution's theta (``Restarts.no_backlash``) the search ended with
    ``k_sh`` x5.5 and was refused; with the linear parameters held at the truth it
    ended at theta 5.4e-4 rad with an interval that left out 0."""
    trials = task_seeds(7, 100)
    refused, held = _records(OTHER, 0.0, seed=trials[23]), _records(OTHER, 0.0, seed=trials[1])
    without = JointSearch(restarts=Restarts(no_backlash=False))
    with pytest.raises(InputError, match=r"^the fit moved k_sh x5\.5 from the prior"):
        _fit(refused, OTHER, search=without)
    old = _fit(held, OTHER, prior_rel_std=0, search=without)
    assert old.theta_ == pytest.approx(5.4e-4, rel=0.01) and old.ci95_[0] > 5e-4
    assert _fit(refused, OTHER).ci95_[0] == 0.0
    assert _fit(held, OTHER, prior_rel_std=0).ci95_[0] == 0.0


def test_a_coulomb_torque_fitted_to_0_has_a_standard_error(tmp_path, capsys):
    """``friction="coulomb"`` on drives without Coulomb friction: the fit puts the
    torques on their floor (0). The floor held them, so their Jacobian columns were 0,
    the information singular, and its pseudo-inverse gave them a standard error of 0,
    as if they were known exactly; ``friction_`` said "viscous" beside them. The
    uncertainty now takes their derivative up from the floor. With backlash,
    ``theta``'s standard error is then about the viscous fit's. Without (the records of
    ``test_a_drive_without_backlash_gets_an_interval_from_0`` as CSV files, ``identify
    --friction coulomb``), the pseudo-inverse also cut ``theta``'s own column, 1e-9 of
    the others' next to ``theta = 0``: its standard error read 0 and its interval
    ``[0, 8.2e-14]`` rad, ten times an estimate of 8.2e-15 rad (``-s`` prints it now)."""
    trials = np.random.SeedSequence(7).spawn(12)
    recs = _records(P_TRUE, THETA, seed=trials[2])
    fit = _fit(recs, P_TRUE, friction="coulomb", actuator=None)
    viscous = _fit(recs, P_TRUE, friction="viscous", actuator=None)
    assert fit.params_["fc_M"] == 0.0 and fit.friction_ == "coulomb"  # still the model's
    assert all(1e-5 < fit.param_std_[n] < 1e-2 for n in ("fc_M", "fc_L"))  # N m
    assert fit.std_ == pytest.approx(viscous.std_, rel=0.05)
    # a fresh trial 2 (the first draw spawned children of trials[2])
    fresh = np.random.SeedSequence(7).spawn(12)[2]
    paths, prior = _files(_records(P_TRUE, 0.0, seed=fresh), tmp_path)
    capsys.readouterr()
    assert cli_main(["identify", *paths, "--drive", prior, "--friction", "coulomb",
                     "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    with capsys.disabled():
        print(f"without backlash, --friction coulomb: theta {doc['theta']:.3g} rad, std "
              f"{doc['std']:.3g}, ci95 [{doc['ci95'][0]:.3g}, {doc['ci95'][1]:.3g}], fc_M "
              f"{doc['fc_M']:.3g} N m")
    assert doc["theta"] < 1e-12 and doc["fc_M"] == doc["fc_L"] == 0.0
    assert doc["std"] > 1e-6 and doc["ci95"][0] == 0.0 and doc["ci95"][1] > doc["std"]


def test_a_singular_information_keeps_a_theta_next_to_0():
    """Where ``J^T J`` is singular (a column of zeros), the pseudo-inverse used to cut
    ``theta``'s column too when ``theta`` sat next to 0, ``theta dr/dtheta`` in its
    logarithm being 1e-9 of the others: a standard error of 0 and an interval of
    ``[0, 10 theta_]``. Scaled to unit columns first, it keeps it."""
    from backlashkit.identify._search import fisher_covariance

    rng = np.random.default_rng(3)
    jz = rng.normal(size=(50, 3)) * [1e-9, 1e4, 0.0]
    cov = fisher_covariance(jz)
    keep = np.linalg.inv(jz[:, :2].T @ jz[:, :2])
    assert np.allclose(cov[:2, :2], keep, rtol=1e-8) and cov[2, 2] == 0.0


def test_known_current_loop_is_not_fitted():
    recs = _records(P_TRUE, THETA, tau_i=1e-3, seed=4)
    fit = _fit(recs, P_TRUE, friction="viscous", actuator=bk.CurrentLoop(tau_i=1e-3))
    assert fit.tau_i_ == 1e-3 and "tau_i" not in fit.estimated_ and fit.choices_ == []
    assert fit.theta_ == pytest.approx(THETA, rel=THETA_RTOL)


@pytest.mark.parametrize(("kw", "match"), [
    ({"friction": "dry"}, "friction must be one of 'auto', 'viscous', 'coulomb', got 'dry'"),
    ({"actuator": "on"}, "actuator must be 'auto', None or a CurrentLoop, got 'on'"),
    ({"actuator": 1e-3}, "actuator must be 'auto', None or a CurrentLoop, got float 0.001 "
                         "(a loop of that time constant: CurrentLoop(tau_i=0.001))"),
])
def test_bad_terms_refused(coulomb, kw, match):
    with pytest.raises(InputError, match=re.escape(match)):
        _fit(coulomb, P_TRUE, **kw)


def _files(recs, tmp_path):
    """The records as CSV files and a prior TOML with only the linear parameters."""
    paths = []
    for k, rec in enumerate(recs):
        paths.append(str(tmp_path / f"exp{k + 1}.csv"))
        write_csv(paths[-1], {"t": rec.t, "torque": rec.torque, "w_motor": rec.w_motor,
                              "w_load": rec.w_load})
    prior = tmp_path / "prior.toml"
    prior.write_text("[drive]\n" + "".join(f"{k} = {v!r}\n" for k, v in P_TRUE.items()))
    return paths, str(prior)


def test_cli_json_says_what_the_model_chose(coulomb, tmp_path, capsys):
    """Issue 20's command: only the linear parameters in the prior, no other option."""
    paths, prior = _files(coulomb, tmp_path)
    assert cli_main(["identify", *paths, "--drive", prior, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["friction"] == "coulomb"
    assert doc["theta"] == pytest.approx(THETA, rel=THETA_RTOL)
    assert abs(doc["theta"] - THETA) < OUTLIER_STDS * doc["std"]
    assert doc["fc_M_std"] > 0 and doc["fc_L_std"] > 0
    assert doc["tau_i"] == 0.0 and doc["tau_i_std"] is None
    assert len(doc["model_choices"]) == 2
    tests = {t["term"]: t for t in doc["model_tests"]}
    assert set(tests) == {"friction", "actuator"} and tests["friction"]["kept"]
    assert tests["friction"]["rise"] > tests["friction"]["threshold"]
    loop = tests["actuator"]
    assert not loop["kept"] and len(loop["widening"]) == 2
    assert loop["held_ci95"] is None or loop["held_ci95"][0] <= doc["ci95"][0] * (1 + 1e-12)


def test_cli_reads_a_known_loop_from_the_drive_file(coulomb, tmp_path, capsys):
    """A drive file's [actuator] table (as ``simulate`` reads it) fixes the loop's lag
    where ``--current-loop`` is not given: nothing to test, no standard error."""
    paths, prior = _files(coulomb, tmp_path)
    with open(prior, "a") as f:
        f.write("[actuator]\ntau_i = 0.0005\n")
    assert cli_main(["identify", *paths, "--drive", prior, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["tau_i"], doc["tau_i_std"]) == (0.0005, None)
    assert [c.split()[0] for c in doc["model_choices"]] == ["Coulomb"]


@pytest.mark.parametrize("estimated, friction, tau_i, words", [
    (["theta", "J_M"], "viscous", 0.0,
     "viscous friction, no current loop (torque applied as recorded)"),
    (["theta", "J_M", "fc_M", "fc_L", "tau_i"], "coulomb", 7e-4,
     "viscous friction and Coulomb torques (fitted), a current loop (its lag fitted)"),
    (["theta", "J_M"], "coulomb", 5e-4, "viscous friction and Coulomb torques (held at "
     "the prior's), a current loop (its lag held at 0.0005 s)"),
])
def test_joint_text_says_the_model_in_one_line(estimated, friction, tau_i, words):
    """The joint text output's ``model =`` line: friction and loop, fitted or held."""
    from types import SimpleNamespace

    from backlashkit.cli._identify_text import _model_line

    est = SimpleNamespace(estimated_=estimated, friction_=friction, tau_i_=tau_i)
    assert _model_line(est) == f"model     = two-mass drive with backlash, {words}"


def test_cli_current_loop_flag_refuses_nonsense(coulomb, tmp_path, capsys):
    (path,), prior = _files(coulomb[1:], tmp_path)
    code = cli_main(["identify", path, "--drive", prior, "--current-loop", "fast"])
    assert code != 0
    assert "--current-loop must be auto, none or a time constant in s, got 'fast'" in \
        capsys.readouterr().err


#: Issue 20's bar on theta where quantisation and friction come together.
THETA_RTOL_ENCODER = 0.05
#: Counts per revolution of the encoders of issue 20's records.
COUNTS = 16384


def _encoder_records(linear, theta, *, fc=(0.0, 0.0), tau_i=0.0, seed=0):
    """Two step-down records as a drive logs them from 16 384-count encoders: the
    differenced counts of the reference's exact angles, each encoder starting at a
    random angle within a count."""
    return _read_by_encoders(_reference_angles(linear, theta, fc=fc, tau_i=tau_i), seed)


def _reference_angles(linear, theta, *, fc=(0.0, 0.0), tau_i=0.0):
    """``(t, torque, (phi_M, phi_L))`` of the two step-down records (scipy reference)."""
    drive = bk.TwoMassDrive(**linear, theta=theta, fc_M=fc[0], fc_L=fc[1])
    loop = bk.CurrentLoop(tau_i=tau_i) if tau_i else None
    t = bk.signals.time_grid(T_END, TS)
    out = []
    for a in (A1, A2):
        u = bk.signals.step_down(t, a, t_s=T_STEP)
        out.append((t, u, reference_angles(drive, t, u, actuator=loop,
                                           initial_state=drive.steady_state(a))))
    return out


def _read_by_encoders(angles, seed):
    """Records of the differenced counts of ``angles``, each encoder from a random
    angle within a count."""
    enc = bk.Encoder(COUNTS)
    out = []
    for (t, u, phi), ss in zip(angles, np.random.SeedSequence(seed).spawn(2), strict=True):
        offsets = np.random.default_rng(ss).uniform(size=2) * enc.resolution
        w_m, w_l = (enc.measure(t, p + o).speed for p, o in zip(phi, offsets, strict=True))
        out.append(bk.Record(t, u, w_m, w_l, name=f"a={u[0]:.3g}"))
    return out


def test_reference_angles():
    """The reference's angles (its speed integrated on a finer grid) agree with the
    compiled kernel's exact angle state, and hardly move from 16 to 32 substeps."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    loop = bk.CurrentLoop(tau_i=1e-3)
    t = bk.signals.time_grid(T_END, TS)
    u = bk.signals.step_down(t, A2, t_s=T_STEP)
    kw = {"actuator": loop, "initial_state": drive.steady_state(A2)}
    fine = reference_angles(drive, t, u, **kw)
    coarse = reference_angles(drive, t, u, substeps=16, **kw)
    q = bk.Encoder(COUNTS).resolution
    assert max(np.max(np.abs(f - c)) for f, c in zip(fine, coarse, strict=True)) < 3e-4 * q
    kernel = drive.simulate(t, u, actuator=loop, positions=True,
                            initial_state=drive.steady_state(A2))
    for ref, ker in zip(fine, (kernel.phi_motor, kernel.phi_load), strict=True):
        assert np.max(np.abs(ref - (ker - ker[0]))) < 1e-3 * q


def test_record_from_positions_and_back():
    """Counts become angles in rad; the speeds are their differences per sample; the
    running sum of differenced counts gives the angles back exactly."""
    t = np.arange(6) * 1e-3
    counts = np.array([0, 3, 7, 7, 6, 10])
    rec = bk.Record.from_positions(t, np.ones(6), counts, 2 * counts, counts_per_rev=4096)
    q = 2 * np.pi / 4096
    assert rec.quantum == pytest.approx(q) and rec.has_positions
    np.testing.assert_allclose(rec.phi_motor, counts * q)
    np.testing.assert_allclose(rec.w_motor[1:], np.diff(counts) * q / 1e-3)
    assert rec.w_motor[0] == rec.w_motor[1]
    back = bk.Record(t, np.ones(6), rec.w_motor, rec.w_load).with_positions(q)
    np.testing.assert_allclose(back.phi_load, 2 * counts * q, rtol=1e-12, atol=1e-15)
    with pytest.raises(InputError, match="give both phi_motor and phi_load"):
        bk.Record(t, np.ones(6), rec.w_motor, rec.w_load, "r", rec.phi_motor)
    with pytest.raises(InputError, match="counts_per_rev must be"):
        bk.Record.from_positions(t, np.ones(6), counts, counts, counts_per_rev=0)


@pytest.fixture(scope="module")
def encoder():
    return _encoder_records(P_TRUE, THETA)


def test_encoder_speeds_are_fitted_as_angles(encoder):
    """Speeds that are differenced encoder counts (issue 20's third row: +0.7 %, the
    truth 6 std outside the interval) are fitted as the encoders' angles: theta within
    3 %, and the interval no narrower than its error calls for."""
    from backlashkit.identify.quantum import speed_quantum

    q = bk.Encoder(COUNTS).resolution / TS
    assert speed_quantum(encoder[1].w_motor) == pytest.approx(q, rel=1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("error", bk.errors.QuantisedSpeedsWarning)
        fit = _fit(encoder, P_TRUE)
    assert fit.measured_ == ["angles", "angles"]
    assert abs(fit.theta_ / THETA - 1) < THETA_RTOL
    assert abs(fit.theta_ - THETA) < OUTLIER_STDS * fit.std_
    # the angles' noise is the quantisation's, q / sqrt(12)
    np.testing.assert_allclose(fit.noise_std_, bk.Encoder(COUNTS).resolution / np.sqrt(12),
                               rtol=0.05)


def test_encoder_with_friction_and_loop_within_5_percent():
    """Issue 20's fourth row (all three: -99 % by the two-step method, refused by the
    joint one): theta within 5 % and no refusal."""
    recs = _encoder_records(P_TRUE, THETA, fc=(0.01, 0.02), tau_i=1e-3, seed=3)
    fit = _fit(recs, P_TRUE)
    assert fit.measured_ == ["angles", "angles"]
    assert fit.friction_ == "coulomb"
    assert abs(fit.theta_ / THETA - 1) < THETA_RTOL_ENCODER
    assert abs(fit.theta_ - THETA) < OUTLIER_STDS * fit.std_


#: Trial 84 of ``python benchmarks/real_drive.py --snr 30 --drives paper --effects
#: coulomb`` (seed 2020: drive 0, scenario 1, trial 84).
TRIAL_84 = np.random.SeedSequence(2020, spawn_key=(0, 1, 84))


def test_the_best_start_is_continued_past_the_first_window():
    """Paper A's drive with Coulomb friction at 30 dB, a trial whose first window sent
    every start to a basin the longer windows kept (one Coulomb torque at 0, ``k_sh``
    far low), until the best start was also refined without the first window
    (``_search.direct_path``). With the package of a441c56, before that, this test
    prints theta 5.56 % low and ``-2 log L`` 65 above the truth's, and fails. The fit
    now ends more likely than the truth, the mark of a search that found the maximum
    (``-s`` prints both figures)."""
    fc = (0.01, 0.02)
    recs = _records(P_TRUE, THETA, fc=fc, seed=TRIAL_84, snr=30.0)
    fit = _fit(recs, P_TRUE, friction="coulomb", actuator=None, interval=bk.FisherInterval())
    truth = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=fc[0], fc_L=fc[1])
    rise = _m2ll(fit, recs) - _m2ll(truth, recs)
    print(f"theta {100 * (fit.theta_ / THETA - 1):+.2f} %, -2 log L {rise:+.4g} from the "
          "truth's")
    assert rise < 0
    assert fit.theta_ == pytest.approx(THETA, rel=THETA_RTOL)
    assert fit.fc_M_ > 0.5 * fc[0]


#: Trial 129 of ``python benchmarks/real_drive.py --snr 30 --drives other --effects
#: coulomb`` (seed 2020: drive 1, scenario 1, trial 129).
TRIAL_129 = np.random.SeedSequence(2020, spawn_key=(1, 1, 129))


def test_the_search_restarts_from_the_priors_linear_parameters():
    """The second drive with Coulomb friction at 30 dB, a trial whose windows carried
    ``k_sh`` 13 % low, into a neighbouring ringing phase's basin, where the whole
    records cost more than around the prior's point: theta stopped 6.1 % low, its
    interval [-8.8, -3.5] % leaving the truth out. Restarted from the prior's linear
    parameters (``Restarts(prior=True)``, the default) the fit ends more likely and
    near the truth (``-s`` prints both)."""
    recs = _records(OTHER, 0.02, fc=(0.01, 0.02), seed=TRIAL_129, snr=30.0)
    kw = {"friction": "coulomb", "actuator": None, "interval": bk.FisherInterval()}
    stuck = _fit(recs, OTHER, search=bk.JointSearch(restarts=bk.Restarts(prior=False)), **kw)
    fit = _fit(recs, OTHER, **kw)
    rise = _m2ll(fit, recs) - _m2ll(stuck, recs)
    print(f"theta {100 * (fit.theta_ / 0.02 - 1):+.2f} % against "
          f"{100 * (stuck.theta_ / 0.02 - 1):+.2f} % without the restart, -2 log L "
          f"{rise:+.4g} from its")
    assert stuck.theta_ < 0.95 * 0.02  # the search alone still stops in that basin
    assert rise < -5.0
    assert fit.theta_ == pytest.approx(0.02, rel=THETA_RTOL)
    assert fit.params_["k_sh"] == pytest.approx(OTHER["k_sh"], rel=0.05)


def test_the_profiles_ends_are_refitted_from_the_priors_point(monkeypatch):
    """Trial 146 of the same row: the search and its restarts end at theta 2.55 % low,
    and the profile's refits, each continued from the last, keep to that basin: the
    interval [-5.07, -0.20] % left the truth out. Each end is now refitted from the
    prior's point too, where a lower basin lies: the estimate moves there (the
    profile's recentring), near the truth, and the interval covers it. Without that
    refit (``recheck`` dropped) it does not (``-s`` prints both)."""
    from backlashkit.identify.intervals import ProfileLikelihood

    recs = _records(OTHER, 0.02, fc=(0.01, 0.02),
                    seed=np.random.SeedSequence(2020, spawn_key=(1, 1, 146)), snr=30.0)
    fit = _fit(recs, OTHER, friction="coulomb", actuator=None)
    end = ProfileLikelihood._end
    monkeypatch.setattr(ProfileLikelihood, "_end",
                        lambda self, rise, first, look_past, recheck=None, largest=None:
                        end(self, rise, first, look_past, largest=largest))
    stuck = _fit(recs, OTHER, friction="coulomb", actuator=None)
    for name, f in (("rechecked", fit), ("not", stuck)):
        print(f"{name}: theta {100 * (f.theta_ / 0.02 - 1):+.2f} %, interval "
              f"[{100 * (f.ci95_[0] / 0.02 - 1):+.2f}, {100 * (f.ci95_[1] / 0.02 - 1):+.2f}] %")
    assert fit.ci95_[0] <= 0.02 <= fit.ci95_[1]
    assert not stuck.ci95_[0] <= 0.02 <= stuck.ci95_[1]
    assert abs(fit.theta_ / 0.02 - 1) < 0.5 * abs(stuck.theta_ / 0.02 - 1)
    assert _m2ll(fit, recs) < _m2ll(stuck, recs) - 1.0


def test_the_interval_spans_a_rival_basin(monkeypatch):
    """Trial 60 of the same row: the likelihood has two basins, the estimate's (theta
    2.75 % low, ``k_sh`` 6 % low) and one near the truth, 2.6 above it in ``-2 log L``,
    which the restart from the prior's point reaches. The estimate's own profile
    leaves the truth out (its interval ends 0.20 % low); the profile is the lowest over
    both basins, so the interval now spans the second one's profile too and covers
    the truth. Without the rivals (``rivals_of`` finding none) it does not (``-s``
    prints both)."""

    recs = _records(OTHER, 0.02, fc=(0.01, 0.02),
                    seed=np.random.SeedSequence(2020, spawn_key=(1, 1, 60)), snr=30.0)
    kw = {"friction": "coulomb", "actuator": None}
    fit = _fit(recs, OTHER, **kw)
    monkeypatch.setattr(_search, "rivals_of", lambda best, states: [])
    alone = _fit(recs, OTHER, **kw)
    for name, f in (("with rivals", fit), ("without", alone)):
        print(f"{name}: theta {100 * (f.theta_ / 0.02 - 1):+.2f} %, interval "
              f"[{100 * (f.ci95_[0] / 0.02 - 1):+.2f}, {100 * (f.ci95_[1] / 0.02 - 1):+.2f}] %")
    assert fit.theta_ == alone.theta_  # the estimate is the same: the lower basin's
    assert fit.ci95_[0] == alone.ci95_[0]  # the rival lies above: its lower side is not looked at
    assert not alone.ci95_[0] <= 0.02 <= alone.ci95_[1]
    assert fit.ci95_[0] <= 0.02 <= fit.ci95_[1]


def test_the_coulomb_start_does_not_lean_on_the_priors_viscous_friction():
    """The Coulomb torques start from the line through the held levels, whose intercept
    is their sum whatever the prior's viscous friction. From one level, the prior's
    viscous friction must be subtracted, and 10 % too much of it leaves nothing: the
    start falls to its floor, a factor 16 below the truth's half-sum."""
    from backlashkit.identify.terms import FC_START_FLOOR, coulomb_start

    recs = _records(OTHER, 0.02, fc=(0.01, 0.02), seed=5, snr=30.0)
    off = bk.TwoMassDrive(**{**OTHER, "f_M": 1.1 * OTHER["f_M"], "f_L": 1.1 * OTHER["f_L"]})
    assert coulomb_start(recs, off) == pytest.approx(0.015, rel=0.1)
    assert coulomb_start(recs, bk.TwoMassDrive(**OTHER)) == coulomb_start(recs, off)
    assert coulomb_start(recs[1:], off) == FC_START_FLOOR * A2  # one level: the floor


@pytest.mark.parametrize("hold", [2.0, 5.0])
def test_a_short_hold_from_rest_starts_the_coulomb_torques_from_the_rigid_body(
        monkeypatch, hold):
    """One record of paper A's drive with Coulomb friction and a 3 ms loop, held 2 s
    from rest (still accelerating with 73 % of the torque at the step-down) or 5 s
    (45 %; ``-s`` prints both shares), 3 s after, and a prior 15 % off:
    ``T - (f_M + f_L) w`` took that acceleration for friction and started both Coulomb
    torques at 0.36 or 0.24 N m. The search did not come back: after 2 s the test
    dropped friction ("the fit with it ends no lower") and theta ended 12 % low with
    an interval 22 standard errors off (a QA pass); after 5 s, 10 % low. The prior's
    rigid body, from rest, sees the friction in how much the drive lags it
    (``T (1 - g)``; ``-s`` prints both fits)."""
    from backlashkit.identify import terms

    truth = bk.TwoMassDrive(**P_TRUE, theta=0.03, fc_M=0.02, fc_L=0.04)
    t = bk.signals.time_grid(hold + 3.0, TS)
    u = bk.signals.step_down(t, A2, t_s=hold)
    ref = reference_simulate(truth, t, u, actuator=bk.CurrentLoop(tau_i=3e-3))
    s_m, s_l = np.random.SeedSequence(3).spawn(2)
    rec = bk.Record(t, u, bk.signals.add_noise(ref.w_motor, 35.0, rng=s_m),
                    bk.signals.add_noise(ref.w_load, 35.0, rng=s_l), name="short")
    prior = {"J_M": 5.5e-3, "J_L": 6.0e-2, "k_sh": 90.0, "f_M": 6e-3, "f_L": 4.5e-3,
             "f_sh": 1.8e-2}
    share = bk.identify.held_unsteady_share(rec, bk.TwoMassDrive(**prior))
    assert share > 0.4
    start = terms.coulomb_start([rec], bk.TwoMassDrive(**prior))
    # the truth's half-sum is 0.03 N m; the prior's inertia, 10 % low, leaves some of
    # the acceleration counted as friction
    assert 0.03 < start < 3 * 0.03, start
    fit = _fit([rec], prior, interval=bk.FisherInterval())
    print(f"hold {hold:g} s, unsteady share {share:.2f}; "
          f"start {start:.4g} N m: theta {100 * (fit.theta_ / 0.03 - 1):+.2f} % "
          f"({(fit.theta_ - 0.03) / fit.std_:+.2f} SE), fc {fit.fc_M_:.4g}, "
          f"{fit.fc_L_:.4g} N m, tau_i {1e3 * fit.tau_i_:.3g} ms")
    assert fit.friction_ == "coulomb" and fit.tau_i_ > 0
    assert fit.theta_ == pytest.approx(0.03, rel=THETA_RTOL)
    assert abs(fit.theta_ - 0.03) < OUTLIER_STDS * fit.std_
    monkeypatch.setattr(terms, "HELD_UNSTEADY", math.inf)  # the start from the level
    level = terms.coulomb_start([rec], bk.TwoMassDrive(**prior))
    assert level > 0.2
    stuck = _fit([rec], prior, interval=bk.FisherInterval())
    print(f"from the level, start {level:.4g} N m: theta "
          f"{100 * (stuck.theta_ / 0.03 - 1):+.2f} % "
          f"({(stuck.theta_ - 0.03) / stuck.std_:+.2f} SE), friction {stuck.friction_}")
    assert abs(stuck.theta_ - 0.03) > OUTLIER_STDS * stuck.std_


def _drawn_prior(seed: np.random.SeedSequence, rel: float) -> dict:
    """The prior ``benchmarks/real_drive.py --prior-rel-std`` draws for the trial of
    ``seed``: each linear parameter times ``1 + rel e``, ``e`` standard normal clipped
    at 3, from the stream ``2**20`` of the trial's seed."""
    rng = np.random.default_rng(np.random.SeedSequence(seed.entropy,
                                                       spawn_key=(*seed.spawn_key, 1 << 20)))
    eps = np.clip(rng.standard_normal(len(OTHER)), -3.0, 3.0)
    return {n: x * (1.0 + rel * e) for (n, x), e in zip(OTHER.items(), eps, strict=True)}


def _coulomb_p10(trial: int) -> tuple[list, dict, dict]:
    """Trial ``trial`` of the second drive's Coulomb row at 30 dB with a prior drawn
    10 % about the truth (``benchmarks/real_drive.py --prior-rel-std 0.1``): its
    records, its prior, and the fit's prior options (Fisher intervals, for speed)."""
    seed = np.random.SeedSequence(2020, spawn_key=(1, 1, trial))
    recs = _records(OTHER, 0.02, fc=(0.01, 0.02), seed=seed, snr=30.0)
    return recs, _drawn_prior(seed, 0.1), {"prior_rel_std": 0.1,
                                           "interval": bk.FisherInterval()}


def test_a_prior_off_in_its_viscous_friction_still_finds_the_coulomb_torques(monkeypatch):
    """Trial 175 of the second drive's Coulomb row at 30 dB with a 10 % prior
    (``benchmarks/real_drive.py --prior-rel-std 0.1``): the prior's ``f_L`` is 18 % high,
    so the Coulomb start from the prior's viscous friction fell to its floor, and the
    search ended with ``fc_M`` at 0, ``k_sh`` 38 % low and theta 9.2 % low, over 90
    above the truth in ``-2 log L``. From the held levels' line it ends near the truth
    (``-s`` prints both)."""
    from backlashkit.identify import terms

    recs, prior, kw = _coulomb_p10(175)
    fit = _fit(recs, prior, **kw)
    monkeypatch.setattr(terms, "LEVEL_SPREAD", math.inf)  # the start from the prior's
    stuck = _fit(recs, prior, **kw)
    rise = _m2ll(stuck, recs) - _m2ll(fit, recs)
    print(f"theta {100 * (fit.theta_ / 0.02 - 1):+.2f} % against "
          f"{100 * (stuck.theta_ / 0.02 - 1):+.2f} % from the prior's friction, -2 log L "
          f"{rise:+.4g} above")
    assert stuck.theta_ < 0.95 * 0.02
    assert rise > 50.0
    assert fit.theta_ == pytest.approx(0.02, rel=THETA_RTOL)
    assert fit.fc_M_ == pytest.approx(0.01, rel=0.3)


def test_long_window_stiffness_restarts_reach_a_basin_the_short_window_merges():
    """Trial 69 of the same row (``--prior-rel-std 0.1 --trial 69``): the search ended
    with ``k_sh`` 8.9 % high and theta 2.70 % high, and the stiffness restarts, screened
    on the 3 s window, came back to it. Screened on a window twice as long (all of
    these 8 s records), the restart at ``k_sh e^0.1`` reaches a basin near the truth,
    lower in ``-2 log L`` by more than 5, with theta within 1 % (``-s`` prints both)."""
    recs, prior, kw = _coulomb_p10(69)
    fit = _fit(recs, prior, **kw)
    window = _fit(recs, prior, search=bk.JointSearch(restarts=bk.Restarts(long=())), **kw)
    fall = _m2ll(window, recs) - _m2ll(fit, recs)
    print(f"theta {100 * (fit.theta_ / 0.02 - 1):+.2f} % against "
          f"{100 * (window.theta_ / 0.02 - 1):+.2f} % without the long window's restarts, "
          f"-2 log L {fall:+.4g} lower")
    assert window.theta_ > 1.02 * 0.02
    assert fall > 5.0
    assert fit.theta_ == pytest.approx(0.02, rel=0.01)


def test_ringing_restarts_reach_a_basin_a_stiffness_shift_alone_does_not(monkeypatch):
    """Trial 18 of the same row (``--prior-rel-std 0.1 --trial 18``): the search ended
    with ``k_sh`` 7.7 % low, ``J_M`` 6.8 % high and theta 4.50 % low, and every
    stiffness restart came back to it. Shifted with ``J_M`` too (``Restarts.ringing``),
    the ringing's frequency moves into a basin near the truth, lower in ``-2 log L`` by
    more than 3, with theta within 2 %; screened for as few iterations as the other
    restarts, they stop on the way (``-s`` prints the three)."""

    recs, prior, kw = _coulomb_p10(18)
    fit = _fit(recs, prior, **kw)
    alone = _fit(recs, prior, search=bk.JointSearch(restarts=bk.Restarts(ringing=())), **kw)
    monkeypatch.setattr(_search, "RINGING_SCREEN_ITER", _search.RESTART_SCREEN_ITER)
    short = _fit(recs, prior, **kw)
    fall = _m2ll(alone, recs) - _m2ll(fit, recs)
    print(f"theta {100 * (fit.theta_ / 0.02 - 1):+.2f} % against "
          f"{100 * (alone.theta_ / 0.02 - 1):+.2f} % without the ringing restarts and "
          f"{100 * (short.theta_ / 0.02 - 1):+.2f} % with a screen of "
          f"{_search.RESTART_SCREEN_ITER} iterations; -2 log L {fall:+.4g} lower")
    assert alone.theta_ < 0.96 * 0.02
    assert short.theta_ == alone.theta_  # the short screen stops them on the way
    assert fall > 3.0
    assert fit.theta_ == pytest.approx(0.02, rel=0.02)


def test_a_search_again_from_a_fit_whose_friction_underflowed(coulomb):
    """The misfit restart searches again from the first fit's linear parameters; a
    friction that fit drove to 0 (its logarithm below the floats' range) raised ``math
    domain error`` there, which stopped ``benchmarks/robustness_joint.py --trials 20
    --seed 5`` at a441c56 and at 51ebc1f. It now starts from the prior's value. (The
    viscous model's search ends too far from the prior on these records, which the
    search refuses before its uncertainty: allowed here, so that it runs on.)"""
    est = bk.JointIdentifier(bk.TwoMassDrive(**P_TRUE), workers=1, friction="viscous",
                             actuator=None, interval=bk.FisherInterval(),
                             allow_far_from_prior=True)
    again = est._fit(coulomb, anchor=bk.TwoMassDrive(**{**P_TRUE, "f_sh": 0.0}))
    assert math.isfinite(again["theta_"])


def test_a_loop_found_after_the_search_is_searched_again():
    """The stiff drive's exact angles with friction and a 1 ms loop. The loop joins the
    model after the search, whose linear parameters have absorbed its lag;
    refitted from there, theta stopped 0.47 % off on these noise-free angles (on encoder
    records, tens of the quantisation's standard errors: 0 of 50 intervals covered the
    truth in ``benchmarks/real_drive.py``). Searched again with the loop in it, the fit
    lands on the truth."""
    recs = [bk.Record.from_positions(t, u, *phi)
            for t, u, phi in _reference_angles(OTHER, 0.02, fc=(0.01, 0.02), tau_i=1e-3)]
    fit = _fit(recs, OTHER, interval=bk.FisherInterval())
    assert {c.term: c.kept for c in fit.choices_} == {"friction": True, "actuator": True}
    assert fit.theta_ == pytest.approx(0.02, rel=1e-5)
    assert fit.tau_i_ == pytest.approx(1e-3, rel=1e-4)
    assert fit.params_["J_M"] == pytest.approx(OTHER["J_M"], rel=1e-4)


def test_a_kept_loop_is_searched_again_from_each_of_its_starts():
    """The search again with a kept loop starts at the prior's point with each of the
    lag's starts (TAU_START_SAMPLES), not at the lag the test fitted, which comes from
    linear parameters that absorbed it (docs/validation/real-drives.md, trial 157); a
    term searched already keeps the fitted value."""
    from dataclasses import replace
    from types import SimpleNamespace

    from backlashkit.identify._model import LINEAR_PARAMS, rel_std
    from backlashkit.identify._problem import build_problem
    from backlashkit.identify._search import research_anchors
    from backlashkit.identify.search import JointSearch
    from backlashkit.identify.terms import TAU_START_SAMPLES, actuator_term

    recs = _records(P_TRUE, THETA, tau_i=1e-3, seed=5)
    pb, _ = build_problem(bk.TwoMassDrive(**P_TRUE), recs, rel_std(0.3, LINEAR_PARAMS),
                          None, JointSearch(), "paper", 1)
    loop = actuator_term("auto")
    big = pb.with_params(loop.params, loop.floors(recs), loop.scales(recs))
    anchor = {n: math.log(P_TRUE[n]) for n in pb.free}
    fitted = SimpleNamespace(z=np.r_[math.log(THETA), [anchor[n] + 0.1 for n in pb.free],
                                     math.log(0.3e-3)])
    starts = research_anchors(big, fitted, anchor, [loop], recs)
    assert len(starts) == len(TAU_START_SAMPLES)
    for z, x in zip(starts, TAU_START_SAMPLES, strict=True):
        assert z[:-1].tolist() == [anchor[n] for n in pb.free]
        assert z[-1] == pytest.approx(math.log(x * TS))
    again = research_anchors(big, fitted, anchor, [replace(loop, searched=True)], recs)
    assert len(again) == 1 and again[0][-1] == fitted.z[-1]


def test_starts_of_the_lag_that_land_together_are_searched_once(monkeypatch):
    """Paper A's drive with a 1 ms loop: the lag is free in the first window, which takes
    its starts to the same candidates, so the search again continues only the first of
    them (the others stop, ``locate(..., seen=)``); the estimate is the one of searching
    every start to the end."""
    from backlashkit.identify import _search

    recs = _records(P_TRUE, THETA, tau_i=1e-3, seed=5)
    real = _search.locate
    stopped = []

    def counted(*args, **kw):
        out = real(*args, **kw)
        if kw.get("seen") is not None:
            stopped.append(out is None)
        return out

    monkeypatch.setattr(_search, "locate", counted)
    fit = _fit(recs, P_TRUE, friction="viscous")
    assert fit.tau_i_ > 0
    assert stopped[0] is False and any(stopped), stopped
    monkeypatch.setattr(_search, "locate", lambda *a, seen=None, **kw: real(*a, **kw))
    every = _fit(recs, P_TRUE, friction="viscous")
    assert fit.theta_ == pytest.approx(every.theta_, rel=1e-9)
    assert fit.tau_i_ == pytest.approx(every.tau_i_, rel=1e-6)


def test_one_quantised_speed_is_noted(encoder, coulomb):
    """A record with one encoder speed and one analogue speed is not fitted as
    angles; the warning says so and what to give instead."""
    mixed = [bk.Record(e.t, e.torque, e.w_motor, c.w_load, name=e.name)
             for e, c in zip(encoder, coulomb, strict=True)]
    with pytest.warns(bk.errors.QuantisedSpeedsWarning,
                      match=r"a=0.942: w_motor is quantised to steps of 0.383 rad/s \(an "
                            r"encoder of about 16384 counts per revolution.*but the other "
                            r"speed is not.*Record.from_positions"):
        fit = _fit(mixed, P_TRUE)
    assert fit.measured_ == ["speeds", "speeds"]


def _encoder_files(tmp_path, scale: float | None = None) -> tuple[list[str], Path]:
    """Paper A's two records as 16 384-count encoder counts (scipy reference), and a
    prior file of the true linear parameters; with ``scale``, the angles in rad times
    ``scale`` instead of the counts."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(T_END, TS)
    enc = bk.Encoder(COUNTS)
    paths = []
    for a in (A1, A2):
        u = bk.signals.step_down(t, a, t_s=T_STEP)
        phi = reference_angles(drive, t, u, initial_state=drive.steady_state(a))
        path = tmp_path / f"enc_{a:.3g}.csv"
        counts = [enc.counts(p + off * enc.resolution) for p, off in zip(phi, (0.3, 0.7),
                                                                          strict=True)]
        if scale is not None:
            counts = [c * enc.resolution * scale for c in counts]
        write_csv(path, {"t": t, "torque": u, "phi_motor": counts[0], "phi_load": counts[1]})
        paths.append(str(path))
    prior = tmp_path / "prior.toml"
    prior.write_text("[drive]\n" + "".join(f"{k} = {x!r}\n" for k, x in P_TRUE.items()))
    return paths, prior


def test_angle_unit_mistakes_are_named_as_such(tmp_path, capsys):
    """Angles in degrees were refused with "deg/s read as rad/s? then give --speed-unit
    deg/s", an option refused for angles; a quadrature encoder's lines given for its
    counts answer theta 4 times too large (the angles' scale), where the note said
    "check the units of the speeds (rpm read as rad/s?)" (a QA pass)."""
    (tmp_path / "deg").mkdir()
    paths, prior = _encoder_files(tmp_path / "deg", scale=180.0 / math.pi)
    assert cli_main(["identify", *paths, "--drive", str(prior), "--angles"]) == 2
    err = capsys.readouterr().err
    assert ("check the units: angles in deg read as rad? then give the angles in rad; else "
            "the time's units, the columns (phi_motor and phi_load swapped?)") in err, err
    paths, prior = _encoder_files(tmp_path)
    assert cli_main(["identify", *paths, "--drive", str(prior), "--counts-per-rev",
                     str(COUNTS // 4), "--interval", "fisher", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    notes = out["notes"]
    assert out["theta"] == pytest.approx(4 * THETA, rel=THETA_RTOL)  # the angles' scale
    assert any("the encoders' lines given for their counts (a quadrature encoder counts 4 "
               "per line)? then give --counts-per-rev 4 times larger" in n
               for n in notes), notes


def test_a_misfit_of_encoder_angles_is_said_of_the_angles():
    """The correlated residual of angles fitted with the linear parameters held at a
    prior 30 % off was said of the speeds (``w_M``), with the speed noise model's remedy
    (``try noise_model=ARNoise()``), which does not apply to angles (a QA pass)."""
    recs = _encoder_records(P_TRUE, THETA, seed=0)
    wrong = {**P_TRUE, "k_sh": 1.3 * P_TRUE["k_sh"]}
    with pytest.warns(bk.CorrelatedResidualsWarning) as caught:
        _fit(recs, wrong, prior_rel_std=0, interval=bk.FisherInterval())
    said = [str(w.message) for w in caught
            if issubclass(w.category, bk.CorrelatedResidualsWarning)]
    assert all("the residual of phi_" in m and "counts_per_rev" in m and "ARNoise" not in m
               for m in said), said


def test_cli_reads_encoder_counts(tmp_path, capsys):
    """``identify --counts-per-rev N`` reads the angles phi_motor, phi_load as counts
    and fits them."""
    paths, prior = _encoder_files(tmp_path)
    assert cli_main(["identify", *paths, "--drive", str(prior), "--counts-per-rev",
                     str(COUNTS), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert abs(out["theta"] / THETA - 1) < THETA_RTOL
    # the interval is the quantisation's, narrower than white noise's here
    assert out["interval"] == "quantisation"
    assert 0.3 * out["std_fisher"] < out["std"] < out["std_fisher"]
    # asked for the Fisher interval, which assumes white noise: told it is replaced
    assert cli_main(["identify", *paths, "--drive", str(prior), "--counts-per-rev",
                     str(COUNTS), "--interval", "fisher"]) == 0
    out = capsys.readouterr().out
    assert "fit % (phi_M, phi_L) = " in out, out
    assert "not the one asked for (FisherInterval())" in out, out
    assert cli_main(["identify", *paths, "--drive", str(prior), "--json"]) == 2
    assert "no column 'w_motor'" in capsys.readouterr().err
    # the refusal names the flags, not the library's parameters (the QA pass's finding)
    assert cli_main(["identify", *paths, "--drive", str(prior), "--counts-per-rev",
                     str(COUNTS), "--speed-unit", "rpm"]) == 2
    err = capsys.readouterr().err
    assert ("--speed-unit does not apply to angles (in rad, or in counts with "
            "--counts-per-rev): leave it out, got --speed-unit rpm") in err
    assert "speed_unit" not in err


def test_term_kept_by_the_test_or_by_the_shift_of_theta():
    """A term is kept where the likelihood-ratio test calls for it, or where it lowers
    -2 log L at all and dropping it moves theta by more than KEEP_SHIFT standard
    errors; the reason says which."""
    from backlashkit.identify.terms import KEEP_SHIFT, TermChoice

    by_test = TermChoice.decide("actuator", 29.5, 6.63, 0.1)
    by_shift = TermChoice.decide("actuator", 5.0, 6.63, KEEP_SHIFT + 2)
    no_gain = TermChoice.decide("actuator", -0.5, 6.63, KEEP_SHIFT + 2)
    small = TermChoice.decide("actuator", 5.0, 6.63, KEEP_SHIFT / 2)
    assert [c.kept for c in (by_test, by_shift, no_gain, small)] == [True, True, False, False]
    assert "current loop kept: it lowers -2 log L by 29.5 > 6.63" in by_test.reason()
    assert "but without it theta moves by 3 of its standard errors (> 1.0)" in by_shift.reason()
    assert "dropped" in small.reason() and "theta moves by 0.5" in small.reason()
    # a larger fit ending higher than the nested one found nothing: no number to read
    assert "ends no lower" in no_gain.reason() and "-0.5" not in no_gain.reason()
    assert "stopped short" not in no_gain.reason()
    # far higher: the larger model's search fell short of the one it contains
    short = TermChoice.decide("friction", -5.8, 9.21, 0.0)
    assert "its search may have stopped short" in short.reason(), short.reason()
    # estimated but not called for: the interval spans the model not chosen too
    cis = ((0.034, 0.036), (0.035, 0.037))
    assert TermChoice.decide("actuator", 5.0, 6.63, 3.0, True, cis).other_ci95 == cis[1]
    assert TermChoice.decide("actuator", 5.0, 6.63, 0.5, True, cis).other_ci95 == cis[0]
    assert TermChoice.decide("actuator", 9.0, 6.63, 3.0, True, cis).other_ci95 is None
    floor = TermChoice.decide("actuator", 3.0, 6.63, 3.0, False, cis)
    assert not floor.kept and floor.other_ci95 is None
    # a fall beyond ESTIMATED_FALL of the threshold pins the term down whatever its
    # Fisher check says (trial 135 of the second drive with friction and the loop:
    # 4.47, 1.8 SE)
    fell = TermChoice.decide("actuator", 4.5, 6.63, 1.8, False, cis)
    assert fell.kept and fell.determined and fell.other_ci95 == cis[1]
    # a Fisher interval reaching 0 or infinity bounds nothing: the interval is not spanned
    for unbounded in ((-821.0, 821.0), (-np.inf, np.inf), (0.03, np.inf)):
        assert TermChoice.decide("actuator", 4.5, 6.63, 0.5, True,
                                 (unbounded, cis[1])).other_ci95 is None
    # the reason names why a shift beyond KEEP_SHIFT did not keep it
    assert "do not pin its value down" in floor.reason() and not floor.determined
    assert "pin" not in small.reason()
    assert "spans the other model's too" in TermChoice.decide(
        "actuator", 5.0, 6.63, 3.0, True, cis).reason()
    # a score-test drop just under its limit does not print as the limit (the QA pass
    # read "by 0.5, less than 0.5")
    screened = TermChoice("actuator", False, 0.4996, 6.63, 0.1, screened=True).reason()
    assert "0.499 lower with it, under 0.5" in screened
    # a fit without the term that stopped before converging has no theta to compare
    # (the QA pass's 80 s records from rest read "theta moves by 0" beside a fall of 2e7)
    unconverged = TermChoice.decide("friction", 2.09e7, 9.21, math.nan)
    assert unconverged.kept and "moves by" not in unconverged.reason()
    assert "stopped before converging" in unconverged.reason()
    assert not TermChoice.decide("friction", 5.0, 9.21, math.nan).kept


class _LinearRows:
    """A residual that is linear in its parameters, ``r = a z - b``, for
    :func:`backlashkit.identify._score.linearise`."""

    def __init__(self, a, b):
        self.a, self.b = a, b

    def at(self, z):
        return self.a @ z - self.b

    def jacobian(self, z, r):
        return self.a


def test_a_term_on_its_floor_leaves_theta_s_move_measured():
    """A nuisance whose column is zero (a Coulomb torque on its floor, the QA pass's
    filtered encoder speeds) makes the information singular: every ``std`` is inf,
    and the tests' shift of theta, measured in it, printed "moves by 0" beside a fall
    of 588. ``theta_std`` holds that direction instead: theta's standard error in the
    model without the column, and the same as ``std[0]`` where nothing is singular."""
    from backlashkit.identify._score import linearise

    rng = np.random.default_rng(7)
    a = rng.normal(size=(50, 3))
    b = rng.normal(size=50)
    seen = linearise(_LinearRows(a, b), np.zeros(3))
    assert seen.theta_std == seen.std[0] == math.sqrt(np.linalg.inv(a.T @ a)[0, 0])
    floored = linearise(_LinearRows(np.column_stack([a, np.zeros(50)]), b), np.zeros(4))
    assert floored.cov is None and np.all(np.isinf(floored.std))
    assert floored.theta_std == pytest.approx(seen.theta_std, rel=1e-12)
    blind = linearise(_LinearRows(np.column_stack([np.zeros(50), a[:, 1:]]), b), np.zeros(3))
    assert blind.theta_std == math.inf  # theta itself unseen: no measure


def _loop_fitted_and_scored(recs, monkeypatch):
    """Fit with the loop's score screen off, so the loop is always fitted: the score
    test's prediction and the fitted test's choice of the loop."""
    import backlashkit.identify._score as score_mod
    import backlashkit.identify._search as search_mod

    seen = {}
    real = search_mod.score_test

    def scored(*args):
        seen["score"] = real(*args)
        return seen["score"]

    monkeypatch.setattr(score_mod, "SCREEN_DROP", -np.inf)
    monkeypatch.setattr(search_mod, "score_test", scored)
    fit = _fit(recs, P_TRUE)
    monkeypatch.undo()
    return seen["score"], {c.term: c for c in fit.choices_}["actuator"], fit


def test_score_test_predicts_the_fit_with_the_loop(monkeypatch):
    """Where the drive has a 1 ms loop, the score test at the fit without it predicts
    what the fit with it finds: the fall of -2 log L and the loop's time constant to
    within a fourth (benchmarks/score_screen.py: fall / rise 0.86-1.11, the medians
    of its scenarios), far above the screen, so the loop is fitted and kept."""
    score, choice, fit = _loop_fitted_and_scored(
        _records(P_TRUE, THETA, tau_i=1e-3, seed=5), monkeypatch)
    assert choice.kept and not score.screened
    assert score.drop == pytest.approx(choice.rise, rel=0.25)
    assert score.value == pytest.approx(fit.tau_i_, rel=0.25)


def test_ideal_records_drop_the_loop_unfitted_as_the_fit_would(monkeypatch):
    """On an ideal drive the score test predicts too small a fall to pin a loop down,
    so the loop is dropped without fitting it, and the same fit with the loop fitted
    drops it too, without widening the interval: the screen changes no answer."""
    recs = _records(P_TRUE, THETA, seed=3)
    fit = _fit(recs, P_TRUE)
    loop = {c.term: c for c in fit.choices_}["actuator"]
    assert loop.screened and not loop.kept and loop.rise < SCREEN_DROP
    assert "current loop dropped unfitted" in loop.reason()
    score, fitted, slow = _loop_fitted_and_scored(recs, monkeypatch)
    assert score.drop == loop.rise and not fitted.screened
    assert not fitted.kept and fitted.other_ci95 is None
    assert (slow.theta_, slow.ci95_) == (fit.theta_, fit.ci95_)


#: The fitted model's Fisher standard error of theta at its estimate, with the noise
#: level it estimated, against the Cramér-Rao bound at the truth with the SNR's noise
#: level: one 40 dB record pair moves both by a few per cent at most (0.4 % here).
CRB_RTOL = 0.10
LARGER_MODEL = ("theta", "J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "fc_M", "fc_L", "tau_i")


def _crb_both(drive, estimate, tau_i, **kw):
    t = bk.signals.time_grid(T_END, TS)
    a, b = (bk.cramer_rao_bound(drive, t, bk.signals.step_down(t, lev, t_s=T_STEP),
                                snr_db=SNR, estimate=estimate, tau_i=tau_i, **kw)
            for lev in (A1, A2))
    return a + b


def test_crb_of_the_larger_model_matches_the_fits_standard_error():
    """The bound with the Coulomb torques and the loop's lag estimated, computed by
    central differences of the kernel from the steady state, agrees with the standard
    error the joint estimator derives from its own Jacobian when it fits those terms on
    the scipy reference's records."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    recs = _records(P_TRUE, THETA, fc=(0.01, 0.02), tau_i=1e-3, seed=10)
    fit = _fit(recs, P_TRUE, friction="coulomb", interval=bk.FisherInterval())
    assert fit.estimated_ == LARGER_MODEL
    crb = _crb_both(drive, LARGER_MODEL, 1e-3, initial_state="steady")
    assert fit.std_ == pytest.approx(crb.theta_std, rel=CRB_RTOL)
    assert crb.theta_std > _crb_both(drive, LARGER_MODEL[:-1], 1e-3,
                                     initial_state="steady").theta_std


def test_crb_with_a_negligible_loop_is_the_bound_without_one():
    """The loop's path (packed rows, a fourth state) against the plain batch path: a
    10 us lag (the kernel refuses one a million times shorter than the sample time) moves
    the bound by 6e-5."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    rest = np.zeros(3)
    plain = _crb_both(drive, "all", 0.0, initial_state=rest).theta_std
    tiny = _crb_both(drive, "all", 1e-5, initial_state=rest).theta_std
    assert tiny == pytest.approx(plain, rel=1e-3)


@pytest.mark.parametrize("kw, match", [
    ({"estimate": ["theta", "tau_i"]}, "at value 0"),
    ({"estimate": ["theta", "fc_M"]}, "at value 0"),
    ({"initial_state": "rest"}, "'steady'"),
    ({"tau_i": -1e-3}, "tau_i"),
])
def test_crb_refuses_what_it_cannot_bound(kw, match):
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(1.0, TS)
    with pytest.raises(InputError, match=match):
        bk.cramer_rao_bound(drive, t, bk.signals.step_down(t, A1, t_s=0.5), snr_db=SNR,
                            **{"tau_i": 1e-3 if "initial_state" in kw else 0.0, **kw})


def test_quantisation_error_is_the_encoders():
    """The errors the interval of encoder angles draws are an encoder's: its reading
    less the angle, in (-q, 0], uniform over the offsets within a count."""
    from backlashkit.identify._quantised import quantisation_error

    enc = bk.Encoder(COUNTS)
    q = enc.resolution
    phi = np.linspace(0.0, 37.3 * q, 200)
    offset = np.random.default_rng(1).uniform(0.0, q, 2000)
    err = quantisation_error(phi, offset, q)
    shifted = phi[np.newaxis, :] + offset[:, np.newaxis]
    reading = enc.counts(shifted.ravel()).reshape(shifted.shape) * q
    np.testing.assert_allclose(err, reading - shifted, atol=1e-9 * q)
    assert np.all((err > -q) & (err <= 0))
    assert np.mean(err) == pytest.approx(-q / 2, rel=0.02)
    assert np.std(err) == pytest.approx(q / np.sqrt(12), rel=0.02)


#: Trials of the interval of encoder angles: the spread of 16 estimates is known to
#: within about +-35 % (95 %, chi-square with 15 degrees of freedom).
OFFSET_TRIALS = 16


def test_encoder_interval_is_the_spread_over_the_offsets():
    """On encoder angles the standard error is the spread of theta over the encoders'
    offsets within a count (the records' only randomness here), not white noise of
    variance q^2 / 12: the white-noise one is about 1.4 times that spread, the
    quantisation's agrees with it (the figures: docs/design/real-drives.md)."""
    angles = _reference_angles(P_TRUE, THETA)
    fits = [_fit(_read_by_encoders(angles, seed), P_TRUE, friction="viscous", actuator=None,
                 interval=bk.FisherInterval()) for seed in range(OFFSET_TRIALS)]
    spread = np.std([f.theta_ for f in fits], ddof=1)
    std = np.median([f.std_ for f in fits])
    white = np.median([f.param_std_["theta"] for f in fits])
    assert 0.65 < std / spread < 1.35
    assert white / spread > 1.35
    assert all(f.interval_ == "quantisation" for f in fits)
    # the ends are the draws' quantiles: about 2 std either side, not exactly 1.96
    half = [(f.ci95_[1] - f.ci95_[0]) / (2 * f.std_) for f in fits]
    assert 1.6 < min(half) and max(half) < 2.3


def test_bootstrap_resamples_encoder_records_as_encoders_read_them(encoder):
    """A parametric bootstrap of encoder records draws its resamples as encoders read
    the model's angles (counts from a random offset), so its spread is already the
    quantisation's: its interval stays the bootstrap's, and its refits stay within a
    few spreads over the offsets (about 9e-7 rad)."""
    from backlashkit.identify._model import spans
    from backlashkit.identify._search import quantised_resample

    q = bk.Encoder(COUNTS).resolution
    sp = spans([encoder[0].with_positions(q)], "steady", 1.0, [(1.0, 1.0)])[0]
    angles = (sp.p_m[np.newaxis, :] + 0.1 * q, sp.p_l[np.newaxis, :] - 0.2 * q)
    drawn = quantised_resample(sp, angles, np.random.default_rng(0))
    assert drawn.quantum == pytest.approx(q) and drawn.has_positions
    for got, exact in zip((drawn.phi_motor, drawn.phi_load), angles, strict=True):
        steps = got / q
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
        assert np.max(np.abs(got - got[0] - (exact[0] - exact[0, 0]))) < q
    fit = _fit(encoder, P_TRUE, friction="viscous", actuator=None,
               interval=bk.ParametricBootstrap(4, seed=1))
    assert fit.interval_ == "bootstrap"
    assert np.all(np.abs(fit.bootstrap_thetas_ - fit.theta_) < 5e-6)
    assert np.ptp(fit.bootstrap_thetas_) > 0


def test_a_prior_on_the_coulomb_torques_pulls_them(coulomb):
    """A prior may give the Coulomb torques with a relative std (issue 20: "the prior
    TOML may give these terms, with their uncertainty"). With fc_M given 30 % above
    the truth at a 1 % std, the fit moves fc_M from the free fit's value towards the
    prior's as the Gaussian update of the free fit's estimate by that prior predicts,
    ``fc + v / (v + s^2) (prior - fc)`` with variance ``1 / (1 / v + 1 / s^2)`` (``v``
    the free fit's variance of fc_M, ``s`` the prior's std): within one standard error,
    which the model's nonlinearity leaves between the two."""
    prior = bk.TwoMassDrive(**P_TRUE, fc_M=0.013, fc_L=0.02)
    linear = dict.fromkeys(P_TRUE, 0.3)
    fits = [bk.JointIdentifier(prior, prior_rel_std=rel, friction="coulomb", actuator=None,
                               interval=bk.FisherInterval(), workers=1).fit(coulomb)
            for rel in (linear, {**linear, "fc_M": 0.01})]
    free, pulled = (f.fc_M_ for f in fits)
    v, s2 = fits[0].param_std_["fc_M"] ** 2, (0.01 * 0.013) ** 2
    std = math.sqrt(1.0 / (1.0 / v + 1.0 / s2))
    assert pulled == pytest.approx(free + v / (v + s2) * (0.013 - free), abs=std)
    assert fits[1].param_std_["fc_M"] == pytest.approx(std, rel=0.1)


def test_a_wrong_tight_prior_is_flagged_as_a_conflict(coulomb):
    """A prior's value 30 % off with a 1 % std pulls the estimate to it, and the
    others with it; the pull of the data says so (``prior_pull_``): the free fit's
    distance from the prior over the spread of that distance, ``(free - prior) /
    sqrt(v + s^2)`` (the Gaussian update's), and the fit warns, naming the torque. The
    same prior at the truth's value pulls by less than its limit and says nothing."""
    linear = dict.fromkeys(P_TRUE, 0.3)
    fits = {}
    for fc_m in (0.01, 0.013):
        prior = bk.TwoMassDrive(**P_TRUE, fc_M=fc_m, fc_L=0.02)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fits[fc_m] = bk.JointIdentifier(
                prior, prior_rel_std={**linear, "fc_M": 0.01}, friction="coulomb",
                actuator=None, interval=bk.FisherInterval(), workers=1).fit(coulomb)
        fits[fc_m].conflicts = [str(w.message) for w in caught
                                if issubclass(w.category, PriorMismatchWarning)]
    free = bk.JointIdentifier(bk.TwoMassDrive(**P_TRUE, fc_M=0.013, fc_L=0.02),
                              prior_rel_std=linear, friction="coulomb", actuator=None,
                              interval=bk.FisherInterval(), workers=1).fit(coulomb)
    v, s2 = free.param_std_["fc_M"] ** 2, (0.01 * 0.013) ** 2
    expected = (free.fc_M_ - 0.013) / math.sqrt(v + s2)
    wrong = fits[0.013]
    assert wrong.prior_pull_["fc_M"] == pytest.approx(expected, rel=0.2)
    assert abs(expected) > 2 * PRIOR_CONFLICT_Z
    assert len(wrong.conflicts) == 1
    assert wrong.conflicts[0].startswith(
        f"the data pull fc_M {abs(wrong.prior_pull_['fc_M']):.1f} standard deviations from "
        "the prior's values (relative stds fc_M 0.01): a prior-data conflict")
    assert abs(fits[0.01].prior_pull_["fc_M"]) < PRIOR_CONFLICT_Z
    assert fits[0.01].conflicts == []


def test_a_known_loop_slower_than_the_mechanics_is_refused(coulomb, tmp_path, capsys):
    """A current loop of 1 s (1 for 1 ms?) did not finish in a QA pass; one of 50 ms
    was refused for another cause. Both are refused at once now, the command line's
    from the flag or the drive file's [actuator] table alike; a 10 ms loop, slow but
    below the shaft's ringing period (the refusal gives it: 48 ms on paper A's drive),
    is accepted."""
    prior = bk.TwoMassDrive(**P_TRUE)
    for tau in (1.0, 0.05):
        with pytest.raises(InputError, match=(
                rf"^the current loop's time constant {tau:g} s is not below the drive's "
                r"shaft ringing period \([\d.]+ ms, from the prior\): .* give its time "
                r"constant in s \(1 ms = 0.001\), or fit it with actuator='auto'$")):
            bk.JointIdentifier(prior, actuator=bk.CurrentLoop(tau)).fit(coulomb)
    bk.JointIdentifier(prior, actuator=bk.CurrentLoop(0.01))._check()
    paths, toml = _files(coulomb, tmp_path)
    assert cli_main(["identify", *paths, "--drive", toml, "--current-loop", "1"]) == 2
    assert capsys.readouterr().err.strip().endswith("or fit it with --current-loop auto")
    with open(toml, "a") as f:
        f.write("[actuator]\ntau_i = 1.0\n")
    assert cli_main(["identify", *paths, "--drive", toml]) == 2
    assert "the current loop's time constant 1 s" in capsys.readouterr().err


def test_cli_notes_where_given_coulomb_torques_go_unused(tmp_path, capsys):
    """Records without Coulomb friction and a drive file that gives its torques with a
    prior std: the joint fit drops the friction, and its prior with it; paper A's
    viscous model leaves them out. Each says so."""
    paths, toml = _files(_records(P_TRUE, THETA, seed=3), tmp_path)
    with open(toml, "a") as f:
        f.write("fc_M = 0.01\nfc_L = 0.02\n[uncertainty]\nfc_M = 0.2\nfc_L = 0.2\n")
    assert cli_main(["identify", *paths, "--drive", toml, "--interval", "fisher",
                     "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["friction"] == "viscous"
    assert ("the prior on fc_M, fc_L ([uncertainty]) was dropped with the Coulomb friction: "
            "the data do not call for it") in " ".join(doc["notes"])
    assert cli_main(["identify", paths[1], "--drive", toml, "--method", "regression",
                     "--json"]) == 0
    notes = " ".join(json.loads(capsys.readouterr().out)["notes"])
    assert ("the Coulomb torques fc_M, fc_L of the [drive] table are not in paper A's "
            "viscous model") in notes


def test_a_known_loop_the_data_refute_is_flagged():
    """Records of a 1 ms loop with Coulomb friction, fitted with the loop fixed: at
    10 ms the other parameters make up for it and theta ends over 5 % low, which was
    said nowhere (found by a QA pass); refitted with the lag free the model falls far below the
    terms' threshold, and the fit warns, naming the loop. Fixed at the truth, the
    refit's fall stays under the threshold and nothing is said."""
    recs = _records(P_TRUE, THETA, fc=(0.01, 0.02), tau_i=1e-3)
    threshold = bk.identify.terms.actuator_term(bk.CurrentLoop(1e-3)).threshold
    for tau, flagged in ((1e-2, True), (1e-3, False)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fit = _fit(recs, P_TRUE, actuator=bk.CurrentLoop(tau))
        said = [str(w.message) for w in caught if "another current loop" in str(w.message)]
        fall, value = fit.fixed_tests_["tau_i"]
        assert (fall > threshold) is flagged and len(said) == int(flagged)
        if flagged:
            assert fit.theta_ < 0.95 * THETA
            assert value < tau / 2  # towards the truth
            assert said[0].startswith(
                "the data call for another current loop than the one given (tau_i 10 ms): "
                "refitted with its lag free, the model moves it to ")
            assert said[0].endswith("check it, or fit it with actuator='auto'")


def test_a_prior_on_the_loop_fits_it_about_the_known_value(tmp_path, capsys):
    """A known loop with a relative std (issue 20: the prior may give the terms with
    their uncertainty): held through the search, then fitted about its value. A 1.5 ms
    loop at 50 % on records of a 1 ms one ends near the truth; a 3 ms one at 5 % is
    pulled towards it and the fit says the prior and the data conflict. The command
    line reads the value from [actuator] and its std from [uncertainty]."""
    recs = _records(P_TRUE, THETA, fc=(0.01, 0.02), tau_i=1e-3)
    linear = dict.fromkeys(P_TRUE, 0.3)
    loose = _fit(recs, P_TRUE, actuator=bk.CurrentLoop(1.5e-3),
                 prior_rel_std={**linear, "tau_i": 0.5})
    assert "tau_i" in loose.estimated_ and loose.tau_i_ == pytest.approx(1e-3, rel=0.2)
    assert loose.theta_ == pytest.approx(THETA, rel=THETA_RTOL)
    assert abs(loose.prior_pull_["tau_i"]) < PRIOR_CONFLICT_Z
    with pytest.warns(PriorMismatchWarning, match=r"^the data pull tau_i [\d.]+ standard "
                                                  r"deviations from the prior's values"):
        tight = _fit(recs, P_TRUE, actuator=bk.CurrentLoop(3e-3),
                     prior_rel_std={**linear, "tau_i": 0.05})
    assert 1e-3 < tight.tau_i_ < 3e-3
    paths, toml = _files(recs, tmp_path)
    with open(toml, "a") as f:
        f.write("[actuator]\ntau_i = 0.0015\n[uncertainty]\n"
                + "".join(f"{n} = 0.3\n" for n in P_TRUE) + "tau_i = 0.5\n")
    assert cli_main(["identify", *paths, "--drive", toml, "--interval", "fisher",
                     "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["tau_i"] == pytest.approx(loose.tau_i_, rel=1e-6)
    assert "tau_i" in doc["estimated"] and "tau_i" in doc["prior_pull"]


@pytest.mark.parametrize("actuator, std, match", [
    ("auto", 0.3, r"^a relative std of tau_i is given \(prior_rel_std\['tau_i'\] = 0.3\), "
                  r"but no known loop to fit it about: give its time constant "
                  r"\(actuator=CurrentLoop\(tau_i\)\)$"),
    (bk.CurrentLoop(1e-3), 0.0, r"a std of 0 is the known loop itself; give a std > 0"),
])
def test_a_loop_prior_without_a_loop_to_fit_is_refused(coulomb, actuator, std, match):
    with pytest.raises(InputError, match=match):
        bk.JointIdentifier(bk.TwoMassDrive(**P_TRUE), actuator=actuator,
                           prior_rel_std={"k_sh": 0.1, "tau_i": std}).fit(coulomb)


def test_a_fixed_loop_is_named_where_the_fit_fails():
    """A fixed loop may be the wrong one: the refusals name it beside the prior."""
    from backlashkit.identify._search import refuse_unexplained
    from backlashkit.identify.terms import Term

    fixed = bk.JointIdentifier(bk.TwoMassDrive(**P_TRUE), actuator=bk.CurrentLoop(0.01),
                               friction="viscous")
    assert [str(p) for p in fixed._missing_terms()] == [
        "friction='auto'", " or ", "actuator='auto'"]
    recs = [bk.identify.Record(np.arange(3.0), np.zeros(3), np.zeros(3), np.zeros(3),
                               name="exp1.csv")]
    with pytest.raises(InputError, match=r"check the columns, units and the prior, and the "
                                         r"fixed current loop \(try actuator='auto'\)$"):
        refuse_unexplained(recs, np.array([[-3.0, 50.0]]),
                           [Term("actuator", ("tau_i",), "fixed", (0.01,))])


@pytest.mark.parametrize("fc, rel, kw, match", [
    ((0.0, 0.02), {"fc_M": 0.1}, {},
     r"fc_M is given \(prior_rel_std\['fc_M'\] = 0.1\), but the prior's fc_M is 0: give "
     r"its value in N m \(TwoMassDrive\(fc_M=...\)\)"),
    ((0.01, 0.02), {"fc_L": 0.1}, {"friction": "viscous"},
     r"friction='viscous' does not fit it: use friction='coulomb' or friction='auto', or "
     r"remove it"),
    ((0.01, 0.02), {"fc_M": 0.0}, {}, r"fitted, not held at the prior's value; give a std > 0"),
    ((0.01, 0.02), {"fs_M": 0.1}, {}, r"prior_rel_std has unknown parameter 'fs_M'"),
])
def test_a_prior_std_the_fit_cannot_use_is_refused(coulomb, fc, rel, kw, match):
    prior = bk.TwoMassDrive(**P_TRUE, fc_M=fc[0], fc_L=fc[1])
    with pytest.raises(InputError, match=match):
        bk.JointIdentifier(prior, prior_rel_std=rel, **kw).fit(coulomb)


@pytest.mark.parametrize("table, ending", [
    ("J_M = 0.1\nfc_M = 0.5\n",
     "a relative std of fc_M is given ({toml}: [uncertainty] fc_M = 0.5), but the prior's "
     "fc_M is 0: give its value in N m (fc_M in the [drive] table of {toml})"),
    ("k_sh = 0.1\ntau_i = 0.3\n",
     "a relative std of tau_i is given ({toml}: [uncertainty] tau_i = 0.3), but no known "
     "loop to fit it about: give its time constant (--current-loop S)"),
])
def test_cli_names_the_drive_file_where_a_term_prior_is_wrong(coulomb, tmp_path, capsys,
                                                              table, ending):
    """The refusals above in the command line's words: the table's entry and the file."""
    paths, toml = _files(coulomb, tmp_path)
    with open(toml, "a") as f:
        f.write("[uncertainty]\n" + table)
    assert cli_main(["identify", *paths, "--drive", toml]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(ending.format(toml=toml))
    assert len(err.splitlines()) == 1


def test_the_published_drive_has_the_friction_the_model_simulated():
    """A prior's Coulomb torques start the fit; where the model has no Coulomb friction
    (friction='viscous', or 'auto' dropping it), the fitted drive has none either and
    says so, not the prior's torques (nor its breakaway torque)."""
    recs = _records(P_TRUE, THETA, seed=3)
    prior = bk.TwoMassDrive(**P_TRUE, fc_M=0.015, fc_L=0.015, fs_M=0.03)
    for friction in ("viscous", "auto"):
        fit = bk.JointIdentifier(prior, friction=friction, actuator=None,
                                 interval=bk.FisherInterval(), workers=1).fit(recs)
        assert fit.friction_ == "viscous" and (fit.fc_M_, fit.fc_L_) == (0.0, 0.0)
        assert (fit.drive_.fc_M, fit.drive_.fs_M) == (0.0, None)
