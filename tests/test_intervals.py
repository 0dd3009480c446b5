"""Interval configurations and the profile-likelihood crossing search
(``backlashkit.identify.intervals``); the intervals of fitted drives are tested in
``tests/test_identify_joint.py``."""

from __future__ import annotations

import math

import pytest

import backlashkit as bk
from backlashkit.errors import InputError
from backlashkit.identify.intervals import CHI2_95, profile_crossing


def test_chi2_quantile():
    import scipy.stats as scipy_stats
    assert CHI2_95 == pytest.approx(scipy_stats.chi2.ppf(0.95, 1), rel=1e-12)


def _counted(fn):
    calls = []

    def rise(d):
        calls.append(d)
        return fn(d)

    return rise, calls


def test_quadratic_profile_crosses_at_the_fisher_end_in_one_step():
    rise, calls = _counted(lambda d: (d / 0.1) ** 2)
    d, bounded = profile_crossing(rise, 1.96 * 0.1)
    assert bounded and d == pytest.approx(0.196) and len(calls) == 1


@pytest.mark.parametrize("power", [1.0, 1.5, 3.0, 4.0])
def test_non_quadratic_profiles(power):
    """rise = (d / s)^p crosses 3.84 at s 3.84^(1/p); found within the tolerance."""
    s = 0.05
    rise, calls = _counted(lambda d: (d / s) ** power)
    d, bounded = profile_crossing(rise, 1.96 * s, tol=1e-3, max_evaluations=30)
    assert bounded
    assert d == pytest.approx(s * CHI2_95 ** (1 / power), rel=1e-3)
    assert len(calls) < 15


def test_negative_and_flat_rises_move_outwards():
    """A rise below 0 (a refit ending under the estimate's cost) counts as 0; a rise
    that never reaches the level leaves the end open at the largest distance."""
    rise, calls = _counted(lambda d: -0.5 if d < 0.3 else 100 * (d - 0.3))
    d, bounded = profile_crossing(rise, 0.1, tol=1e-3, max_evaluations=40)
    assert bounded and d == pytest.approx(0.3 + CHI2_95 / 100, rel=1e-4)
    assert calls[1] == pytest.approx(0.4)  # 0 counts as far below: four times further
    d, bounded = profile_crossing(lambda d: 1.0, 0.1, largest=math.log(10.0))
    assert not bounded and d == pytest.approx(math.log(10.0))


def test_failed_refits_are_bisected():
    """An infinite rise (a simulation that failed) brackets like a large one."""
    rise, calls = _counted(lambda d: math.inf if d > 0.5 else (d / 0.2) ** 2)
    d, bounded = profile_crossing(rise, 0.6, tol=1e-3, max_evaluations=40)
    assert bounded and d == pytest.approx(0.2 * math.sqrt(CHI2_95), rel=1e-3)
    assert calls[1] == pytest.approx(0.3)


def test_last_bracket_interpolated_after_max_evaluations():
    d, bounded = profile_crossing(lambda d: (d / 0.1) ** 3, 0.05, tol=1e-9,
                                  max_evaluations=2)
    assert bounded and 0.05 < d < 0.2


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"tol": 0.0}, r"tol must be in \(0, 3.841\)"),
        ({"tol": 5.0}, r"tol must be in \(0, 3.841\)"),
        ({"max_evaluations": 0}, "max_evaluations must be an integer >= 1"),
        ({"max_iter": 1.5}, "max_iter must be an integer >= 1"),
        ({"max_factor": 1.0}, "max_factor must be a finite number > 1"),
        ({"max_factor": math.inf}, "max_factor must be a finite number > 1"),
    ],
)
def test_profile_likelihood_validated(kwargs, pattern):
    with pytest.raises(InputError, match=pattern):
        bk.ProfileLikelihood(**kwargs)


def test_configurations_are_exported():
    assert bk.ProfileLikelihood() == bk.ProfileLikelihood()
    assert bk.FisherInterval() == bk.FisherInterval()
    from backlashkit import identify

    assert identify.ParametricBootstrap is bk.ParametricBootstrap


