"""Joint ML identification (``backlashkit.identify.joint``) and its Cramér-Rao bound.

Protocol as in ``tests/test_identify.py`` (paper A's drive, theta* = 2 deg half-width,
Ts = 1 ms). The calibration and efficiency checks use a short experiment (0.942 N m
from rest for 2 s, then 0, 4 s record, SNR 30 dB on both speeds) so that 20 seeded
trials stay fast.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.errors import InputError
from backlashkit.identify import Record
from backlashkit.identify.crb import CramerRaoBound, cramer_rao_bound
from backlashkit.identify.intervals import MAX_HALF_WIDTH
from backlashkit.identify.joint import LINEAR_PARAMS, JointIdentifier
from backlashkit.identify.search import (
    Continuation,
    FirstHorizon,
    JointSearch,
    Restarts,
    ThetaGrid,
)
from backlashkit.io import write_csv

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DRIVE_TOML = str(EXAMPLES / "paper_drive.toml")
P_TRUE = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
TRUE = bk.TwoMassDrive(**P_TRUE, theta=THETA)
A2 = 0.942
REL = 0.1  # prior relative std of the calibration study
N_TRIALS = 20
#: With true coverage 0.95, P(X >= 17 of 20) = 0.984 (binomial), so a calibrated
#: estimator fails this check with probability 1.6 %; at a true coverage of 0.80
#: it would pass with probability 0.41 only.
MIN_COVERED = 17


#: Paper A's model (viscous friction, the torque applied exactly): the tests of the
#: search's stages on kernel-made trials pin it, so that they test those stages.
PAPER_MODEL = {"friction": "viscous", "actuator": None}


@pytest.fixture(scope="module")
def short():
    t = signals.time_grid(4.0, 1e-3)
    u = signals.step_down(t, A2, t_s=2.0)
    return t, u, TRUE.simulate(t, u)


def _noisy(clean, snr, seed) -> Record:
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    a, b = ss.spawn(2)
    return Record(clean.t, clean.torque, signals.add_noise(clean.w_motor, snr, rng=a),
                  signals.add_noise(clean.w_load, snr, rng=b))


@pytest.fixture(scope="module")
def trials(short):
    """20 seeded MAP fits: prior ~ N(P*, (0.1 P*)^2) per parameter, noise 30 dB."""
    t, u, clean = short
    out = []
    for k in range(N_TRIALS):
        s_noise, s_prior = np.random.SeedSequence([7, k]).spawn(2)
        rng = np.random.default_rng(s_prior)
        prior = bk.TwoMassDrive(**{n: x * (1 + REL * rng.standard_normal())
                                   for n, x in P_TRUE.items()})
        out.append(JointIdentifier(prior, prior_rel_std=REL).fit(_noisy(clean, 30, s_noise)))
    return out


# --- Cramér-Rao bound: closed-form checks -------------------------------------------


def test_crb_scales_with_noise_and_samples(short):
    t, u, _ = short
    base = cramer_rao_bound(TRUE, t, u, noise_std=(0.5, 0.5), estimate="all")
    double = cramer_rao_bound(TRUE, t, u, noise_std=(1.0, 1.0), estimate="all")
    assert double.theta_std == pytest.approx(2 * base.theta_std, rel=1e-9)
    # two independent repeats: Fisher information adds, std falls by sqrt(2)
    assert (base + base).theta_std == pytest.approx(base.theta_std / np.sqrt(2), rel=1e-9)
    # the same experiment sampled twice as fast (2N samples): ~ 1/sqrt(2)
    t2 = signals.time_grid(4.0, 0.5e-3)
    fine = cramer_rao_bound(TRUE, t2, signals.step_down(t2, A2, t_s=2.0),
                            noise_std=(0.5, 0.5), estimate="all")
    assert fine.theta_std == pytest.approx(base.theta_std / np.sqrt(2), rel=0.05)


def test_crb_structure_and_snr(short):
    t, u, clean = short
    known = cramer_rao_bound(TRUE, t, u, snr_db=30)
    joint = cramer_rao_bound(TRUE, t, u, snr_db=30, estimate="all")
    informed = cramer_rao_bound(TRUE, t, u, snr_db=30, estimate="all", prior_rel_std=REL)
    assert isinstance(joint, CramerRaoBound)
    assert known.names == ("theta",) and joint.names == ("theta", *LINEAR_PARAMS)
    assert np.allclose(joint.fisher, joint.fisher.T, rtol=1e-8, atol=0)
    assert known.theta_std < informed.theta_std < joint.theta_std
    # snr_db follows signals.add_noise's definition
    s_m = np.sqrt(np.mean(clean.w_motor**2) / 10**3)
    assert joint.noise_std[0] == pytest.approx(s_m, rel=1e-12)
    by_std = cramer_rao_bound(TRUE, t, u, noise_std=joint.noise_std, estimate="all")
    assert by_std.theta_std == pytest.approx(joint.theta_std, rel=1e-12)
    sub = cramer_rao_bound(TRUE, t, u, snr_db=30, estimate=["k_sh", "theta"])
    assert sub.names == ("theta", "k_sh")
    assert known.theta_std <= sub.theta_std <= joint.theta_std


#: Relative step of the central differences checked against the compiled
#: sensitivities: the bound's default (1e-6) loses to rounding across the record's 42
#: contact changes from the steady start (3.7e-4 of the largest of the k_sh column;
#: 6.5e-5 at this step, 1e-2 at 1e-4, where truncation rules)...
CHECK_STEP = 1e-5
#: ... the agreement asked of the sensitivities (of each column's largest) and of the
#: two bounds of theta (``-s`` prints it).
SENS_FD_RTOL, CRB_EXACT_RTOL = 1e-4, 1e-5
#: Encoder angles' residuals differenced: the simulator's angles carry its rounding,
#: grown along the record, which a difference divides by its step (CHECK_STEP missed
#: SENS_FD_RTOL on the windows after a hold, 1.4e-4, and behind a loop, 5.6e-4); at
#: 1e-4 every case agrees within 1.1e-4, the step's truncation (``-s`` prints it).
#: The kernel's angle against extrapolated differences, to 1e-6: crates/core's
#: ``the_motor_angle_matches_central_differences``.
ANGLE_STEP, ANGLE_RTOL = 1e-4, 3e-4


@pytest.mark.parametrize("initial_state", [None, "steady-values"])
def test_crb_from_exact_sensitivities_matches_central_differences(short, initial_state):
    """Within the compiled sensitivities' scope the bound takes them (one sensitivity
    run, whose speeds are the simulator's to rounding); it agrees with the bound of
    central differences."""
    from backlashkit.identify import crb

    t, u, _ = short
    x0 = None if initial_state is None else TRUE.steady_state(float(u[0]))
    names = ("theta", *LINEAR_PARAMS)
    values = np.array([getattr(TRUE, n) for n in names])
    speeds, exact = crb._exact(TRUE, names, 0.0, t, u, "paper", x0)
    assert exact is not None
    speeds_fd, fd = crb._differenced(TRUE, names, values, CHECK_STEP, 0.0, t, u, "paper",
                                     x0)
    np.testing.assert_allclose(speeds, speeds_fd, rtol=0, atol=1e-10 * np.max(np.abs(speeds_fd)))
    assert exact.shape == fd.shape == (t.size, 2, len(names))
    for s_exact, s_fd in zip(exact.transpose(1, 0, 2), fd.transpose(1, 0, 2), strict=True):
        scale = np.max(np.abs(s_fd), axis=0)
        assert np.max(np.abs(s_exact - s_fd) / scale) < SENS_FD_RTOL
    bound = cramer_rao_bound(TRUE, t, u, snr_db=30, estimate="all", initial_state=x0)
    fisher = sum(s.T @ s / sd**2 for s, sd in zip(fd.transpose(1, 0, 2), bound.noise_std,
                                                   strict=True))
    by_fd = np.sqrt(np.linalg.inv(fisher)[0, 0])
    print(f"CRB of theta: exact {bound.theta_std:.6e}, central differences {by_fd:.6e} "
          f"({bound.theta_std / by_fd - 1:+.1e})")
    assert bound.theta_std == pytest.approx(by_fd, rel=CRB_EXACT_RTOL)
    # Coulomb friction is in the scope, its torques' columns too: the kernel's, which
    # tests/test_sensitivity_kernel.py checks against extrapolated differences (plain
    # ones at CHECK_STEP resolve only 1e-2 here, as the motor's stick-slip changes
    # cross the samples)
    from backlashkit._sensitivity import sensitivities

    rough = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    with_fc = (*names, "fc_M", "fc_L")
    _, exact = crb._exact(rough, with_fc, 0.0, t, u, "paper", x0)
    kernel = sensitivities(rough, t, u, initial_state=x0, params=with_fc)
    np.testing.assert_array_equal(exact, kernel)
    # behind a current loop too, its time constant's column as well: the kernel's with
    # the loop, which starts at the first torque (as the differences' runs do)
    looped = (*names, "tau_i")
    _, exact = crb._exact(rough, looped, 1e-3, t, u, "paper", x0)
    start = np.r_[np.zeros(3) if x0 is None else x0, u[0]]
    kernel = sensitivities(rough, t, u, initial_state=start, params=looped,
                           actuator=bk.CurrentLoop(1e-3))
    np.testing.assert_array_equal(exact, kernel)
    # outside it (a breakaway torque of its own) the bound differences
    sticky = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fs_M=0.02)
    assert crb._exact(sticky, names, 0.0, t, u, "paper", x0) == (None, None)


#: The bound behind a loop with its time constant estimated is worse conditioned (theta's
#: bound 2.7 times paper A's model's here): the differenced bound moves by 1.8e-5 of
#: itself at CHECK_STEP, 4.5e-4 at 3e-5 and 5.4e-4 at 1e-6, while the sensitivities
#: agree within SENS_FD_RTOL.
LOOP_CRB_RTOL = 1e-4


@pytest.mark.parametrize("loop", [False, True])
def test_crb_from_a_steady_start_takes_the_kernel(short, loop):
    """From the steady start (``initial_state="steady"``, which moves with the
    parameters, as the joint fit's ``start="steady"``) the bound takes the compiled
    sensitivities, from that start's own (``steady_sensitivity``); it agrees with the
    bound of central differences, on paper A's model and behind a 1 ms current loop
    (the loop's time constant estimated too)."""
    from backlashkit.identify import crb

    t, u, _ = short
    names = ("theta", *LINEAR_PARAMS, *(("tau_i",) if loop else ()))
    tau_i = 1e-3 if loop else 0.0
    assert crb._in_scope(TRUE, names, tau_i, "paper", "steady")
    speeds, exact = crb._exact(TRUE, names, tau_i, t, u, "paper", "steady")
    values = np.array([tau_i if n == "tau_i" else getattr(TRUE, n) for n in names])
    speeds_fd, fd = crb._differenced(TRUE, names, values, CHECK_STEP, tau_i, t, u, "paper",
                                     "steady")
    np.testing.assert_allclose(speeds, speeds_fd, rtol=0, atol=1e-10 * np.max(np.abs(speeds_fd)))
    for s_exact, s_fd in zip(exact.transpose(1, 0, 2), fd.transpose(1, 0, 2), strict=True):
        scale = np.max(np.abs(s_fd), axis=0)
        assert np.max(np.abs(s_exact - s_fd) / scale) < SENS_FD_RTOL
    bound = cramer_rao_bound(TRUE, t, u, snr_db=30, estimate=names, initial_state="steady",
                             tau_i=tau_i)
    fisher = sum(s.T @ s / sd**2 for s, sd in zip(fd.transpose(1, 0, 2), bound.noise_std,
                                                   strict=True))
    by_fd = np.sqrt(np.linalg.inv(fisher)[0, 0])
    print(f"CRB of theta from the steady start{' behind a loop' if loop else ''}: exact "
          f"{bound.theta_std:.6e}, central differences {by_fd:.6e} "
          f"({bound.theta_std / by_fd - 1:+.1e})")
    assert bound.theta_std == pytest.approx(by_fd, rel=LOOP_CRB_RTOL if loop else CRB_EXACT_RTOL)


def _exact_against_differences(res, z: np.ndarray, what: str, step: float = CHECK_STEP,
                               rtol: float = SENS_FD_RTOL) -> np.ndarray:
    """The residual's exact Jacobian at ``z``, checked against its central differences
    (step ``step``) to ``rtol`` of each column's largest; ``-s`` prints the
    agreement."""
    exact = res.exact_jacobian(z)
    assert exact is not None and exact.shape == (res.n_res, z.size)
    zz = np.repeat(z[np.newaxis, :], 2 * z.size, axis=0)
    for i in range(z.size):
        zz[2 * i, i] += step
        zz[2 * i + 1, i] -= step
    rr = res(zz)
    fd = ((rr[0::2] - rr[1::2]) / (2 * step)).T
    worst = np.max(np.max(np.abs(exact - fd), axis=0) / np.max(np.abs(fd), axis=0))
    print(f"exact Jacobian {what} against central differences: {worst:.1e}")
    assert worst < rtol
    return exact


@pytest.mark.parametrize("ar", [None, [-0.5, 0.1]])
def test_the_fits_exact_jacobian_matches_central_differences(short, ar):
    """The uncertainty's Jacobian (weighted residual in log-parameters, whitened with
    an AR noise model, the prior's rows) from the compiled sensitivities agrees with
    central differences of the residual; with Coulomb friction it is the kernel's
    (:func:`_check_coulomb_columns`)."""
    from backlashkit.identify._model import rel_std
    from backlashkit.identify._problem import build_problem

    t, u, clean = short
    recs = [_noisy(clean, 30, 1), _noisy(clean, 30, 2)]
    pb, sig = build_problem(TRUE.with_theta(None), recs, rel_std(0.3, LINEAR_PARAMS), None,
                            JointSearch(), "paper", 1)
    lags = None if ar is None else np.tile(ar, (len(recs), 2, 1))
    res = pb.residual(pb.spans, None, sig, lags)
    z = np.log([getattr(TRUE, n) for n in pb.names])
    exact = _exact_against_differences(res, z, "of the fit")
    # the iterations (Problem.refine) take the same Jacobian, and the profile's
    # held-theta refits the same without theta's column, from runs without it
    assert np.array_equal(res.jacobian(z, res.at(z)), exact)
    held = res.exact_jacobian(z, with_theta=False)
    assert held.shape == (res.n_res, len(pb.names) - 1)
    assert np.array_equal(held, exact[:, 1:])
    _check_coulomb_columns(pb, sig, z)


@pytest.mark.parametrize("start", ["hold", "steady"])
def test_the_exact_jacobian_from_a_start_that_moves_with_the_parameters(short, start):
    """A span that starts after a held torque (the short-horizon stages' spans,
    ``Problem.screen``, fitted in windows) or from the model's steady state starts
    with that state's sensitivity: the Jacobian agrees with central differences."""
    from backlashkit.identify._model import rel_std
    from backlashkit.identify._problem import build_problem

    t, u, clean = short
    recs = [_noisy(clean, 30, 1), _noisy(clean, 30, 2)]
    search = JointSearch() if start == "hold" else JointSearch(start="steady",
                                                               pre_window=0.5)
    pb, sig = build_problem(TRUE.with_theta(None), recs, rel_std(0.3, LINEAR_PARAMS), None,
                            search, "paper", 1)
    spans, horizon = (pb.screen, 0.3) if start == "hold" else (pb.spans, None)
    assert all((sp.hold is not None) == (start == "hold") for sp in spans if sp.level)
    assert any(sp.level is not None for sp in spans)
    res = pb.residual(spans, horizon, sig)
    _exact_against_differences(res, np.log([getattr(TRUE, n) for n in pb.names]),
                               f"from a {start} start")


@pytest.mark.parametrize("what", ["whole", "hold", "loop", "ar"])
def test_the_exact_jacobian_of_encoder_angles_matches_central_differences(short, what):
    """Records of encoder angles are fitted as angles, each span's from its first
    sample, less their mean: the Jacobian from the sensitivity of the motor's angle,
    which the span's run tracks, agrees with central differences of the residual; on
    the whole records, on the windows after a held torque, behind a current loop (its
    time constant's column too), and whitened by an AR noise model."""
    from backlashkit.identify._model import rel_std
    from backlashkit.identify._problem import build_problem

    t, u, clean = short
    rng = np.random.default_rng(7)
    # the angles' values do not enter the Jacobian (they are offsets of the residual)
    phi_m, phi_l = np.cumsum(clean.w_motor) * 1e-3, np.cumsum(clean.w_load) * 1e-3
    recs = [Record.from_positions(t, u, phi_m + rng.normal(0, 1e-4, t.size), phi_l,
                                  name=f"enc{k}") for k in range(2)]
    pb, sig = build_problem(TRUE.with_theta(None), recs, rel_std(0.3, LINEAR_PARAMS), None,
                            JointSearch(), "paper", 1)
    z = np.log([getattr(TRUE, n) for n in pb.names])
    spans, horizon, lags = pb.spans, None, None
    if what == "hold":
        spans, horizon = pb.screen, 0.3
        assert any(sp.hold is not None for sp in spans)
    elif what == "loop":
        pb = pb.with_params(("tau_i",), {"tau_i": 1e-5}, {})
        z = np.r_[z, np.log(1e-3)]
        spans = pb.spans
    elif what == "ar":
        lags = np.tile([-0.5, 0.1], (len(recs), 2, 1))
    assert all(sp.positions for sp in spans)
    res = pb.residual(spans, horizon, sig, lags)
    _exact_against_differences(res, z, f"of encoder angles ({what})", ANGLE_STEP, ANGLE_RTOL)


def test_the_exact_jacobian_follows_the_residuals_own_runs(short, monkeypatch):
    """At a point the residual has just simulated (Levenberg-Marquardt's accepted
    point), the Jacobian follows those runs, holds included, and simulates nothing
    more; the same values as at a point simulated afresh. A point pushed out of the
    kept ones (``KEPT_POINTS``) is simulated again."""
    from backlashkit.identify import _problem
    from backlashkit.identify._model import rel_std
    from backlashkit.identify._problem import KEPT_POINTS, build_problem

    t, u, clean = short
    recs = [_noisy(clean, 30, 1), _noisy(clean, 30, 2)]
    pb, sig = build_problem(TRUE.with_theta(None), recs, rel_std(0.3, LINEAR_PARAMS), None,
                            JointSearch(), "paper", 1)
    res = pb.residual(pb.screen, 0.3, sig)
    assert any(sp.hold is not None for sp in res.spans)
    z = np.log([getattr(TRUE, n) for n in pb.names])
    fresh = res.exact_jacobian(z)
    res.kept.clear()
    res.at(z)
    calls = []
    real = _problem.simulate_span
    monkeypatch.setattr(_problem, "simulate_span",
                        lambda *a, **kw: calls.append(1) or real(*a, **kw))
    assert np.array_equal(res.exact_jacobian(z), fresh)
    assert not calls
    for i in range(KEPT_POINTS):
        res.at(z + 1e-3 * (i + 1))
    assert np.array_equal(res.exact_jacobian(z), fresh)
    assert len(calls) == (KEPT_POINTS + 1) * len(res.spans)


def test_the_steady_starts_sensitivity_is_the_long_holds():
    """The steady state's sensitivity in closed form
    (:func:`~backlashkit.identify._model.steady_sensitivity`) against central
    differences of the steady state, and against the compiled sensitivities at the end
    of a held torque long enough to settle (an independent route to it), with Coulomb
    friction, moving or held stuck."""
    from backlashkit._sensitivity import PARAMS
    from backlashkit.identify._model import Span, initial_states, packed_row, span_start
    from backlashkit.identify._model import steady_sensitivity as steady

    PARAMS = PARAMS[:-1]  # noqa: N806 (the drive's: tau_i is the loop's)
    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, fc_M=0.01, fc_L=0.02)
    for level in (A2, -A2, 0.02):  # 0.02 N m < fc_M + fc_L: held stuck
        got = steady(drive, level, PARAMS)
        for c, n in enumerate(PARAMS):
            h = 1e-6 * getattr(drive, n)
            hi, lo = (initial_states(packed_row(replace(drive, **{n: getattr(drive, n) + d})
                                                )[np.newaxis, :], level)[0]
                      for d in (h, -h))
            np.testing.assert_allclose(got[:, c], (hi - lo) / (2 * h), rtol=1e-6,
                                       atol=1e-9 * np.max(np.abs(got)), err_msg=n)
    # a 120 s hold from rest: the slowest mode's time constant, (J_M + J_L) / (f_M +
    # f_L), is 7.3 s, so the state is e^-16 and its sensitivity, which carries t
    # e^(-t/tau) terms, 16 e^-16 = 1.2e-6 from settled
    t, u = np.arange(3) * 1e-3, np.zeros(3)
    span = Span(None, 0, 0, t, u, u, u, A2, hold=120.0)
    x0, s0 = span_start(drive, span, PARAMS)
    want = steady(drive, A2, PARAMS)
    np.testing.assert_allclose(x0, initial_states(packed_row(drive)[np.newaxis, :], A2)[0],
                               rtol=1e-6)
    np.testing.assert_allclose(s0, want, rtol=0, atol=1e-5 * np.max(np.abs(want)))


def _check_coulomb_columns(pb, sig, z):
    """With the Coulomb torques fitted (in natural units, floored, the breakaway
    torques tied to them) the Jacobian is the kernel's sensitivities weighed as the
    residual (tests/test_sensitivity_kernel.py checks those against extrapolated
    differences: plain ones resolve only 1e-2 on this record); a torque held at its
    floor has a zero column, but for the uncertainty (``upward``); behind a current
    loop they are the kernel's with it."""
    from backlashkit._sensitivity import sensitivities

    rough = pb.with_params(("fc_M", "fc_L"), {"fc_M": 1e-9, "fc_L": 1e-9},
                           {"fc_M": 0.01, "fc_L": 0.01})
    res = rough.residual(rough.spans, None, sig)
    for zr in (np.r_[z, 1.0, 2.0], np.r_[z, 1.0, -1.0]):  # the second at fc_L's floor
        jac, (drive, loop) = res.exact_jacobian(zr), rough.exact_model(zr)
        assert loop is None
        # fs None: the breakaway torques are the Coulomb torques
        assert (drive.fc_M, drive.fs_M, drive.fs_L) == (0.01, None, None)
        assert drive.fc_L == (0.02 if zr[-1] > 0 else 1e-9)
        per_z = np.r_[np.exp(z), 0.01, 0.01 if zr[-1] > 0 else 0.0]
        pos = 0
        for sp in rough.spans:
            sens = sensitivities(drive, sp.t, sp.torque, params=rough.names)
            for c in (0, 1):
                want = -sens[:, c, :] * per_z / sig[sp.k, c]
                np.testing.assert_allclose(jac[pos : pos + sp.t.size], want, rtol=1e-12,
                                           atol=0)
                pos += sp.t.size
        assert np.array_equal(jac[pos:, -2:], np.zeros((len(rough.free), 2)))
        r = res.at(zr)
        assert np.array_equal(res.jacobian(zr, r), jac)
    # the uncertainty's (upward): the floored torque's derivative up from its floor
    up = res.exact_jacobian(zr, upward=True)
    assert np.array_equal(up[:, :-1], jac[:, :-1]) and np.abs(up[:pos, -1]).max() > 0
    looped = rough.with_params(("tau_i",), {"tau_i": 1e-5}, {})
    res_loop, zl = looped.residual(looped.spans, None, sig), np.r_[z, 1.0, 1.0, np.log(1e-3)]
    jac, (drive, loop) = res_loop.exact_jacobian(zl), looped.exact_model(zl)
    assert loop.tau_i == pytest.approx(1e-3, rel=1e-12)
    r = res_loop.at(zl)
    assert np.array_equal(res_loop.jacobian(zl, r), jac)
    forward = res_loop.forward_jacobian(zl, r)
    # the loop's column against forward differences (their step's error, about 1e-3)
    big = np.max(np.abs(jac[:, -1]))
    assert np.max(np.abs(forward[:, -1] - jac[:, -1])) < 1e-2 * big


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({}, "exactly one of noise_std"),
        ({"snr_db": 30, "noise_std": (1, 1)}, "exactly one of noise_std"),
        ({"snr_db": 30, "estimate": ("J_M",)}, "including 'theta'"),
        ({"snr_db": 30, "estimate": "some"}, "estimate must be 'all'"),
        ({"noise_std": (1, -1)}, r"noise_std\[1\] \(s_L\) must be > 0"),
        ({"snr_db": (1, 2, 3)}, "snr_db must be a number or a pair"),
    ],
)
def test_crb_validation(short, kwargs, pattern):
    t, u, _ = short
    with pytest.raises(InputError, match=pattern):
        cramer_rao_bound(TRUE, t, u, **kwargs)


