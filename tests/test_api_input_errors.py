"""Bad input found by a QA pass over the Python API: each case is one InputError that
names the parameter and what to do, never NumPy's or the compiled core's words, and a
plot takes the axes that ``plt.subplots`` returns."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings

import matplotlib.pyplot as plt
import numpy as np
import pytest

import backlashkit as bk
from backlashkit.errors import InputError
from backlashkit.papers.ravanbod2002 import P_TRUE, THETA

DRIVE = bk.TwoMassDrive(**P_TRUE, theta=THETA)


def test_the_discrete_controller_refuses_a_reading_that_is_not_finite():
    """A NaN read once carried into every later sample through the adaptive law (the
    output and theta_b stayed NaN until reset); it is refused, and the state kept."""
    ctrl = bk.DiscreteAdaptiveController(([1.0], [1.0, -0.5, -1.5]), ts=1e-3)
    ctrl.step(0.1, 1.0)
    before = ctrl.theta_b.copy()
    for args, said in (((np.nan, 1.0), "y must be finite, got nan"),
                       ((0.0, np.inf), "r must be finite, got inf"),
                       ((np.array([1.0, 2.0]), 0.0), "y must be a real number"),
                       ((0.0, 1.0, np.nan), "r_dot must be finite")):
        with pytest.raises(InputError, match=said):
            ctrl.step(*args)
    np.testing.assert_array_equal(ctrl.theta_b, before)
    assert np.isfinite(ctrl.step(0.1, 1.0))


def test_the_bound_of_an_experiment_that_moves_nothing_is_refused():
    """A zero torque moves nothing: an SNR gives no noise level (it answered NaN), and
    given noise levels the information is 0 (NumPy's "Singular matrix")."""
    t = bk.signals.time_grid(4.0, 1e-3)
    zero = np.zeros_like(t)
    with pytest.raises(InputError, match=r"snr_db: the model's w_M is 0 over the whole "
                                         r"experiment.*give noise_std=\(s_M, s_L\)"):
        bk.cramer_rao_bound(DRIVE, t, zero, snr_db=30.0)
    with pytest.raises(InputError, match="the experiment carries no information on theta"):
        bk.cramer_rao_bound(DRIVE, t, zero, noise_std=(0.1, 0.1))
    bound = bk.cramer_rao_bound(DRIVE, t, bk.signals.step_down(t, 0.942, t_s=2.0),
                                snr_db=30.0, estimate="all")
    singular = bk.identify.CramerRaoBound(bound.names, bound.values,
                                          np.zeros_like(bound.fisher) + 1.0,
                                          bound.noise_std, bound.n_samples)
    with pytest.raises(InputError, match="is singular: it cannot tell them apart"):
        singular.covariance  # noqa: B018


@pytest.mark.parametrize("workers", [-1, 0, 1.5, "2", True])
def test_the_joint_fits_workers_must_be_a_positive_integer(workers):
    """-1 reached the compiled core as an unsigned integer (OverflowError), a string
    or a float Python's range (TypeError), and 0 was taken silently."""
    with pytest.raises(InputError, match=f"workers must be an integer >= 1, got "
                                         f"{workers!r}"):
        bk.JointIdentifier(DRIVE.with_theta(None), workers=workers).fit([])


def test_plots_take_the_axes_array_of_subplots():
    """``fig, axes = plt.subplots(3, 1)`` gives a NumPy array, which the drive
    response's plot refused as "1 Axes"; the delay margin's took no single Axes."""
    from backlashkit.delay import delay_margin

    t = bk.signals.time_grid(4.0, 1e-3)
    resp = DRIVE.simulate(t, bk.signals.step_down(t, 0.942, t_s=2.0))
    fig, axes = plt.subplots(3, 1)
    assert resp.plot(ax=axes) is fig
    with pytest.raises(InputError, match=r"ax must be 3 Axes \(a sequence or an array of "
                                         r"them, as plt.subplots returns\), got 2"):
        resp.plot(ax=axes[:2])
    result = delay_margin([[-2.0, 0.0], [0.0, -0.9]], [[[-1.0, 0.0], [-1.0, -1.0]]])
    fig2, axes2 = plt.subplots(1, 2)
    assert result.plot(ax=axes2) is fig2
    with pytest.raises(InputError, match="ax must be 2 Axes"):
        result.plot(ax=axes2[0])
    assert len(result.plot().axes) == 2
    plt.close("all")


@pytest.mark.parametrize("cls", [bk.JointIdentifier, bk.TwoStepIdentifier,
                                 bk.RegressionIdentifier])
def test_a_learned_attribute_before_fit_says_to_fit(cls):
    """Python said only "object has no attribute 'theta_'"; hasattr stays False, any
    other name keeps Python's words, and the estimator still pickles (the bootstrap's
    worker processes)."""
    import pickle

    est = cls(DRIVE.with_theta(None))
    with pytest.raises(AttributeError, match=rf"^{cls.__name__}\.theta_ is learned by "
                                             r"fit\(\): call fit\(records\) first$"):
        est.theta_  # noqa: B018
    assert not hasattr(est, "std_")
    with pytest.raises(AttributeError, match="object has no attribute 'thetaa'"):
        est.thetaa  # noqa: B018
    assert repr(pickle.loads(pickle.dumps(est))) == repr(est)


def test_arguments_of_the_wrong_kind_are_named():
    """What Python or pathlib said ("'TwoMassDrive' object is not iterable", "'float'
    object is not callable", "expected str, bytes or os.PathLike object") is said in the
    library's words, with the remedy; a flag given as a string is refused, where "no"
    counted as true."""
    from backlashkit import Backlash, SumOfSines, simulate_closed_loop

    t = bk.signals.time_grid(1.0, 1e-3)
    u = np.full_like(t, 0.5)
    with pytest.raises(InputError, match=r"drives must be a sequence of drives, got one "
                                         r"TwoMassDrive: pass \[drive\]"):
        bk.simulate_batch(DRIVE, t, u)
    with pytest.raises(InputError, match="output_noise must be a function of the time "
                                         "array t"):
        simulate_closed_loop(([1.0], [1.0, -0.5, -1.5]), Backlash(0.7, 1.3, -0.5),
                             reference=SumOfSines([10.0], [1.3]), duration=1.0, ts=0.05,
                             output_noise=0.01)
    with pytest.raises(InputError, match="path must be a file name .* got int 3"):
        bk.read_records(3)
    with pytest.raises(InputError, match=r"one name is a sequence too: \('theta',\)"):
        bk.cramer_rao_bound(DRIVE, t, u, snr_db=30.0, estimate="theta")
    for cls in (bk.JointIdentifier, bk.TwoStepIdentifier, bk.RegressionIdentifier):
        with pytest.raises(InputError, match="allow_far_from_prior must be True or False, "
                                             "got 'no'"):
            cls(DRIVE.with_theta(None), allow_far_from_prior="no").fit([])


def test_a_noise_level_given_far_from_the_residuals_is_warned_of(short_csv):
    """A level given 5 times too small made the standard error 5 times too small
    without a word; a level the residuals agree with says nothing."""
    from backlashkit import NoiseLevelWarning
    from backlashkit.identify.intervals import FisherInterval

    rec = bk.read_records(short_csv)
    prior = DRIVE.with_theta(None)
    with pytest.warns(NoiseLevelWarning, match=r"^the residual of w_M in .*exp\.csv spreads "
                                               r"0\.5\d+ \(rms\), 5\.\d+ times the noise level "
                                               r"given \(0\.1\).*leave noise=None"):
        bk.JointIdentifier(prior, noise=(0.1, 0.1), interval=FisherInterval()).fit(rec)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NoiseLevelWarning)
        bk.JointIdentifier(prior, noise=(0.5, 0.5), interval=FisherInterval()).fit(rec)