def test_each_interval_computes_its_own():
    """Fisher's and the bootstrap's intervals from what a fit hands them (the profile's
    is checked on fitted drives in tests/test_identify_joint.py)."""
    import numpy as np

    from backlashkit.identify.intervals import IntervalInputs

    draws = iter([0.9, 1.1, 1.0])
    fit = IntervalInputs(theta=1.0, std=0.6, z=np.zeros(1), cov_z=np.eye(1), cost=0.0,
                         residual=None, fd_step=1e-6, resample=lambda rng: None,
                         refit=lambda records: next(draws))
    fisher = bk.FisherInterval()._interval(fit)
    assert fisher.kind == "fisher" and fisher.ci95 == (0.0, 1.0 + 1.96 * 0.6)  # cut at 0
    boot = bk.ParametricBootstrap(3)._interval(fit)
    assert boot.kind == "bootstrap" and boot.std == pytest.approx(0.1)
    assert boot.ci95 == pytest.approx((1.0 - 4.3027 * 0.1, 1.0 + 4.3027 * 0.1), rel=1e-4)
    assert boot.bootstrap_thetas.tolist() == [0.9, 1.1, 1.0] and boot.lowest_rise == 0.0


def _refit_from_seed(records):
    """A picklable refit: the resample here is the noise draw itself."""
    return float(records)


def test_bootstrap_refits_anywhere_give_the_same_interval():
    """The resamples are drawn in order in the caller; the refits (picklable) may run
    serially, on a process pool or on any executor, with the same answer bit for bit."""
    from concurrent.futures import ThreadPoolExecutor

    import numpy as np

    from backlashkit.identify.intervals import IntervalInputs

    fit = IntervalInputs(theta=1.0, std=0.6, z=np.zeros(1), cov_z=np.eye(1), cost=0.0,
                         residual=None, fd_step=1e-6,
                         resample=lambda rng: 1.0 + 0.1 * rng.standard_normal(),
                         refit=_refit_from_seed)
    serial = bk.ParametricBootstrap(8, seed=4)._interval(fit)
    pooled = bk.ParametricBootstrap(8, seed=4, jobs=2)._interval(fit)
    with ThreadPoolExecutor(2) as ex:
        threaded = bk.ParametricBootstrap(8, seed=4, executor=ex)._interval(fit)
    for other in (pooled, threaded):
        np.testing.assert_array_equal(other.bootstrap_thetas, serial.bootstrap_thetas)
        assert other.ci95 == serial.ci95
    with ThreadPoolExecutor(1) as ex, pytest.raises(bk.InputError, match="executor or jobs"):
        bk.ParametricBootstrap(8, jobs=2, executor=ex)


def _profile_of(rise_at):
    """A fit of ``theta`` alone (``z = 0``, a Fisher error of 0.1 in ``log theta``)
    whose profile rises by ``rise_at(d)`` at a distance ``d`` on either side."""
    import numpy as np

    from backlashkit.identify.intervals import IntervalInputs

    def residual(zz):
        return np.sqrt([[rise_at(abs(float(zz[0, 0])))]])

    return lambda look_past: IntervalInputs(
        theta=1.0, std=0.1, z=np.zeros(1), cov_z=np.array([[0.01]]), cost=0.0,
        residual=residual, fd_step=1e-6, resample=None, refit=None, look_past=look_past)


def test_a_profile_that_falls_again_is_looked_past():
    """A profile whose rise reaches 3.84 and then falls (a current loop's lag jumping
    across its valley, docs/validation/real-drives.md) ends at its outer crossing when
    the fit says it may fall again, and at the first crossing otherwise; a profile that
    keeps rising ends where it did, at one more refit per side."""
    def bump(d):  # 3.67 at the Fisher end 0.196, 2.51 a quarter further out
        return (d / 0.1) ** 2 if d <= 0.19 else 2.5 + ((d - 0.25) / 0.05) ** 2

    fit = _profile_of(bump)
    first = bk.ProfileLikelihood()._interval(fit(False))
    assert first.ci95 == pytest.approx((math.exp(-0.196), math.exp(0.196)))
    looked = bk.ProfileLikelihood()._interval(fit(True))
    lo, hi = -math.log(looked.ci95[0]), math.log(looked.ci95[1])
    assert lo == pytest.approx(hi) and abs(bump(lo) - CHI2_95) <= 0.25 and lo > 0.29
    plain = _profile_of(lambda d: (d / 0.1) ** 2)
    once, twice = (bk.ProfileLikelihood()._interval(plain(k)) for k in (False, True))
    assert twice.ci95 == once.ci95 and len(twice.profile) == len(once.profile) + 2