def test_crb_needs_theta(short):
    t, u, _ = short
    with pytest.raises(InputError, match="no backlash value"):
        cramer_rao_bound(bk.TwoMassDrive(**P_TRUE), t, u, snr_db=30)


# --- the estimator ------------------------------------------------------------------


def test_coverage_of_ci95(trials):
    covered = sum(e.ci95_[0] <= THETA <= e.ci95_[1] for e in trials)
    assert covered >= MIN_COVERED, covered
    for e in trials:  # the profile interval, close to Fisher's on paper A's drive at 30 dB
        assert e.interval_ == "profile" and e.ci95_bounded_ == (True, True)
        lo, hi = e.ci95_
        assert 0.8 < (e.theta_ - lo) / (1.96 * e.std_) < 1.25
        assert 0.8 < (hi - e.theta_) / (1.96 * e.std_) < 1.25


def _independent_profile(est, rec, theta):
    """Cost rise of the profile at ``theta`` by scipy's least_squares over the other
    log-parameters (the model simulated by ``TwoMassDrive.simulate``, weighted by the
    fit's noise levels), started from the fit."""
    from scipy.optimize import least_squares

    (s_m, s_l), = est.noise_std_

    def residual(w):
        drive = bk.TwoMassDrive(**dict(zip(LINEAR_PARAMS, np.exp(w), strict=True)), theta=theta)
        r = drive.simulate(rec.t, rec.torque)
        return np.r_[(rec.w_motor - r.w_motor) / s_m, (rec.w_load - r.w_load) / s_l]

    w0 = np.log([est.params_[n] for n in LINEAR_PARAMS])
    sol = least_squares(residual, w0, method="lm", xtol=1e-10, ftol=1e-10)
    at_fit = residual(w0) if theta == est.theta_ else None
    return 2 * sol.cost - est.cost_, at_fit