def test_results_print_short():
    """The dataclasses' reprs printed every array; each now fits a line and says what
    it holds."""
    from backlashkit import Backlash, SumOfSines, simulate_closed_loop

    t = bk.signals.time_grid(4.0, 1e-3)
    u = bk.signals.step_down(t, 0.942, t_s=2.0)
    resp = DRIVE.simulate(t, u)
    loop = simulate_closed_loop(([1.0], [1.0, -0.5, -1.5]), Backlash(0.7, 1.3, -0.5),
                                reference=SumOfSines([10.0], [1.3]), duration=5.0, ts=0.01)
    texts = {
        repr(resp): (r"^DriveResponse\(4001 samples, t = 0 to 4 s, \d+ contact changes, "
                     r"law 'paper'\)$"),
        repr(bk.cramer_rao_bound(DRIVE, t, u, snr_db=30.0)):
            r"^CramerRaoBound\(theta_std=\S+ rad, names=\('theta',\), noise_std=\(\S+, \S+\) "
            r"rad/s, n_samples=4001\)$",
        repr(bk.Record(t, u, resp.w_motor, resp.w_load, name="x.csv")):
            r"^Record\('x\.csv', 4001 samples at 0\.001 s from t = 0 s, speeds\)$",
        repr(loop): r"^ClosedLoopResponse\(\d+ samples, t = 0 to 5 s, inverse .*, RMS "
                    r"tracking error over the last third \S+\)$",
    }
    for text, pattern in texts.items():
        assert len(text) < 200 and re.match(pattern, text), text