def _two_basins(anchor_w: float, calls: list):
    """A profile with two basins in the other log-parameter ``w``: the estimate's at
    ``w = 1`` and a lower one at ``w = 3``; a constant row of 1000 stands for the
    noise (the estimate's cost)."""
    import numpy as np

    from backlashkit.identify.intervals import IntervalInputs, _HeldTheta

    def residual(rows):
        calls.append(len(rows))
        zt, w = rows[:, 0], rows[:, 1]
        return np.column_stack([30.0 * (w - 1.0) * (w - 3.0), 0.3 * (w - 3.0), 5.0 * zt,
                                np.full(len(rows), math.sqrt(1000.0))])

    z = np.array([0.0, 1.0])
    cost = float(np.sum(residual(z[np.newaxis, :]) ** 2))
    fit = IntervalInputs(theta=1.0, std=0.1, z=z, cov_z=np.diag([0.04, 1.0]), cost=cost,
                         residual=residual, fd_step=1e-6, resample=lambda rng: None,
                         refit=lambda records: 1.0, anchor=np.array([anchor_w]))
    return _HeldTheta(fit, max_iter=20)


def test_an_end_is_refitted_from_the_priors_point_only_where_it_is_near(monkeypatch):
    """The recheck from the prior's point finds the lower basin where that point costs
    within RECHECK_FAR of the estimate's cost above it; farther, it is not run (one
    simulation, of the point itself), unless RECHECK_FAR allows it."""
    import backlashkit.identify.intervals as intervals

    calls: list = []
    held = _two_basins(3.2, calls)
    continued = held.rise(1.0, memo := {}, 0.2)
    assert continued == pytest.approx(1.0, abs=0.01)  # 5 * 0.2, squared: the held theta
    assert held.recheck(1.0, memo, 0.2) == pytest.approx(continued - 0.36, abs=0.01)
    far = _two_basins(4.5, calls := [])  # 30 * 3.5 * 1.5 squared: far above 1000
    continued = far.rise(1.0, memo := {}, 0.2)
    n = len(calls)
    assert far.recheck(1.0, memo, 0.2) == continued and len(calls) == n + 1
    monkeypatch.setattr(intervals, "RECHECK_FAR", math.inf)
    assert far.recheck(1.0, memo, 0.2) == pytest.approx(continued - 0.36, abs=0.01)


def test_the_profile_spans_a_rival_basins_own():
    """Two basins in the other log-parameter ``w``: the estimate's at ``w = 1`` with
    ``theta``'s minimum at 0 (log), and a rival at ``w = 3``, 2.0 above, with its minimum
    at 0.3. The estimate's profile ends at +-sqrt(3.84) / 5; the lowest profile over
    both basins reaches 3.84 at 0.3 + sqrt(3.84 - 2) / 5 on the rival's side, and the
    side towards the estimate is not refitted from the rival."""
    import numpy as np

    from backlashkit.identify.intervals import IntervalInputs

    def residual(rows):
        zt, w = rows[:, 0], rows[:, 1]
        return np.column_stack([30.0 * (w - 1.0) * (w - 3.0), math.sqrt(2.0) * (w - 1.0) / 2.0,
                                5.0 * (zt - 0.15 * (w - 1.0)), np.full(len(rows), 30.0)])

    def inputs(rivals):
        z = np.array([0.0, 1.0])
        return IntervalInputs(theta=1.0, std=0.2, z=z, cov_z=np.diag([0.04, 1.0]),
                              cost=900.0, residual=residual, fd_step=1e-6,
                              resample=lambda rng: None, refit=lambda records: 1.0,
                              rivals=rivals)

    alone = bk.ProfileLikelihood()._interval(inputs([]))
    half = math.sqrt(CHI2_95) / 5.0
    assert np.log(alone.ci95) == pytest.approx([-half, half], abs=0.03)
    assert alone.rivals == 0
    both = bk.ProfileLikelihood()._interval(inputs([(np.array([0.3, 3.0]), 902.0)]))
    assert both.ci95[0] == alone.ci95[0] and both.rivals == 1
    assert math.log(both.ci95[1]) == pytest.approx(0.3 + math.sqrt(CHI2_95 - 2.0) / 5.0,
                                                   abs=0.03)
    def below(found):
        return sum(theta < 1.0 for theta, _ in found.profile)

    assert below(both) == below(alone) and len(both.profile) > len(alone.profile)