def test_profile_interval_ends_checked_independently(short):
    """At both ends of ``ci95_`` the best fit with ``theta`` held costs 3.84 more than
    the estimate (within the search's tolerance, 0.25), refitted here by scipy's
    Levenberg-Marquardt on the public simulator."""
    _, _, clean = short
    rec = _noisy(clean, 20, 21)
    prior = bk.TwoMassDrive(**{n: 1.1 * x for n, x in P_TRUE.items()})
    e = JointIdentifier(prior).fit(rec)
    fisher = JointIdentifier(prior, interval=bk.FisherInterval()).fit(rec)
    assert e.theta_ == fisher.theta_ and e.std_ == fisher.std_
    assert fisher.ci95_ == pytest.approx((e.theta_ - 1.96 * e.std_, e.theta_ + 1.96 * e.std_))
    _, r = _independent_profile(e, rec, e.theta_)
    assert float(r @ r) == pytest.approx(e.cost_, rel=1e-9)  # same cost function
    for end in e.ci95_:
        rise, _ = _independent_profile(e, rec, end)
        assert rise == pytest.approx(3.84, abs=0.5), (end, rise)
    # the evaluated profile: sorted, zero at the estimate, past 3.84 -/+ 0.25 on each side
    p = e.profile_
    assert p.shape[1] == 2 and np.all(np.diff(p[:, 0]) > 0)
    assert [e.theta_, 0.0] in p.tolist()
    assert p[0, 1] >= 3.84 - 0.25 and p[-1, 1] >= 3.84 - 0.25
    assert p[0, 0] <= e.ci95_[0] * (1 + 1e-9) and p[-1, 0] >= e.ci95_[1] * (1 - 1e-9)
    assert fisher.profile_ is None


