"""Noise models of the joint estimator (``backlashkit.identify.noise``).

The fits use the short experiment of ``tests/test_identify_joint.py`` (paper A's drive,
theta* = 2 deg half-width, 0.942 N m from rest for 2 s, then 0; 4 s at Ts = 1 ms),
with white noise or with white noise passed through ``e_t = 0.8 e_{t-1} + w_t`` (the
noise of a speed measured through a first-order filter), 30 dB on both speeds.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.errors import CorrelatedResidualsWarning, InputError
from backlashkit.identify import Record
from backlashkit.identify.joint import CORRELATED_LAG1, JointIdentifier
from backlashkit.identify.noise import (
    ARNoise,
    AutoNoise,
    WhiteNoise,
    fit_ar,
    held_noise_lag1,
    innovation_ratio,
    sample_noise,
    whiten,
)
from backlashkit.identify.search import JointSearch
from backlashkit.io import write_csv

P_TRUE = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
TRUE = bk.TwoMassDrive(**P_TRUE, theta=THETA)
PRIOR = bk.TwoMassDrive(**{k: v * f for (k, v), f in zip(
    P_TRUE.items(), (1.1, 0.9, 1.15, 0.8, 1.2, 0.9), strict=True)})
CORR = 0.8


def _colored(x: np.ndarray, corr: float, rng: np.random.Generator) -> np.ndarray:
    """``x`` plus noise ``e_t = corr e_(t-1) + w_t`` at 30 dB (stationary start)."""
    e = lfilter([1.0], [1.0, -corr], rng.standard_normal(x.size + 1000))[1000:]
    return x + e * np.sqrt(np.mean(x**2) / 10**3 / np.var(e))


@pytest.fixture(scope="module")
def clean():
    t = signals.time_grid(4.0, 1e-3)
    return TRUE.simulate(t, signals.step_down(t, 0.942, t_s=2.0))


def _record(clean, corr: float, seed: int) -> Record:
    rng = np.random.default_rng(seed)
    return Record(clean.t, clean.torque, _colored(clean.w_motor, corr, rng),
                  _colored(clean.w_load, corr, rng), name="exp.csv")


@pytest.fixture(scope="module")
def colored_fits(clean):
    """The same coloured record fitted with white and with AR(2) noise."""
    rec = _record(clean, CORR, 3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        white = JointIdentifier(PRIOR, noise_model=WhiteNoise()).fit(rec)
    ar = JointIdentifier(PRIOR, noise_model=ARNoise(2)).fit(rec)
    return rec, white, ar, caught


# --- the pieces ---------------------------------------------------------------------


def test_fit_ar_recovers_a_known_process_and_agrees_with_least_squares():
    a_true = np.array([-1.2, 0.5])  # poles 0.6 +- 0.37j: stationary
    n = 200_000
    e = lfilter([1.0], np.r_[1.0, a_true], 0.3 * np.random.default_rng(0).standard_normal(n))
    a, var = fit_ar(e, 2)
    assert a == pytest.approx(a_true, abs=0.01)
    assert var == pytest.approx(0.09, rel=0.01)
    # independent: regress e_t on e_(t-1), e_(t-2) (covariance method)
    x = e - e.mean()
    lags = np.column_stack([x[1:-1], x[:-2]])
    coef, *_ = np.linalg.lstsq(lags, x[2:], rcond=None)
    assert a == pytest.approx(-coef, abs=1e-3)
    # Yule-Walker from the biased autocovariance: a stationary model, roots inside
    assert np.all(np.abs(np.roots(np.r_[1.0, fit_ar(np.cumsum(x[:5000]), 3)[0]])) < 1.0)


def test_whiten_is_the_fir_filter_a_of_q():
    rng = np.random.default_rng(1)
    e = rng.standard_normal((3, 50))
    a = np.array([0.4, -0.2, 0.1])
    assert whiten(e, a) == pytest.approx(lfilter(np.r_[1.0, a], [1.0], e, axis=-1)[:, 3:])
    # on an AR process with those coefficients, the output is the innovation
    w = rng.standard_normal(400)
    assert whiten(lfilter([1.0], np.r_[1.0, a], w), a) == pytest.approx(w[3:])


@pytest.mark.parametrize(
    ("call", "pattern"),
    [
        (lambda: fit_ar(np.ones(3), 2), r"at least 6 samples for order 2"),
        (lambda: fit_ar(np.arange(9.0), 0), r"order must be an integer >= 1, got 0"),
        (lambda: fit_ar(np.r_[np.zeros(9), np.nan], 1), r"NaN or inf"),
        (lambda: fit_ar(np.ones(20), 1), r"constant"),
        (lambda: whiten(np.ones(2), [0.1, 0.2]), r"more than 2 samples"),
        (lambda: ARNoise(0), r"order must be an integer >= 1"),
        (lambda: ARNoise(2.5), r"order must be an integer"),
        (lambda: ARNoise(51), r"order must be at most 50"),
    ],
)
def test_bad_input(call, pattern):
    with pytest.raises(InputError, match=pattern):
        call()


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"noise_model": "ar"}, r"noise_model must be a WhiteNoise, ARNoise or AutoNoise"),
        ({"noise_model": ARNoise(), "noise": (0.1, 0.1)}, r"give one or the other"),
        ({"noise_model": ARNoise(), "search": JointSearch(final_horizon=0.5)},
         r"cannot be combined with "
         r"final_horizon \(got 0\.5\)"),
    ],
)
def test_identifier_validates_the_noise_model(clean, kwargs, pattern):
    with pytest.raises(InputError, match=pattern):
        JointIdentifier(PRIOR, **kwargs).fit(_record(clean, 0.0, 0))


# --- fits -----------------------------------------------------------------------------


def test_ar_noise_on_white_noise_changes_next_to_nothing(clean):
    rec = Record(clean.t, clean.torque, signals.add_noise(clean.w_motor, 30, rng=4),
                 signals.add_noise(clean.w_load, 30, rng=5))
    with warnings.catch_warnings():
        warnings.simplefilter("error", CorrelatedResidualsWarning)  # no warning here
        white = JointIdentifier(PRIOR).fit(rec)
        ar = JointIdentifier(PRIOR, noise_model=ARNoise(2)).fit(rec)
    assert white.noise_ar_ is None and ar.noise_ar_.shape == (1, 2, 2)
    assert np.all(np.abs(ar.noise_ar_) < 4 / np.sqrt(clean.t.size))
    assert abs(ar.theta_ - white.theta_) < 0.1 * white.std_
    assert ar.std_ == pytest.approx(white.std_, rel=0.02)
    assert np.all(np.abs(white.residual_lag1_) < 4 / np.sqrt(clean.t.size))
    assert white.noise_std_ is white.noise_innovation_std_


def test_white_model_on_coloured_noise_warns(colored_fits):
    _, white, _, caught = colored_fits
    assert white.residual_lag1_ == pytest.approx(np.full((1, 2), CORR), abs=0.03)
    msgs = [str(w.message) for w in caught if w.category is CorrelatedResidualsWarning]
    assert len(msgs) == 1
    assert msgs[0].startswith("the residual of w_")
    assert "exp.csv (record 1)" in msgs[0] and "noise_model=ARNoise()" in msgs[0]
    assert CORRELATED_LAG1 < 0.5 < CORR
    # a 2 s hold is too brief to see the noise itself on (the ringing has not decayed)
    assert np.all(np.isnan(white.held_noise_lag1_))


def test_ar_model_on_coloured_noise(colored_fits, clean):
    rec, white, ar, _ = colored_fits
    # the fitted A(q) is the filter's inverse, 1 - 0.8 q^-1 (second lag about 0)
    assert ar.noise_ar_[0, :, 0] == pytest.approx([-CORR, -CORR], abs=0.04)
    assert np.all(np.abs(ar.noise_ar_[0, :, 1]) < 0.04)
    assert np.all(np.abs(ar.residual_lag1_) < 0.02)
    assert ar.correlation_message() is None
    # the noise's std, and its innovation's: var(e) = var(w) / (1 - 0.8^2)
    assert ar.noise_innovation_std_ == pytest.approx(ar.noise_std_ * np.sqrt(1 - CORR**2),
                                                     rel=0.05)
    # white noise filtered to lag-1 correlation 0.8 has 9 times the spectrum at 0 of
    # white noise of the same innovation and 1/(1 - 0.64) its variance: the white
    # model's standard error is too small by up to sqrt(9 * 0.36) = 1.8 times
    assert 1.4 < ar.std_ / white.std_ < 4.0
    assert ar.ci95_[0] < ar.theta_ < ar.ci95_[1]
    assert abs(ar.theta_ - THETA) < 3 * ar.std_


def test_a_dropped_loop_is_tested_and_spanned_under_the_ar_likelihood(colored_fits):
    """The loop's test and its spans weigh the whitened residual: made on the white
    one, the spans of the model without the loop fall inside the AR model's wider
    interval and widen nothing, as before the tests were whitened."""
    rec, white, ar, _ = colored_fits
    plain = JointIdentifier(PRIOR, noise_model=ARNoise(2), actuator=None).fit(rec)
    (loop,) = [c for c in ar.choices_ if c.term == "actuator"]
    (white_loop,) = [c for c in white.choices_ if c.term == "actuator"]
    assert not loop.kept and ar.theta_ == pytest.approx(plain.theta_, rel=1e-6)
    # the white likelihood overstates what a term explains of coloured noise
    assert 0 <= loop.rise < 0.2 * white_loop.rise
    # the spans reach past the AR model's own interval, in its units
    assert loop.held_ci95 is not None and loop.held_ci95[0] < plain.ci95_[0]
    assert ar.ci95_[0] == loop.held_ci95[0] < white_loop.held_ci95[0]
    assert ar.ci95_[1] == pytest.approx(plain.ci95_[1], rel=1e-6)


def test_ar_cost_is_the_whitened_likelihood_computed_independently(colored_fits):
    rec, _, ar, _ = colored_fits
    sim = ar.drive_.simulate(rec.t, rec.torque)  # the drive's own simulate, not the fit's
    cost = 0.0
    for c, (y, yhat) in enumerate(((rec.w_motor, sim.w_motor), (rec.w_load, sim.w_load))):
        a = ar.noise_ar_[0, c]
        white = lfilter(np.r_[1.0, a], [1.0], y - yhat)[a.size :]
        cost += float(np.sum((white / ar.noise_innovation_std_[0, c]) ** 2))
    assert ar.cost_ == pytest.approx(cost, rel=1e-6)


def test_bootstrap_draws_the_fitted_autoregression(colored_fits):
    _, _, ar, _ = colored_fits
    e = sample_noise(np.random.default_rng(0), ar.noise_innovation_std_[0, 1],
                     ar.noise_ar_[0, 1], 100_000)
    a, var = fit_ar(e, 2)
    assert a == pytest.approx(ar.noise_ar_[0, 1], abs=0.02)
    assert np.sqrt(var) == pytest.approx(ar.noise_innovation_std_[0, 1], rel=0.02)


def test_bootstrap_with_ar_noise_runs(clean):
    rec = _record(clean, CORR, 8)
    est = JointIdentifier(PRIOR, noise_model=ARNoise(1),
                          interval=bk.ParametricBootstrap(2, seed=1)).fit(rec)
    assert est.interval_ == "bootstrap" and est.bootstrap_thetas_.size == 2
    assert np.all(np.abs(est.bootstrap_thetas_ / THETA - 1) < 0.2)


# --- command line ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def colored_csv(clean, tmp_path_factory):
    path = tmp_path_factory.mktemp("noise") / "exp.csv"
    rec = _record(clean, CORR, 3)
    write_csv(path, {"t": rec.t, "torque": rec.torque, "w_motor": rec.w_motor,
                     "w_load": rec.w_load})
    prior = path.parent / "prior.toml"
    prior.write_text("[drive]\n" + "".join(f"{k} = {getattr(PRIOR, k)!r}\n" for k in P_TRUE))
    return path, prior


def test_cli_noise_ar(colored_csv, capsys):
    path, prior = colored_csv
    report = path.parent / "report_white"
    code = main(["identify", str(path), "--drive", str(prior), "--noise", "white",
                 "--report", str(report)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "note: the residual of w_" in out and "try --noise ar" in out
    # the page's noise section words its advice as the command line does (a QA pass
    # found the Python API's noise_model=ARNoise() there)
    page = (report / "index.html").read_text(encoding="utf-8")
    assert "try --noise ar" in page and "ARNoise" not in page
    code = main(["identify", str(path), "--drive", str(prior)])  # auto: a 2 s hold is
    out, err = capsys.readouterr()  # too brief to see the noise there: white, and the note
    assert code == 0, err
    assert "note: the residual of w_" in out and "try --noise ar" in out
    code = main(["identify", str(path), "--drive", str(prior), "--noise", "ar", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    assert doc["noise_model"] == "ar(2)" and doc["residuals_correlated"] is False
    rec = doc["records"][0]
    assert len(rec["noise_ar"]) == 2 and len(rec["noise_ar"][0]) == 2
    assert rec["noise_ar"][0][0] == pytest.approx(-CORR, abs=0.04)
    assert max(abs(x) for x in rec["residual_lag1"]) < 0.02
    code = main(["identify", str(path), "--drive", str(prior), "--noise", "ar",
                 "--noise-order", "3", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)["noise_model"] == "ar(3)"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--noise", "white", "--noise-order", "3"],
         "--noise-order only applies with --noise ar or auto"),
        (["--noise", "ar", "--noise-order", "0"], "--noise-order must be an integer >= 1"),
        (["--noise", "ar", "--method", "two-step"], "--noise only applies with --method joint"),
        (["--noise", "ar", "--final-horizon", "1"], "cannot be combined with final_horizon"),
    ],
)
def test_cli_noise_errors(colored_csv, capsys, argv, message):
    path, prior = colored_csv
    code = main(["identify", str(path), "--drive", str(prior), *argv])
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and message in err, err


def test_auto_noise_is_the_default(tmp_path, capsys):
    """AutoNoise (the default) looks at the speeds on the level held before the
    step-down (from 12 ringing time constants after the step up, 7 s here, on): white
    noise there -> WhiteNoise (the same fit as WhiteNoise()), noise filtered to lag-1 0.8
    or averaged over 10 samples -> ARNoise(2) (the same fit as ARNoise(2)); on a level
    held too briefly, with noise=... and with final_horizon (which ARNoise cannot
    whiten) it stays white. The command line's default is the same."""
    t = signals.time_grid(12.0, 1e-3)
    long = TRUE.simulate(t, signals.step_down(t, 0.942, t_s=10.0))
    assert JointIdentifier(PRIOR).noise_model == AutoNoise()
    fisher = bk.FisherInterval()
    white_rec = _record(long, 0.0, 8)
    auto = JointIdentifier(PRIOR, interval=fisher).fit(white_rec)
    white = JointIdentifier(PRIOR, interval=fisher, noise_model=WhiteNoise()).fit(white_rec)
    assert auto.noise_model_ == WhiteNoise() and auto.noise_ar_ is None
    assert np.all(np.abs(auto.held_noise_lag1_) < 0.1)
    assert auto.theta_ == white.theta_ and auto.std_ == white.std_
    rec = _record(long, CORR, 3)
    auto = JointIdentifier(PRIOR, interval=fisher).fit(rec)
    ar = JointIdentifier(PRIOR, interval=fisher, noise_model=ARNoise(2)).fit(rec)
    assert auto.held_noise_lag1_ == pytest.approx(np.full((1, 2), CORR), abs=0.1)
    assert auto.noise_model_ == ARNoise(2) and auto.noise_model == AutoNoise()
    assert auto.theta_ == ar.theta_ and auto.std_ == ar.std_
    rng = np.random.default_rng(4)  # a moving average (an observer): lag-1 about 0.9
    averaged = [x + 0.01 * np.std(x) * np.convolve(rng.standard_normal(x.size + 9),
                                                    np.ones(10) / 10, "valid") * np.sqrt(10)
                for x in (long.w_motor, long.w_load)]
    held, _ = held_noise_lag1([Record(t, long.torque, *averaged)], PRIOR)
    assert np.all(held > 0.8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CorrelatedResidualsWarning)
        short = JointIdentifier(PRIOR, search=JointSearch(final_horizon=1.0),
                                interval=fisher).fit(rec)
        fixed = JointIdentifier(PRIOR, noise=(0.1, 0.1), interval=fisher).fit(rec)
    assert short.noise_model_ == WhiteNoise() and fixed.noise_model_ == WhiteNoise()
    t6 = t[:6000]  # held 4 s, less than the 7 s of ringing decay: no window
    brief = _record(TRUE.simulate(t6, signals.step_down(t6, 0.942, t_s=4.0)), CORR, 3)
    assert np.all(np.isnan(held_noise_lag1([brief], PRIOR)[0]))
    with pytest.raises(InputError, match="order must be an integer >= 1, got 0"):
        AutoNoise(0)
    path = tmp_path / "long.csv"
    write_csv(path, {"t": rec.t, "torque": rec.torque, "w_motor": rec.w_motor,
                     "w_load": rec.w_load})
    prior = tmp_path / "prior.toml"
    prior.write_text("[drive]\n" + "".join(f"{k} = {getattr(PRIOR, k)!r}\n" for k in P_TRUE))
    assert main(["identify", str(path), "--drive", str(prior), "--interval", "fisher",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["noise_model"] == "ar(2)"


# --- the Cramér-Rao bound with autoregressive noise -------------------------------------


def test_innovation_ratio():
    assert innovation_ratio([-0.8]) == pytest.approx(1 - 0.8**2, rel=1e-9)
    a = np.array([-1.2, 0.5])
    e = lfilter([1.0], np.r_[1.0, a], np.random.default_rng(2).standard_normal(400_000))
    assert innovation_ratio(a) == pytest.approx(1.0 / np.var(e), rel=0.02)
    with pytest.raises(InputError, match="not stationary"):
        innovation_ratio([-1.0])


def test_crb_with_ar_noise_against_the_exact_gaussian_likelihood():
    """AR(1) noise: the bound's information (conditional on the first sample) plus the
    first sample's own term equals S^T Sigma^-1 S with the exact Toeplitz covariance
    Sigma_ij = s^2 rho^|i - j|; the sensitivities are recomputed here with the drive's
    own simulate."""
    from scipy.linalg import toeplitz

    t = signals.time_grid(0.4, 1e-3)
    u = signals.step_down(t, 0.942, t_s=0.2)
    sig, rho = (0.3, 0.2), 0.7
    crb = bk.cramer_rao_bound(TRUE, t, u, noise_std=sig, noise_ar=[-rho])
    h = 1e-6
    up = bk.TwoMassDrive(**P_TRUE, theta=THETA * (1 + h)).simulate(t, u)
    down = bk.TwoMassDrive(**P_TRUE, theta=THETA * (1 - h)).simulate(t, u)
    exact = 0.0
    first = 0.0
    for ch, s in zip(("w_motor", "w_load"), sig, strict=True):
        sens = (getattr(up, ch) - getattr(down, ch)) / (2 * h * THETA)
        cov = toeplitz(s**2 * rho ** np.arange(t.size))
        exact += float(sens @ np.linalg.solve(cov, sens))
        first += sens[0] ** 2 / s**2
    assert crb.fisher[0, 0] + first == pytest.approx(exact, rel=1e-6)
    white = bk.cramer_rao_bound(TRUE, t, u, noise_std=sig)
    # correlated noise of the same variance hides a slow signal: the bound is wider
    assert crb.theta_std > white.theta_std
    # a zero autoregression is white noise (the first sample dropped)
    zero = bk.cramer_rao_bound(TRUE, t, u, noise_std=sig, noise_ar=[[0.0], [0.0]])
    assert zero.theta_std == pytest.approx(white.theta_std, rel=1e-2)
    with pytest.raises(InputError, match=r"noise_ar: the autoregression \[-1\.5\] is not "
                       "stationary"):
        bk.cramer_rao_bound(TRUE, t, u, noise_std=sig, noise_ar=[-1.5])
    with pytest.raises(InputError, match="noise_ar must be the coefficients"):
        bk.cramer_rao_bound(TRUE, t, u, noise_std=sig, noise_ar=np.zeros((3, 1)))
