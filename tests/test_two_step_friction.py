"""Paper A's two-step method and its regression baseline on drives with Coulomb friction
(issue 20, item 3), their search-edge warning and messages (issue 21).

Records come from the independent scipy reference (``backlashkit.verify``), not from
the kernel the estimators simulate: paper A's drive (``theta* = 0.0349`` rad,
half-width) with Coulomb torques ``fc_M = 0.01``, ``fc_L = 0.02`` N m, started at the
steady state under the held torque, stepped down at ``t_s = 2`` s and recorded to
3.5 s at 1 ms (the reference takes about 0.1-0.3 s per record). The prior is the true
linear drive without Coulomb friction.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import backlashkit as bk
from backlashkit.errors import InputError, SearchEdgeWarning
from backlashkit.identify import Record, RegressionIdentifier, TwoStepIdentifier
from backlashkit.identify.decay import free_decay
from backlashkit.papers.ravanbod2002 import A1, A2, P_TRUE, THETA, protocol_records
from backlashkit.verify import reference_simulate

FC_M, FC_L = 0.01, 0.02
TS, T_STEP, DURATION = 1e-3, 2.0, 3.5
SNR_DB = 40.0
PRIOR = bk.TwoMassDrive(**P_TRUE)
#: The issue's bar on theta, relative.
BAR = 0.03


def reference_response(a: float, fc_m: float, fc_l: float):
    """Reference response to a step-down from ``a`` N m, from its steady state."""
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=fc_m, fc_L=fc_l)
    t = bk.signals.time_grid(DURATION, TS)
    w0 = (a - fc_m - fc_l) / (P_TRUE["f_M"] + P_TRUE["f_L"])
    twist = THETA + (P_TRUE["f_L"] * w0 + fc_l) / P_TRUE["k_sh"]
    return reference_simulate(drive, t, bk.signals.step_down(t, a, t_s=T_STEP),
                              initial_state=[w0, w0, twist])


def noisy(response, snr, seed: int, name: str) -> Record:
    if snr is None:
        return Record(response.t, response.torque, response.w_motor, response.w_load,
                      name=name)
    s_m, s_l = np.random.SeedSequence([seed, len(name)]).spawn(2)
    return Record(response.t, response.torque,
                  bk.signals.add_noise(response.w_motor, snr, rng=s_m),
                  bk.signals.add_noise(response.w_load, snr, rng=s_l), name=name)


@pytest.fixture(scope="module")
def coulomb():
    """Reference responses of the drive with Coulomb friction, steps a_1 and a_2."""
    return reference_response(A1, FC_M, FC_L), reference_response(A2, FC_M, FC_L)


@pytest.fixture(scope="module")
def viscous():
    """The same without Coulomb friction (paper A's drive)."""
    return reference_response(A1, 0.0, 0.0), reference_response(A2, 0.0, 0.0)


def error(theta: float) -> float:
    return theta / THETA - 1.0


def test_free_decay_matches_reference_in_the_gap(coulomb):
    """Eq. 9's decay with Coulomb friction is the load's exact motion while the shaft
    is in the gap (reference between its contact loss and impact events)."""
    r = coulomb[0]
    lost, made = [e.time for e in r.events if e.time > T_STEP][:2]
    i = np.flatnonzero((r.t > lost) & (r.t < made))
    alpha, decel = P_TRUE["f_L"] / P_TRUE["J_L"], FC_L / P_TRUE["J_L"]
    g, off = free_decay(r.t[i] - r.t[i[0]], alpha, decel)
    model = r.w_load[i[0]] * g + off
    assert np.max(np.abs(model - r.w_load[i])) < 1e-7
    g0, off0 = free_decay(r.t[i] - r.t[i[0]], alpha, 0.0)  # the paper's model is off
    assert np.max(np.abs(r.w_load[i[0]] * g0 + off0 - r.w_load[i])) > 1e-2


def test_free_decay_sticks_and_falls_linearly_without_viscosity():
    g, off = free_decay(np.array([0.0, 1.0, 2.0]), 0.0, 3.0)
    np.testing.assert_allclose(g, 1.0)
    np.testing.assert_allclose(off, [0.0, -3.0, -6.0])


@pytest.mark.parametrize("seed", range(4))
def test_regression_coulomb_within_bar_at_40db(coulomb, seed):
    """The least squares with the Coulomb torques fitted is within 3 % at 40 dB; the
    viscous one is biased low by the friction it lacks (about -1.5 %, measured)."""
    rec = noisy(coulomb[1], SNR_DB, seed, "step2")
    fit = RegressionIdentifier(PRIOR, friction="coulomb", workers=1).fit(rec)
    assert fit.friction_ == "coulomb"
    assert abs(error(fit.theta_)) < BAR
    assert 0.5 < (fit.fc_M_ + fit.fc_L_) / (FC_M + FC_L) < 1.5


def test_regression_viscous_misses_coulomb_noise_free(coulomb):
    """Noise-free: the viscous model sits 1.6 % low, the Coulomb one on the truth."""
    rec = noisy(coulomb[1], None, 0, "step2")
    vis = RegressionIdentifier(PRIOR, workers=1).fit(rec)
    cou = RegressionIdentifier(PRIOR, friction="coulomb", workers=1).fit(rec)
    assert error(vis.theta_) < -0.01
    assert abs(error(cou.theta_)) < 1e-3
    np.testing.assert_allclose([cou.fc_M_, cou.fc_L_], [FC_M, FC_L], rtol=0.02)


@pytest.mark.parametrize("seed", range(3))
def test_two_step_coulomb_within_bar(coulomb, seed):
    """Paper A's two steps with the Coulomb terms: step 2 at 40 dB, step 1 at 60 dB
    (eq. 9 locates the passage on the load speed, which at 40 dB it misses as often
    with as without friction: docs/validation/ravanbod2002.md, "Coulomb friction")."""
    rec1 = noisy(coulomb[0], 60.0, seed, "step1")
    rec2 = noisy(coulomb[1], SNR_DB, seed, "step2")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SearchEdgeWarning)  # the pre-estimate is ~10 % low
        fit = TwoStepIdentifier(PRIOR, friction="coulomb", workers=1).fit(
            rec1, final_records=rec2)
    assert fit.friction_ == "coulomb" and fit.fc_M_ + fit.fc_L_ > 0
    assert abs(error(fit.theta_)) < BAR