def test_std_across_trials_near_crb(trials, short):
    t, u, _ = short
    crb = cramer_rao_bound(TRUE, t, u, snr_db=30, estimate="all", prior_rel_std=REL).theta_std
    thetas = np.array([e.theta_ for e in trials])
    spread = float(np.std(thetas, ddof=1))
    # 20 trials: the sample std has a relative scatter of about 1/sqrt(38) = 16 %
    assert 0.6 * crb < spread < 1.5 * crb, (spread, crb)
    assert abs(np.mean(thetas) - THETA) < 3 * crb
    # the reported standard error agrees with the bound (local linearisation)
    assert np.median([e.std_ for e in trials]) == pytest.approx(crb, rel=0.3)


def test_fitted_attributes(trials):
    e = trials[0]
    assert e.estimated_ == ("theta", *LINEAR_PARAMS)
    assert set(e.params_) == {*LINEAR_PARAMS, "fc_M", "fc_L", "tau_i"}
    assert e.drive_.theta == e.theta_
    # ideal records: the tests of friction and current loop keep paper A's model
    assert (e.friction_, e.fc_M_, e.fc_L_, e.tau_i_) == ("viscous", 0.0, 0.0, 0.0)
    assert [c.term for c in e.choices_] == ["friction", "actuator"]
    assert not any(c.kept for c in e.choices_)
    assert e.noise_std_.shape == (1, 2) and np.all(e.noise_std_ > 0)
    assert e.fit_percent_.shape == (1, 2) and np.all(e.fit_percent_ > 90)
    (res_m, res_l), = e.residuals_
    assert res_m.size == res_l.size == 4001
    assert e.noise_std_[0, 0] == pytest.approx(np.sqrt(np.mean(res_m**2)), rel=1e-3)
    assert e.covariance_.shape == (7, 7) and e.param_std_["theta"] == e.std_
    assert e.cost_ > 0 and e.model_start_ == ["rest"]


def test_wrong_prior_without_penalty_recovers_truth(short):
    """Nearly noise-free data, 20 % prior errors refined from the data alone."""
    _, _, clean = short
    factors = (1.2, 0.8, 1.2, 0.8, 1.2, 0.8)
    prior = bk.TwoMassDrive(**{n: x * f for (n, x), f in zip(P_TRUE.items(), factors,
                                                              strict=True)})
    e = JointIdentifier(prior).fit(_noisy(clean, 80, 3))
    assert e.theta_ == pytest.approx(THETA, rel=1e-3)
    for n in LINEAR_PARAMS:
        assert e.params_[n] == pytest.approx(P_TRUE[n], rel=2e-2), n
    assert e.std_ < 1e-3 * THETA


@pytest.mark.filterwarnings("ignore::backlashkit.CorrelatedResidualsWarning")  # no noise
def test_model_commutation_instants_on_noise_free_data(short):
    """The identified model's t_c, t_b match the true contact changes to 2 samples
    (issue 3's bar; eq. 9 on the sampled load speed puts t_c ~2.4 samples early)."""
    t, u, clean = short
    t_s = float(t[np.flatnonzero(np.diff(u) < 0)[0] + 1])
    lost, made = [e.time for e in clean.events if e.time >= t_s][:2]
    prior = bk.TwoMassDrive(**{n: 1.1 * x for n, x in P_TRUE.items()})
    e = JointIdentifier(prior).fit(Record(t, u, clean.w_motor, clean.w_load))
    (ts_, t_c, t_b), = e.commutations_
    assert ts_ == pytest.approx(t_s)
    assert abs(t_c - lost) <= 2e-3 and abs(t_b - made) <= 2e-3
    assert e.t_c_ == [t_c] and e.t_b_ == [t_b]
    assert e.theta_ini_ is not None and e.theta_ini_ > 0


def test_resplit_keeps_sums_and_ringing_frequency():
    """A split restart moves J_M / J_L (or f_M / f_L) by e^shift and keeps the sum and
    k_sh (1/J_M + 1/J_L)."""
    from backlashkit.identify._search import resplit as _resplit

    free = list(LINEAR_PARAMS)
    z = np.log([THETA, *(P_TRUE[n] for n in free)])
    p = dict(zip(["theta", *free], z, strict=True))
    for pair, shift in ((("J_M", "J_L"), 0.5), (("f_M", "f_L"), -0.5)):
        q = dict(zip(["theta", *free], _resplit(z, free, pair, shift), strict=True))
        a, b = pair
        assert np.exp(q[a]) + np.exp(q[b]) == pytest.approx(np.exp(p[a]) + np.exp(p[b]))
        assert (q[a] - q[b]) - (p[a] - p[b]) == pytest.approx(shift)
        ring = [np.exp(d["k_sh"]) * (np.exp(-d["J_M"]) + np.exp(-d["J_L"])) for d in (p, q)]
        assert ring[1] == pytest.approx(ring[0])
        assert q["theta"] == p["theta"]
    assert _resplit(z[:3], free[:2], ("f_M", "f_L"), 0.5) is None  # pair not estimated


def test_candidates_along_one_basins_flat_direction_count_as_one():
    """Two first-window solutions 3e-3 apart in one log-parameter at costs within
    SAME_COST are one candidate (paper A's records from a prior 30 % off had such a
    pair, continued side by side to the same end); apart in cost, or farther than
    DISTINCT, they are two."""
    from backlashkit.identify._lm import LMState
    from backlashkit.identify._search import DISTINCT, SAME_COST, distinct

    def state(shift, cost):
        return LMState(np.r_[0.0, 0.0, shift], np.zeros(1), cost, None)

    a = state(0.0, 100.0)
    assert len(distinct([a, state(3e-3, 100.0 + 0.5 * SAME_COST)], 3, np.inf)) == 1
    assert len(distinct([a, state(3e-3, 100.0 + 2 * SAME_COST)], 3, np.inf)) == 2
    assert len(distinct([a, state(2 * DISTINCT, 100.0)], 3, np.inf)) == 2
    assert len(distinct([a, state(1e-4, 150.0)], 3, np.inf)) == 1  # SAME_POINT


def test_a_rival_on_the_estimates_valley_floor_is_no_rival():
    """``bowl_rise`` measures a rival's distance up the estimate's Fisher quadratic in
    natural units. Two friction coefficients of about equal size whose sum alone the
    residual sees: a split moved x0.53 and x1.39 (0.63 and 0.33 apart in their
    logarithms, far beyond DISTINCT) keeps the sum, and lies on the valley's floor,
    while a point 3 standard errors off the sum lies 9 up it. ``theta`` next to 0: a
    thousandth of the estimate's, 7 apart in its logarithm, is no step in rad."""
    from backlashkit.identify._search import BOWL_RISE, bowl_rise, outside_bowl

    f = np.array([1.0, 1.2])  # the two coefficients, their sum seen with std 0.01
    jz = np.zeros((2, 3))
    jz[0, 1:] = f / 0.01  # columns p dr/dp; theta's: 0 (a theta of 1e-14 rad)
    jz[1, 0] = 1e-9
    z = np.r_[math.log(1e-14), np.log(f)]
    split = np.r_[z[0], np.log([f[0] * 0.5348, f[1] + f[0] * (1 - 0.5348)])]
    assert np.ptp(split[1:] - z[1:]) > 60 * 1e-2  # far apart in logarithms
    logs = np.zeros(3, bool)
    assert bowl_rise(jz, z, split, logs) == pytest.approx(0.0, abs=1e-12)
    off = np.r_[z[0], np.log(f * (1 + 0.03 / f.sum()))]  # the sum 0.03 up: 3 std
    assert bowl_rise(jz, z, off, logs) == pytest.approx(9.0)
    near_0 = np.r_[z[0] - math.log(1e3), z[1:]]
    assert bowl_rise(jz, z, near_0, logs) < 1e-15
    assert outside_bowl(jz, z, [split, off, near_0], logs) == [off] and BOWL_RISE < 9.0
    # the same split with the two estimated in natural units (as the Coulomb torques, of
    # scale 1: their columns dr/dp): its steps are the differences themselves
    jz[0, 1:] = 1.0 / 0.01
    natural = np.array([False, True, True])
    assert bowl_rise(jz, np.r_[z[0], f], np.r_[z[0], np.exp(split[1:])],
                     natural) == pytest.approx(0.0, abs=1e-12)
    assert bowl_rise(jz, np.r_[z[0], f], np.r_[z[0], np.exp(off[1:])],
                     natural) == pytest.approx(9.0)