def test_a_step_down_off_the_grid_is_refused():
    """A step-down past the grid's end (or at its start) gave one level throughout,
    which identify then refused as "no step-down" far from the cause."""
    t = bk.signals.time_grid(4.0, 1e-3)
    for t_s in (10.0, 0.0, -1.0):
        with pytest.raises(InputError, match=rf"t_s must lie within the grid, after its "
                                             rf"first sample: in \(0, 4\] s, got {t_s!r}"):
            bk.signals.step_down(t, 0.5, t_s=t_s)
    u = bk.signals.step_down(t, 0.5, t_s=4.0)  # the last sample steps down
    assert u[-2] == 0.5 and u[-1] == 0.0
    ctrl = bk.DiscreteAdaptiveController(([1.0], [1.0, -0.5, -1.5]), ts=1e-3)
    assert repr(ctrl) == ("DiscreteAdaptiveController(ts=0.001, inverse=ExactInverse(), "
                          "theta_b=[1.51, 0.2, -0.55])")


def _steady_record(hold: float = 2.0, torque: float = 0.942) -> bk.identify.Record:
    """Paper A's drive held at ``torque`` (N m) from its steady state, then 0 at
    ``hold`` s; ``hold`` + 2 s at 1 ms, 40 dB on both speeds."""
    t = bk.signals.time_grid(hold + 2.0, 1e-3)
    u = bk.signals.step_down(t, torque, t_s=hold)
    res = DRIVE.simulate(t, u, initial_state=DRIVE.steady_state(torque))
    rng = np.random.default_rng(3)
    return bk.identify.Record(t, u, bk.signals.add_noise(res.w_motor, 40.0, rng=rng),
                              bk.signals.add_noise(res.w_load, 40.0, rng=rng))


def test_a_search_range_in_degrees_is_noted():
    """``theta_max=15`` meant 15 degrees: the search ran over 0 to 859 deg, its grid 60
    times coarser than meant, and said nothing."""
    said = (r"theta_max = 15 rad is a half-width of 859 deg: theta_max is in rad "
            r"\(degrees written as rad\? 15 deg is 0.2618 rad\)")
    with pytest.warns(UserWarning, match="ThetaGrid." + said):
        bk.identify.ThetaGrid(theta_max=15)
    with pytest.warns(UserWarning, match="^" + said):
        bk.RegressionIdentifier(DRIVE, theta_max=15, n_grid=4).fit([_steady_record()])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bk.identify.ThetaGrid(theta_max=0.5)  # 29 deg: wide, but a half-width in rad