def test_auto_keeps_coulomb_on_coulomb_records(coulomb):
    rec = noisy(coulomb[1], SNR_DB, 3, "step2")
    fit = RegressionIdentifier(PRIOR, friction="auto", workers=1).fit(rec)
    assert fit.friction_ == "coulomb"
    assert fit.friction_lr_ > bk.identify.two_step.FRICTION_LR


def test_short_repr_before_and_after_the_fit(coulomb):
    """As JointIdentifier's: the options given, then what the fit chose (the QA pass
    met ``<TwoStepIdentifier object at 0x...>``)."""
    est = RegressionIdentifier(PRIOR, friction="auto", workers=1)
    assert repr(est) == f"RegressionIdentifier({PRIOR!r}, friction='auto', workers=1)"
    est.fit(noisy(coulomb[1], SNR_DB, 3, "step2"))
    assert repr(est).endswith(f": theta_ = {est.theta_:.4g} rad, friction_ = 'coulomb'")
    assert repr(TwoStepIdentifier(PRIOR, n_theta=0.2)) == (
        f"TwoStepIdentifier({PRIOR!r}, n_theta=0.2)")


def test_auto_keeps_viscous_on_viscous_records(viscous):
    """No Coulomb friction and the true prior: "auto" answers the viscous fit itself."""
    rec = noisy(viscous[1], SNR_DB, 1, "step2")
    vis = RegressionIdentifier(PRIOR, workers=1).fit(rec)
    auto = RegressionIdentifier(PRIOR, friction="auto", workers=1).fit(rec)
    assert auto.friction_ == "viscous" and auto.friction_lr_ < bk.identify.two_step.FRICTION_LR
    assert auto.theta_ == vis.theta_ and auto.cost_ == vis.cost_
    assert (auto.fc_M_, auto.fc_L_) == (0.0, 0.0)