def test_parametric_bootstrap(short):
    """Resamples simulated from the estimate and refitted: std_ and ci95_ from their
    spread, the estimate itself unchanged, the same resamples for the same seed."""
    _, _, clean = short
    prior = bk.TwoMassDrive(**{n: 1.1 * x for n, x in P_TRUE.items()})
    rec = _noisy(clean, 30, 11)
    boot = bk.ParametricBootstrap(6, seed=3)
    e = JointIdentifier(prior, interval=boot).fit(rec)
    f = JointIdentifier(prior, interval=bk.FisherInterval()).fit(rec)
    assert e.interval_ == "bootstrap" and f.interval_ == "fisher"
    assert e.bootstrap_thetas_.shape == (6,) and f.bootstrap_thetas_ is None
    assert e.std_ == pytest.approx(np.std(e.bootstrap_thetas_, ddof=1))
    q = 2.5706  # Student's 97.5 % quantile, 5 degrees of freedom (std from 6 refits)
    assert e.ci95_ == pytest.approx((e.theta_ - q * e.std_, e.theta_ + q * e.std_), rel=1e-4)
    assert e.theta_ == f.theta_ and e.param_std_ == f.param_std_
    # resampled around the estimate, with a spread of the Fisher std's order
    assert abs(np.mean(e.bootstrap_thetas_) - e.theta_) < 3 * f.std_
    assert 0.3 < e.std_ / f.std_ < 3
    again = JointIdentifier(prior, interval=boot).fit(rec)
    np.testing.assert_array_equal(again.bootstrap_thetas_, e.bootstrap_thetas_)
    # the refits pickled to two worker processes: the same refits, bit for bit
    pooled = JointIdentifier(prior, interval=bk.ParametricBootstrap(6, seed=3, jobs=2)).fit(rec)
    np.testing.assert_array_equal(pooled.bootstrap_thetas_, e.bootstrap_thetas_)


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"n_resamples": 1}, "n_resamples must be an integer >= 2"),
        ({"seed": -1}, "seed must be an integer >= 0"),
        ({"seed": 1.5}, "seed must be an integer"),
    ],
)
def test_parametric_bootstrap_validated(kwargs, pattern):
    with pytest.raises(InputError, match=pattern):
        bk.ParametricBootstrap(**kwargs)


def test_stiffness_grid_starts(short):
    """With k_sh 40 % low in the prior, the gridded stiffness gives starts near the
    truth's ringing frequency, and the fit still recovers theta and k_sh."""
    _, _, clean = short
    prior = bk.TwoMassDrive(**{**P_TRUE, "k_sh": 0.6 * P_TRUE["k_sh"]})
    search = JointSearch(grid=ThetaGrid(stiffness_points=5))
    e = JointIdentifier(prior, search=search).fit(_noisy(clean, 60, 5))
    assert e.theta_ == pytest.approx(THETA, rel=1e-2)
    assert e.params_["k_sh"] == pytest.approx(P_TRUE["k_sh"], rel=1e-2)
    assert len(e.theta_starts_) >= 2


def test_known_noise_and_subset_of_parameters(short):
    _, _, clean = short
    prior = TRUE.with_theta(None)
    e = JointIdentifier(prior, prior_rel_std={"k_sh": 0.1, "J_M": 0.0},
                        noise=(0.5, 0.5), **PAPER_MODEL).fit(_noisy(clean, 30, 4))
    assert e.estimated_ == ("theta", "k_sh")
    assert e.params_["J_M"] == P_TRUE["J_M"]
    assert e.noise_std_.tolist() == [[0.5, 0.5]]
    assert abs(e.theta_ - THETA) < 4 * e.std_


def test_steady_start(short):
    """A record that starts in steady state under the held torque."""
    t = signals.time_grid(3.0, 1e-3)
    u = signals.step_down(t, A2, t_s=1.0)
    clean = TRUE.simulate(t, u, initial_state=TRUE.steady_state(A2))
    e = JointIdentifier(bk.TwoMassDrive(**P_TRUE), prior_rel_std=0.05,
                        search=JointSearch(pre_window=0.5)).fit(_noisy(clean, 40, 5))
    assert e.model_start_ == ["steady"]
    assert e.residuals_[0][0].size == 2501
    assert abs(e.theta_ - THETA) < 4 * e.std_ and e.std_ < 0.02 * THETA
    with pytest.raises(InputError, match="pre_window"):
        JointIdentifier(bk.TwoMassDrive(**P_TRUE),
                        search=JointSearch(start="steady", pre_window=2.0)
                        ).fit(_noisy(clean, 40, 5))


def test_paper_protocol_quick():
    """Paper A's protocol (80 s records, paper SNRs), Err_p = 30 %, 3 runs."""
    t = signals.time_grid(80.0, 1e-3)
    out = []
    for k in range(3):
        s1, s2, sp = np.random.SeedSequence([2002, 300, k]).spawn(3)
        x = np.random.default_rng(sp).uniform(-1, 1, 6)
        prior = bk.TwoMassDrive(**{n: v * (1 - 0.3 * xi)
                                   for (n, v), xi in zip(P_TRUE.items(), x, strict=True)})
        recs = []
        for a, snr, s in ((0.157, (17.4, 6.43), s1), (A2, (35.7, 35.6), s2)):
            r = TRUE.simulate(t, signals.step_down(t, a, t_s=40.0))
            sm, sl = s.spawn(2)
            recs.append(Record(t, r.torque, signals.add_noise(r.w_motor, snr[0], rng=sm),
                               signals.add_noise(r.w_load, snr[1], rng=sl)))
        e = JointIdentifier(prior).fit(recs)
        assert e.std_ < 1.0e-3
        assert abs(e.theta_ - THETA) < 4 * e.std_
        out.append(e.theta_)
    assert abs(np.mean(out) - THETA) < 0.02 * THETA


def _robustness_trial(seed: int, scenario: int, trial: int, trials: int, theta_deg: float,
                      snr: float):
    """Records and prior of one trial of ``benchmarks/robustness_joint.py --seed SEED
    --trials TRIALS`` on the light load J_L/J_M = 2 (the script's seeding)."""
    base = {**P_TRUE, "J_L": 1.0e-2}
    drive = bk.TwoMassDrive(**base, theta=np.deg2rad(theta_deg))
    t = signals.time_grid(80.0, 1e-3)
    s_rec, s_prior = np.random.SeedSequence([seed, scenario]).spawn(trials)[trial].spawn(2)
    recs = []
    for a, ss in zip((0.157, 0.942), s_rec.spawn(2), strict=True):
        with warnings.catch_warnings():  # grazing late in the coast-down, below the noise
            warnings.simplefilter("ignore", bk.SensitivityWarning)
            r = drive.simulate(t, signals.step_down(t, a, t_s=40.0))
        sm, sl = ss.spawn(2)
        recs.append(Record(t, r.torque, signals.add_noise(r.w_motor, snr, rng=sm),
                           signals.add_noise(r.w_load, snr, rng=sl)))
    x = np.random.default_rng(s_prior).uniform(-1, 1, len(LINEAR_PARAMS))
    prior = bk.TwoMassDrive(**{n: base[n] * (1 - 0.4 * xi)
                               for n, xi in zip(LINEAR_PARAMS, x, strict=True)})
    return drive, recs, prior


def _weighted_sse(est, noise):
    """Sum of squared residuals of a fit weighted by ``noise`` (one set of noise levels
    for the fits compared, so that their costs compare)."""
    return sum(np.sum(em**2) / s_m**2 + np.sum(el**2) / s_l**2
               for (em, el), (s_m, s_l) in zip(est.residuals_, noise, strict=True))


def test_stiffness_restarts_escape_a_wrong_ringing_phase():
    """A trial of ``benchmarks/robustness_joint.py --trials 6 --seed 4`` (light load J_L/J_M = 2,
    theta 2 deg, 20 dB, prior 40 % off): without the restarts the fit settles with
    ``k_sh`` 22 % low and theta 8 % low, in a minimum the true parameters beat; a
    restart at a 16 % higher stiffness reaches the minimum near the truth (so does the
    finer continuation path, switched off here to test the restarts alone)."""
    drive, recs, prior = _robustness_trial(4, 3, 1, 6, 2.0, 20.0)
    one_path = Continuation(fine_horizons=())
    stuck = JointIdentifier(prior, search=JointSearch(
        restarts=Restarts(stiffness=(), long=()), continuation=one_path)).fit(recs)
    fit = JointIdentifier(prior, search=JointSearch(continuation=one_path)).fit(recs)
    assert stuck.theta_ < 0.94 * drive.theta and stuck.params_["k_sh"] < 0.85 * drive.k_sh
    assert abs(fit.theta_ / drive.theta - 1) < 0.05
    assert abs(fit.params_["k_sh"] / drive.k_sh - 1) < 0.1