def test_a_level_window_longer_than_the_hold_is_noted():
    """The starting speed's level was averaged over what there is before the step-down,
    whatever ``level_window`` asked for, without a word."""
    recs = [_steady_record(torque=0.157), _steady_record(torque=0.942)]
    with pytest.warns(UserWarning, match=r"record: level_window = 100 s is longer than "
                                         r"the 2 s recorded before the step-down at "
                                         r"t = 2 s; the speed level is their mean"):
        est = bk.TwoStepIdentifier(DRIVE, level_window=100.0).fit(recs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same = bk.TwoStepIdentifier(DRIVE, level_window=2.0).fit(recs)
    assert est.theta_ == same.theta_


def test_a_generator_seeds_a_batch_as_it_seeds_add_noise():
    """``add_noise(rng=)`` takes a generator, ``ParametricBootstrap(seed=)`` refused one.
    A generator's own SeedSequence is now the root: the same generator state gives the
    same streams, and a second batch from it other streams, as a second draw would."""
    def states(seeds):
        return [tuple(s.generate_state(2)) for s in seeds]

    a, b = np.random.default_rng(5), np.random.default_rng(5)
    assert bk.ParametricBootstrap(seed=a).seed is a
    first = states(bk.parallel.task_seeds(a, 3))
    assert first == states(bk.parallel.task_seeds(b, 3))
    assert set(first).isdisjoint(states(bk.parallel.task_seeds(a, 3)))
    assert first == states(bk.parallel.task_seeds(np.random.default_rng(5), 3))
    with pytest.raises(InputError, match=r"seed must be an integer >= 0, a numpy.random."
                                         r"SeedSequence or a numpy.random.Generator, got "
                                         r"'7'"):
        bk.ParametricBootstrap(seed="7")


def test_the_delay_margin_is_at_the_top_level_without_scipy_at_import():
    """``delay_margin`` was only in ``backlashkit.delay``; it is read from there on first
    use, so that ``import backlashkit`` still leaves scipy out."""
    code = ("import sys, backlashkit as bk; assert 'scipy' not in sys.modules; "
            "from backlashkit import delay_margin; import backlashkit.delay as d; "
            "assert delay_margin is d.delay_margin and bk.DelaySystem is d.DelaySystem; "
            "assert set(d.__all__) >= {n for n in bk.__all__ if n in dir(d)}; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=False)
    assert out.stdout.strip() == "ok", out.stderr
    with pytest.raises(AttributeError, match="module 'backlashkit' has no attribute 'nope'"):
        bk.nope  # noqa: B018


def test_the_discrete_loop_names_an_argument_of_the_wrong_kind():
    """A plain function as the reference ended in ``AttributeError: 'function' object
    has no attribute 'derivative'``; the other arguments likewise."""
    plant = ([1.0], [1.0, -0.5, -1.5])
    ctrl = bk.DiscreteAdaptiveController(plant, ts=1e-3)
    gap = bk.Backlash(m=1.0, c_r=0.2, c_l=-0.3)
    ref = bk.SumOfSines([1.0], [3.0])
    loop = bk.control.simulate_discrete_loop
    for kwargs, said in (
            ({"reference": lambda t: np.sin(t)}, "reference must be a SumOfSines or a "
                                                 "TableReference, got function"),
            ({"backlash": (1.0, 0.2, -0.3)}, "backlash must be a Backlash, got tuple"),
            ({"controller": "pi"}, "controller must be a DiscreteAdaptiveController, got "
                                   "str")):
        args = {"backlash": gap, "controller": ctrl, "reference": ref, **kwargs}
        with pytest.raises(InputError, match=said):
            loop(plant, args.pop("backlash"), args.pop("controller"), duration=0.1, **args)
    assert loop(plant, gap, ctrl, reference=ref, duration=0.1).t.size == 101  # both ends


def test_a_record_s_time_grid_is_named_once_with_its_digits():
    """The record's name leads the message once, its samples are ``t[i]`` (not
    ``record: t[i]``), and times print without a difference's binary rounding."""
    t = np.arange(100) * 1e-3
    with pytest.raises(InputError, match=re.escape(
            "exp.csv: t must be strictly increasing; t[1] = 0.098 follows t[0] = 0.099")):
        bk.Record(t[::-1], t, t, t, name="exp.csv")
    jitter = t.copy()
    jitter[50] += 5e-4
    with pytest.raises(InputError, match=re.escape(
            "exp.csv: t must be uniformly sampled; step 49 is 0.0015 s but the mean step is "
            "0.001 s;")):
        bk.Record(jitter, t, t, t, name="exp.csv")


def test_a_drives_repr_leaves_out_friction_terms_at_their_defaults():
    """The prior a QA pass printed in an estimator's repr held fc_M=0.0, fc_L=0.0,
    fs_M=None, fs_L=None: the terms most drives do not have."""
    prior = DRIVE.with_theta(None)
    assert repr(bk.JointIdentifier(prior)) == (
        "JointIdentifier(TwoMassDrive(J_M=0.00488, J_L=0.068, k_sh=78.0, f_M=0.005, "
        "f_L=0.005, f_sh=0.01575, theta=None))")
    assert "fc_M=0.01" in repr(bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01))