def test_viscous_is_the_default_and_publishes_no_coulomb():
    rec1, rec2, prior = protocol_records(0.1, np.random.SeedSequence(7), snr1=(60.0, 60.0))
    fit = TwoStepIdentifier(prior, allow_far_from_prior=True, workers=1)
    assert fit.friction == "viscous"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SearchEdgeWarning)
        fit.fit(rec1, final_records=rec2)
    forced = TwoStepIdentifier(prior, allow_far_from_prior=True, workers=1,
                               friction="viscous")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SearchEdgeWarning)
        forced.fit(rec1, final_records=rec2)
    assert fit.friction_ == "viscous" and (fit.fc_M_, fit.fc_L_) == (0.0, 0.0)
    assert np.isnan(fit.friction_lr_)
    assert forced.theta_ == fit.theta_


@pytest.mark.parametrize("cls", [TwoStepIdentifier, RegressionIdentifier])
def test_the_viscous_model_has_no_coulomb_torques_whatever_the_prior_gives(coulomb, cls,
                                                                          monkeypatch):
    """A prior with Coulomb torques (as a drive file's ``[drive]`` table may give): the
    viscous fit is the one of the prior without them, and says so (it simulated the
    prior's torques and called them viscous before); the Coulomb fit starts from them."""
    rec1 = noisy(coulomb[0], 60.0, 0, "step1")
    rec2 = noisy(coulomb[1], SNR_DB, 0, "step2")
    given = bk.TwoMassDrive(**P_TRUE, fc_M=FC_M, fc_L=FC_L)
    finals = {"final_records": rec2} if cls is TwoStepIdentifier else {}
    recs = rec1 if cls is TwoStepIdentifier else rec2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SearchEdgeWarning)
        fits = [cls(p, workers=1).fit(recs, **finals) for p in (PRIOR, given)]
        starts = []
        fit_from = bk.identify.two_step.coulomb_fit
        monkeypatch.setattr(bk.identify.two_step, "coulomb_fit",
                            lambda *a: starts.append(a[-1]) or fit_from(*a))
        started = cls(given, friction="coulomb", workers=1).fit(recs, **finals)
    assert fits[1].friction_ == "viscous" and (fits[1].fc_M_, fits[1].fc_L_) == (0.0, 0.0)
    assert (fits[1].theta_, fits[1].cost_) == (fits[0].theta_, fits[0].cost_)
    assert started.friction_ == "coulomb" and starts[0] == (FC_M, FC_L)
    assert 0.5 < (started.fc_M_ + started.fc_L_) / (FC_M + FC_L) < 1.5


@pytest.mark.parametrize("cls", [TwoStepIdentifier, RegressionIdentifier])
def test_friction_refused_with_its_name(viscous, cls):
    rec = noisy(viscous[1], None, 0, "step2")
    with pytest.raises(InputError, match=r"^friction must be one of 'viscous', 'coulomb', "
                                         r"'auto', got 'dry'$"):
        cls(PRIOR, friction="dry").fit(rec)


def test_two_step_warns_at_the_edge_of_its_interval(viscous):
    """Noise-free, exact prior: eq. 6 comes out about 11 % low, so the truth lies above
    theta_ini (1 + 0.1) and the estimate sits on that end: the library warns."""
    rec1, rec2 = (noisy(r, None, 0, n) for r, n in zip(viscous, ("step1", "step2"),
                                                          strict=True))
    with pytest.warns(SearchEdgeWarning, match=r"at the upper end of the search interval"
                      r".*widen n_theta"):
        fit = TwoStepIdentifier(PRIOR, workers=1).fit(rec1, final_records=rec2)
    assert fit.search_edges_ == ["upper"]
    assert fit.theta_ == pytest.approx(fit.bounds_[1], rel=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SearchEdgeWarning)  # a wider interval holds it
        wide = TwoStepIdentifier(PRIOR, n_theta=0.3, workers=1).fit(rec1, final_records=rec2)
    assert wide.search_edges_ == [] and abs(error(wide.theta_)) < 1e-3


def test_step_down_messages_use_no_paper_notation(viscous):
    r = viscous[1]
    up = Record(r.t, -r.torque, -r.w_motor, -r.w_load, name="up")
    with pytest.raises(InputError) as info:
        TwoStepIdentifier(PRIOR).fit(up)
    text = str(info.value)
    assert text.startswith("up: the torque has no step-down")
    assert "held at a positive level and then dropped" in text
    for notation in ("1(t", "C_M", "eq. ", "W_1", "paper"):
        assert notation not in text