def test_wide_stiffness_restarts_reach_the_truths_basin():
    """A trial of ``benchmarks/robustness_joint.py --seed 5 --trials 20`` (light load,
    theta 2 deg, 20 dB, CRB 2.0 %): with the restarts at e^+-0.15 alone the fit
    settles at 0.47 of the true stiffness with theta 10 % low, a minimum the true
    parameters beat; the restart at e^0.4 (screened: below the solution's cost after
    ``RESTART_SCREEN_ITER`` iterations) reaches the minimum near the truth. The path
    past the first window (``Continuation.direct``) reaches it too, so the narrow fit
    goes without it."""
    drive, recs, prior = _robustness_trial(5, 3, 17, 20, 2.0, 20.0)
    fisher = bk.FisherInterval()  # the restarts come before the interval
    narrow = JointIdentifier(prior, search=JointSearch(
        continuation=Continuation(direct=False),
        restarts=Restarts(stiffness=(0.15,), long=())),
        interval=fisher).fit(recs)
    fit = JointIdentifier(prior, interval=fisher).fit(recs)
    assert fit.search.restarts.stiffness == (0.15, 0.4, 0.8)  # the default
    assert narrow.theta_ < 0.93 * drive.theta and narrow.params_["k_sh"] < 0.6 * drive.k_sh
    assert abs(fit.theta_ / drive.theta - 1) < 0.02
    assert abs(fit.params_["k_sh"] / drive.k_sh - 1) < 0.05
    assert _weighted_sse(fit, fit.noise_std_) < _weighted_sse(narrow, fit.noise_std_) - 50


def test_friction_restarts_cross_the_ridge_of_a_wrong_split():
    """A trial of ``benchmarks/robustness_joint.py --seed 11 --trials 30`` (light load,
    theta 5 deg, 40 dB, CRB 0.11 %): without the restarts of the friction split the fit
    settles with f_M 42 % low and f_L 42 % high, theta 2.9 % low (9 of its standard
    errors), 35 000 chi-square units above the minimum near the truth; the restart with
    f_M / f_L multiplied by e reaches that minimum."""
    drive, recs, prior = _robustness_trial(11, 8, 26, 30, 5.0, 40.0)
    fisher = bk.FisherInterval()
    # without the second search too, which also leaves this minimum (misfit_restart)
    with pytest.warns(bk.CorrelatedResidualsWarning):
        stuck = JointIdentifier(prior, search=JointSearch(
            restarts=Restarts(friction=(), misfit=False, long=())), interval=fisher,
            **PAPER_MODEL).fit(recs)
    fit = JointIdentifier(prior, interval=fisher, **PAPER_MODEL).fit(recs)
    assert fit.search.restarts.friction == (1.0,)  # the default
    assert not fit.misfit_restarted_  # the friction restart alone reached it
    assert stuck.params_["f_M"] < 0.7 * drive.f_M and stuck.theta_ < 0.98 * drive.theta
    assert abs(stuck.theta_ - drive.theta) > 5 * stuck.std_
    assert abs(fit.params_["f_M"] / drive.f_M - 1) < 0.05
    assert abs(fit.theta_ - drive.theta) < 1.96 * fit.std_
    assert _weighted_sse(fit, fit.noise_std_) < _weighted_sse(stuck, fit.noise_std_) - 10_000


def test_misfit_restart_leaves_a_stiff_shaft_without_backlash():
    """A trial of ``benchmarks/robustness_joint.py --seed 21 --trials 40`` (light load,
    theta 2 deg, 40 dB, CRB 0.2 %): from the prior (J_M 31 % low, J_L 37 % high)
    every start of the theta grid lies in the basin of a stiff shaft with almost no
    backlash, and the fit
    ends at 7 % of the true theta with a residual whose lag-1 autocorrelation (0.24)
    no noise has; the second search, from the fitted linear parameters, finds the
    truth's basin and is kept."""
    drive, recs, prior = _robustness_trial(21, 5, 12, 40, 2.0, 40.0)
    fisher = bk.FisherInterval()
    with pytest.warns(bk.CorrelatedResidualsWarning,
                      match=r"lag-1 .*the model misfits, since the noise itself is white"):
        stuck = JointIdentifier(prior, search=JointSearch(restarts=Restarts(misfit=False,
                                                                          long=())),
                                interval=fisher).fit(recs)
    assert np.all(np.abs(stuck.held_noise_lag1_) < 0.1)  # the speeds' own noise: white
    fit = JointIdentifier(prior, interval=fisher).fit(recs)
    assert fit.search.restarts.misfit is True  # the default
    with pytest.raises(bk.InputError, match="Restarts.misfit must be True or False, got 'no'"):
        Restarts(misfit="no")
    assert not stuck.misfit_restarted_ and stuck.theta_ < 0.2 * drive.theta
    assert np.max(np.abs(stuck.residual_lag1_)) > 0.2
    assert fit.misfit_restarted_ and fit.misfit_restart_won_
    assert abs(fit.theta_ / drive.theta - 1) < 0.01
    assert np.max(np.abs(fit.residual_lag1_)) < 0.02
    assert _weighted_sse(fit, fit.noise_std_) < _weighted_sse(stuck, fit.noise_std_) - 10_000


def test_fine_horizons_avoid_a_wrong_basin():
    """A trial of ``benchmarks/robustness_joint.py --seed 5 --trials 20`` (light load,
    theta 5 deg, 20 dB, CRB 1.1 %): continued by the long steps 0.4 -> 1 -> 3 s alone,
    the fit ends with theta 15 % low and k_sh 36 % low, 470 chi-square units above the
    minimum near the truth; the finer path reaches that minimum and wins on the whole
    record. (The wide stiffness restarts, switched off here to test the path alone,
    reach it from the wrong basin too.)

    That held in the environments of earlier CI runs. In a fresh one of 2026-12-02
    (numpy 2.4.6, scipy 1.17.1, a new build; commit 8f352ce, which passed CI, fails
    there too) the long steps alone reach the minimum near the truth as well (theta
    0.2 % off). So the wrong basin is asserted only where the path alone still ends
    in it; the fit must be right either way."""
    drive, recs, prior = _robustness_trial(5, 6, 9, 20, 5.0, 20.0)
    one_path = JointIdentifier(prior, search=JointSearch(
        continuation=Continuation(fine_horizons=()),
        restarts=Restarts(stiffness=(0.15,), long=()))
    ).fit(recs)
    fit = JointIdentifier(prior).fit(recs)
    assert abs(fit.theta_ / drive.theta - 1) < 0.02
    assert abs(fit.theta_ - drive.theta) < 1.96 * fit.std_
    sse_fit, sse_one = (_weighted_sse(f, fit.noise_std_) for f in (fit, one_path))
    assert sse_fit <= sse_one + 1.0
    if one_path.theta_ < 0.9 * drive.theta:
        assert sse_fit < sse_one - 100


def test_ambiguity_starts_continue_more_candidates():
    """A trial of ``benchmarks/robustness_joint.py --seed 5 --trials 20`` (light load,
    theta 0.5 deg, 20 dB): the two continuation paths end in distinct minima, and the
    usual candidates all lead to one with theta 29 % low and k_sh 55 % high (a rival
    basin's profile, ``IntervalInputs.rivals``, now finds a lower point there, still
    far off, and the estimate moves to it), outside its interval;
    continuing more first-horizon solutions finds a lower minimum whose interval
    covers the truth."""
    drive, recs, prior = _robustness_trial(5, 0, 10, 20, 0.5, 20.0)
    usual = JointIdentifier(prior, search=JointSearch(
        continuation=Continuation(ambiguity_starts=0)), **PAPER_MODEL).fit(recs)
    fit = JointIdentifier(prior, **PAPER_MODEL).fit(recs)
    assert usual.ambiguous_ and fit.ambiguous_  # detected either way; acted on if asked
    assert usual.theta_ < 0.8 * drive.theta and abs(usual.params_["k_sh"] / drive.k_sh - 1) > 0.3
    assert abs(usual.theta_ - drive.theta) > 1.96 * usual.std_
    assert abs(fit.theta_ / drive.theta - 1) < 0.1
    assert abs(fit.theta_ - drive.theta) < 1.96 * fit.std_
    assert _weighted_sse(fit, fit.noise_std_) < _weighted_sse(usual, fit.noise_std_) - 10


def test_profile_interval_of_theta_alone(short):
    """With the linear parameters known the profile is the cost itself: at the ends of
    ``ci95_`` the weighted cost of the simulated drive is 3.84 above the estimate's."""
    _, _, clean = short
    rec = _noisy(clean, 30, 8)
    # no current loop tested: a dropped loop widens the interval past the profile's ends
    e = JointIdentifier(bk.TwoMassDrive(**P_TRUE), prior_rel_std=0, actuator=None).fit(rec)
    assert e.estimated_ == ("theta",) and e.interval_ == "profile"
    (s_m, s_l), = e.noise_std_
    for end in e.ci95_:
        r = bk.TwoMassDrive(**P_TRUE, theta=end).simulate(rec.t, rec.torque)
        cost = (np.sum(((rec.w_motor - r.w_motor) / s_m) ** 2)
                + np.sum(((rec.w_load - r.w_load) / s_l) ** 2))
        assert cost - e.cost_ == pytest.approx(3.84, abs=0.25)
    assert e.ci95_[0] < e.theta_ < e.ci95_[1]


def _in_contact_record() -> Record:
    """8 s around a torque drop from 0.942 to 0.6 N m on a drive settled from rest: the
    shaft never leaves its flank, so the speeds do not depend on theta at all."""
    t = signals.time_grid(44.0, 1e-3)
    u = np.where(t < 40.0, A2, 0.6)
    r = TRUE.simulate(t, u)
    keep = t >= 36.0
    a, b = np.random.SeedSequence(3).spawn(2)
    return Record(t[keep] - 36.0, u[keep], signals.add_noise(r.w_motor[keep], 30, rng=a),
                  signals.add_noise(r.w_load[keep], 30, rng=b), name="in_contact.csv")


def test_profile_interval_open_when_the_records_do_not_bound_theta(tmp_path, capsys):
    rec = _in_contact_record()
    e = JointIdentifier(bk.TwoMassDrive(**P_TRUE), prior_rel_std=0.1).fit(rec)
    # the Fisher interval reaches 0, so the profile is followed in rad of theta, up to
    # half a turn: the records bound nothing below it
    assert e.model_start_ == ["steady"] and e.theta_ <= 1.96 * e.std_
    assert e.ci95_bounded_[1] is False and e.ci95_[1] == pytest.approx(MAX_HALF_WIDTH)
    path = tmp_path / "in_contact.csv"
    write_csv(path, {"t": rec.t, "torque": rec.torque, "w_motor": rec.w_motor,
                     "w_load": rec.w_load})
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--prior-rel-std", "0.1"]) == 0
    out, _ = capsys.readouterr()
    assert "note: the likelihood does not rise to the 95% level on the upper side" in out


def test_profile_interval_follows_a_rattling_likelihood():
    """A trial of ``benchmarks/robustness_joint.py --seed 5 --trials 20`` (light load,
    theta 5 deg, 20 dB): the estimate is 2.4 Fisher standard errors below the truth;
    the profile likelihood rises more slowly above the estimate than its curvature
    says, and its interval, asymmetric, covers the truth (at about half its upper
    half-width)."""
    drive, recs, prior = _robustness_trial(5, 6, 17, 20, 5.0, 20.0)
    fit = JointIdentifier(prior, **PAPER_MODEL).fit(recs)
    assert fit.interval_ == "profile" and fit.ci95_bounded_ == (True, True)
    assert abs(fit.theta_ - drive.theta) > 1.96 * fit.std_  # Fisher's misses
    lo, hi = fit.ci95_
    assert lo <= drive.theta <= hi
    assert hi - fit.theta_ > 1.5 * (fit.theta_ - lo)


def test_profile_search_recentres_the_estimate(monkeypatch):
    """A trial of ``benchmarks/robustness_joint.py --seed 5 --trials 20`` (light load,
    theta 2 deg, 30 dB): a held-theta refit of the profile search ends 0.9 below the
    estimate's cost; refined from there, the estimate moves to a lower minimum, closer
    to the truth. The stiffness restarts on a longer window (``Restarts.long``) now
    reach that minimum in the search itself, so they are off for the recentring's
    test."""
    from backlashkit.identify import _search

    drive, recs, prior = _robustness_trial(5, 4, 15, 20, 2.0, 30.0)
    search = JointSearch(restarts=Restarts(long=()))
    fit = JointIdentifier(prior, search=search).fit(recs)
    monkeypatch.setattr(_search, "RECENTRE_MAX", 0)
    stopped = JointIdentifier(prior, search=search).fit(recs)
    assert stopped.profile_[:, 1].min() < -_search.RECENTRE_MARGIN
    assert fit.profile_[:, 1].min() == 0.0  # the new estimate is its profile's minimum
    assert fit.cost_ < stopped.cost_ - _search.RECENTRE_MARGIN
    assert abs(fit.theta_ / drive.theta - 1) < 0.6 * abs(stopped.theta_ / drive.theta - 1)
    searched = JointIdentifier(prior).fit(recs)  # the default, not recentred
    off = {name: f.theta_ / drive.theta - 1
           for name, f in (("recentred", fit), ("stopped", stopped), ("searched", searched))}
    print("theta off: " + ", ".join(f"{name} {x:+.4f}" for name, x in off.items()))
    assert searched.profile_[:, 1].min() == 0.0
    noise = fit.noise_std_  # one noise level for the three: their costs compare
    assert (_weighted_sse(searched, noise)
            < _weighted_sse(stopped, noise) - _search.RECENTRE_MARGIN)


def test_cli_notes_an_ambiguous_fit(tmp_path, capsys):
    """``identify`` says when the search found distinct minima (the trial above)."""
    _, recs, prior = _robustness_trial(5, 0, 10, 20, 0.5, 20.0)
    paths = []
    for k, rec in enumerate(recs):
        paths.append(str(tmp_path / f"e{k}.csv"))
        write_csv(paths[-1], {"t": rec.t, "torque": rec.torque, "w_motor": rec.w_motor,
                              "w_load": rec.w_load})
    drive = tmp_path / "prior.toml"
    drive.write_text("[drive]\n" + "".join(f"{n} = {getattr(prior, n)!r}\n"
                                           for n in LINEAR_PARAMS))
    assert main(["identify", *paths, "--drive", str(drive)]) == 0
    out, _ = capsys.readouterr()
    assert "note: the search ended in distinct minima of nearly equal cost" in out


#: How far apart two fits of the same records may stop when their iterations take
#: different Jacobians, in standard errors: the Levenberg-Marquardt stops at a gain
#: under 1e-3 chi-square units, about 0.03 standard errors at most.
LM_STOP_STDS = 0.03


def test_final_horizon(short):
    """A final horizon longer than the record is the whole record (fitted through the
    coarse hold simulation instead of sample by sample); a short one fits less data:
    a wider interval around the same truth, the same noise levels."""
    _, _, clean = short
    prior = bk.TwoMassDrive(**{n: 1.1 * x for n, x in P_TRUE.items()})
    rec = _noisy(clean, 30, 5)
    whole = JointIdentifier(prior).fit(rec)
    assert not whole.ambiguous_  # paper A's drive: the continuation paths agree
    long = JointIdentifier(prior, search=JointSearch(final_horizon=10.0)).fit(rec)
    # the whole record's iterations take the exact Jacobian, the held span's (out of the
    # sensitivities' scope) differences: they stop apart by the Levenberg-Marquardt
    # tolerance (a gain under 1e-3 chi-square units), a few thousandths of std_
    assert long.theta_ == pytest.approx(whole.theta_, abs=LM_STOP_STDS * whole.std_)
    assert long.std_ == pytest.approx(whole.std_, rel=1e-4)
    np.testing.assert_allclose(long.noise_std_, whole.noise_std_, rtol=1e-6)
    with warnings.catch_warnings():  # only the fitted samples count for the whiteness
        warnings.simplefilter("error", bk.CorrelatedResidualsWarning)
        short_h = JointIdentifier(prior, search=JointSearch(final_horizon=0.3)).fit(rec)
    assert short_h.std_ > 1.2 * whole.std_
    assert abs(short_h.theta_ - THETA) < 4 * short_h.std_
    np.testing.assert_allclose(short_h.noise_std_, whole.noise_std_, rtol=0.1)
    assert len(short_h.residuals_[0][0]) == rec.t.size  # residuals: the whole record


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"prior_rel_std": {"J_X": 0.1}}, "unknown parameter 'J_X'"),
        ({"prior_rel_std": -0.1}, "prior_rel_std must be >= 0"),
        ({"prior_rel_std": {"J_M": -1}}, r"prior_rel_std\['J_M'\] must be >= 0"),
        ({"noise": (1.0,)}, "noise must be a pair"),
        ({"noise": (1.0, 0.0)}, r"noise\[1\] \(s_L\) must be > 0"),
        ({"interval": 30}, "interval must be a ProfileLikelihood, FisherInterval or "
         r"ParametricBootstrap \(backlashkit.identify.intervals\), got int"),
        ({"interval": "fisher"}, "interval must be .* got str"),
        ({"search": {"n_grid": 61}}, r"search must be a JointSearch "
         r"\(backlashkit.identify.search\), got dict"),
    ],
)
def test_parameters_validated(short, kwargs, pattern):
    _, _, clean = short
    with pytest.raises(InputError, match=pattern):
        JointIdentifier(bk.TwoMassDrive(**P_TRUE), **kwargs).fit(_noisy(clean, 30, 1))


@pytest.mark.parametrize(
    "make, pattern",
    [
        (lambda: JointSearch(start="middle"), "start must be 'auto', 'rest' or 'steady'"),
        (lambda: JointSearch(fd_step=0.5), "fd_step must be < 0.1"),
        (lambda: JointSearch(final_horizon=0.0), "final_horizon must be > 0, got 0.0"),
        (lambda: JointSearch(max_iter=0), "max_iter must be an integer >= 1, got 0"),
        (lambda: JointSearch(grid=(61,)), "grid must be a ThetaGrid, got tuple"),
        (lambda: JointSearch(first=FirstHorizon(horizon=0.5)),
         r"continuation.horizons must start after first.horizon \(0.5 s\)"),
        (lambda: ThetaGrid(points=1), "ThetaGrid.points must be an integer >= 2, got 1"),
        (lambda: ThetaGrid(theta_max=0), "ThetaGrid.theta_max must be > 0, got 0"),
        (lambda: ThetaGrid(stiffness_points=0), "ThetaGrid.stiffness_points must be an "
         "integer >= 1"),
        (lambda: ThetaGrid(stiffness_span=1.0), "ThetaGrid.stiffness_span must be > 1"),
        (lambda: ThetaGrid(two_step_start=1), "ThetaGrid.two_step_start must be True or "
         "False, got 1"),
        (lambda: FirstHorizon(split_shifts=(0.5, -1.0)),
         r"FirstHorizon.split_shifts\[1\] must be > 0, got -1.0"),
        (lambda: FirstHorizon(split_shifts=0.5), "FirstHorizon.split_shifts must be a "
         "sequence of numbers > 0, got 0.5"),
        (lambda: FirstHorizon(search_factor=1.0), "FirstHorizon.search_factor must be > 1"),
        (lambda: FirstHorizon(search_factor=-2.0), "FirstHorizon.search_factor must be > 0"),
        (lambda: Continuation(fine_horizons=(0.3, -1.0)),
         r"Continuation.fine_horizons\[1\] must be > 0"),
        (lambda: Continuation(horizons=(1.0, 0.4)), r"Continuation.horizons must increase"),
        (lambda: Continuation(ambiguity_starts=-1), "Continuation.ambiguity_starts must be "
         "an integer >= 0, got -1"),
        (lambda: Continuation(direct="yes"), "Continuation.direct must be True or False, "
         "got 'yes'"),
        (lambda: Restarts(stiffness=(0.1, 0.0)), r"Restarts.stiffness\[1\] must be > 0"),
        (lambda: Restarts(stiffness=0.1), "Restarts.stiffness must be a sequence of "
         "numbers > 0"),
        (lambda: Restarts(friction=(-1.0,)), r"Restarts.friction\[0\] must be > 0"),
    ],
)
def test_search_configuration_validated(make, pattern):
    with pytest.raises(InputError, match=pattern):
        make()


def test_search_configuration_defaults_and_repr():
    """The configuration objects are frozen, equal by value, normalise sequences to
    tuples of floats, and print only what differs from the defaults."""
    s = JointSearch()
    assert s == JointSearch() and repr(s) == "JointSearch()"
    assert s.first.horizon == 0.15 and s.continuation.horizons == (0.4, 1.0, 3.0)
    assert s.continuation.paths(0.15) == [[0.4, 1.0, 3.0], [0.25, 0.4, 0.6, 1.0, 1.6, 3.0]]
    assert Continuation(fine_horizons=()).paths(0.15) == [[0.4, 1.0, 3.0]]
    assert s.grid.bounds == (np.deg2rad(15.0) / 61, np.deg2rad(15.0))
    custom = JointSearch(restarts=Restarts(stiffness=[1]), final_horizon=1)
    assert custom.restarts.stiffness == (1.0,) and isinstance(custom.final_horizon, float)
    assert repr(custom) == "JointSearch(restarts=Restarts(stiffness=(1.0,)), final_horizon=1.0)"
    with pytest.raises(AttributeError):
        s.max_iter = 3  # frozen
    est = JointIdentifier(TRUE.with_theta(None), search=custom, workers=1)
    assert repr(est).startswith("JointIdentifier(TwoMassDrive(")
    assert repr(est).endswith(", search=JointSearch(restarts=Restarts(stiffness=(1.0,)), "
                              "final_horizon=1.0), workers=1)")


def test_repr_after_fit_is_one_line(trials):
    text = repr(trials[0])
    assert "\n" not in text and f"theta_ = {trials[0].theta_:.4g} rad" in text
    assert f"std_ = {trials[0].std_:.3g} rad" in text and "prior_rel_std=0.1" in text
    assert text.endswith(f"[profile], friction_ = {trials[0].friction_!r}")


def test_help_is_short_and_has_examples():
    """``help(JointIdentifier)`` fits on two screens and its Examples run as written."""
    import doctest
    import pydoc

    # copyreg caches __slotnames__ on the class once an instance is pickled or copied
    # (another test of this process may have): help() would list it, 2 lines
    cache = JointIdentifier.__dict__.get("__slotnames__")
    if cache is not None:
        del JointIdentifier.__slotnames__
    try:
        text = pydoc.render_doc(JointIdentifier, renderer=pydoc.plaintext)
    finally:
        if cache is not None:
            JointIdentifier.__slotnames__ = cache
    assert len(text.splitlines()) <= 110, len(text.splitlines())
    assert "Examples\n" in text
    finder = doctest.DocTestFinder(recurse=False)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for test in finder.find(JointIdentifier):
        runner.run(test)
    assert runner.summarize(verbose=False).failed == 0
    assert runner.summarize(verbose=False).attempted >= 8


def test_prior_type_validated(short):
    _, _, clean = short
    with pytest.raises(InputError, match="prior must be a TwoMassDrive"):
        JointIdentifier({"J_M": 1}).fit(_noisy(clean, 30, 1))


# --- CLI --------------------------------------------------------------------------


def test_cli_joint_json_with_uncertainty_table(short_csv, tmp_path, capsys):
    prior = tmp_path / "prior.toml"
    text = Path(DRIVE_TOML).read_text().replace("k_sh = 78.0", "k_sh = 85.0")
    prior.write_text(text + "\n[uncertainty]\nk_sh = 0.2\nJ_M = 0.1\n")
    capsys.readouterr()
    code = main(["identify", str(short_csv), "--drive", str(prior), "--method", "joint",
                 "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    assert doc["method"] == "joint"
    assert doc["std"] > 0 and doc["ci95"][0] < doc["theta"] < doc["ci95"][1]
    assert abs(doc["theta"] - THETA) < 4 * doc["std"]
    # the table sets which linear parameters are estimated (the loop's test may add tau_i)
    assert [n for n in doc["estimated"] if n not in ("fc_M", "fc_L", "tau_i")] == [
        "theta", "J_M", "k_sh"]
    assert doc["prior_rel_std"] == {"k_sh": 0.2, "J_M": 0.1}
    assert doc["params"]["k_sh"] == pytest.approx(78.0, rel=0.02)
    rec = doc["records"][0]
    assert rec["model_start"] == "rest" and rec["commutation"] == "model"
    assert rec["t_s"] < rec["t_c"] < rec["t_b"] < rec["t_s"] + 0.5
    assert doc["theta_ini"] > 0
    code = main(["identify", str(short_csv), "--drive", str(prior), "--method", "joint",
                 "--prior-rel-std", "0"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "95% interval" in out and "theta     =" in out


def test_cli_joint_bootstrap(short_csv, capsys):
    # no current loop tested: a dropped loop widens the interval past the bootstrap's
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--bootstrap", "3",
                 "--seed", "4", "--json", "--current-loop", "none"])
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    assert doc["interval"] == "bootstrap" and doc["std_fisher"] > 0
    assert doc["ci95_bounded"] == [True, True]
    q = 4.3027  # Student's 97.5 % quantile, 2 degrees of freedom (std from 3 refits)
    assert doc["ci95"] == pytest.approx([doc["theta"] - q * doc["std"],
                                         doc["theta"] + q * doc["std"]], rel=1e-4)
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--json", "--current-loop", "none"])
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    assert doc["interval"] == "fisher" and doc["std"] == doc["std_fisher"]
    assert doc["ci95"] == pytest.approx([doc["theta"] - 1.96 * doc["std"],
                                         doc["theta"] + 1.96 * doc["std"]])
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--bootstrap", "3"])
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1
    assert "give --interval or --bootstrap, not both" in err
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--interval", "profile",
                 "--method", "regression"])
    out, err = capsys.readouterr()
    assert code != 0 and "--interval only applies with --method joint" in err
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--bootstrap", "3",
                 "--method", "two-step"])
    out, err = capsys.readouterr()
    assert code != 0 and "--bootstrap only applies with --method joint" in err
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--final-horizon", "1",
                 "--method", "regression"])
    out, err = capsys.readouterr()
    assert code != 0 and "--final-horizon only applies with --method joint" in err
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--final-horizon", "0"])
    out, err = capsys.readouterr()
    assert code != 0 and "--final-horizon must be > 0" in err
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--final-horizon", "0.5",
                 "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    assert doc["final_horizon"] == 0.5 and doc["interval"] == "profile"
    assert doc["ambiguous"] is False
    assert doc["misfit_restarted"] is False and doc["misfit_restart_won"] is False
    code = main(["identify", str(short_csv), "--drive", DRIVE_TOML, "--bootstrap", "1"])
    out, err = capsys.readouterr()
    assert code != 0 and "--bootstrap must be an integer >= 2" in err
