"""Paper A's backlash identification (``backlashkit.identify``) and ``backlashkit identify``.

Protocol (paper A, Section 5, and the project's NOTES): the paper drive with
``theta* = 2 deg = 3.49e-2`` rad (half-width), Ts = 1 ms, step 1 ``a_1 = 0.157`` N m
held 40 s from rest then 0, step 2 ``a_2 = 0.942`` N m; SNR as defined in
:mod:`backlashkit.signals`.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.errors import InputError
from backlashkit.identify import (
    Record,
    RegressionIdentifier,
    TwoStepIdentifier,
    commutation_instants,
    find_step_down,
    fir_lowpass,
    pre_estimate,
)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DRIVE_TOML = str(EXAMPLES / "paper_drive.toml")
P_TRUE = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
T_S = 40.0
TS = 1e-3
A1, A2 = 0.157, 0.942
PRIOR = bk.TwoMassDrive(**P_TRUE)
TRUE = PRIOR.with_theta(THETA)
ALPHA = P_TRUE["f_L"] / P_TRUE["J_L"]


@pytest.fixture(scope="module")
def grid():
    return signals.time_grid(2 * T_S, TS)


@pytest.fixture(scope="module")
def clean(grid):
    """Noise-free responses to the two steps of the protocol."""
    return {a: TRUE.simulate(grid, signals.step_down(grid, a, t_s=T_S)) for a in (A1, A2)}


def passage(response):
    """First contact loss (t_c) and the following impact (t_b) after t_s."""
    ev = [e for e in response.events if e.time > T_S]
    assert ev[0].kind == "contact_lost" and ev[0].flank == "positive"
    assert ev[1].kind == "contact_made" and ev[1].flank == "negative"
    return ev[0].time, ev[1].time


def noisy_record(response, snr_m, snr_l, seed, name="rec"):
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    sm, sl = ss.spawn(2)
    return Record(
        response.t,
        response.torque,
        signals.add_noise(response.w_motor, snr_m, rng=sm),
        signals.add_noise(response.w_load, snr_l, rng=sl),
        name=name,
    )


# --- (a) relation (4), Appendix B ---------------------------------------------------


@pytest.mark.parametrize("a", [A1, A2])
def test_relation_4_exact_instants(clean, a):
    """theta = -0.5 int_{t_c}^{t_b} (w_M - w_L) dt (eq. 4, Appendix B) on the exact flow.

    The state at t_c comes from simulating t_s -> t_c on a grid ending exactly at the
    event; over [t_c, t_b] the drive is free (both inertias decay exponentially), so the
    integral has a closed form, and a fine-grid trapezoid (``pre_estimate``) must agree.
    """
    r = clean[a]
    t_c, t_b = passage(r)
    i_s = int(round(T_S / TS))
    x_s = r.states[i_s]
    tt = np.linspace(T_S, t_c, 2001)
    x_c = TRUE.simulate(tt, np.zeros(tt.size), initial_state=x_s).states[-1]
    assert x_c[2] == pytest.approx(THETA, rel=1e-9)
    a_m, a_l = P_TRUE["f_M"] / P_TRUE["J_M"], P_TRUE["f_L"] / P_TRUE["J_L"]
    span = t_b - t_c
    exact = x_c[0] * -np.expm1(-a_m * span) / a_m - x_c[1] * -np.expm1(-a_l * span) / a_l
    assert -0.5 * exact == pytest.approx(THETA, rel=1e-6)
    fine = np.linspace(t_c, t_b, 20001)
    rf = TRUE.simulate(fine, np.zeros(fine.size), initial_state=x_c)
    est = pre_estimate(rf.w_motor, rf.w_load, fine[1] - fine[0], 0, fine.size - 1)
    assert est == pytest.approx(THETA, rel=1e-6)
    # and not independent of the instants: a 5 ms shift of t_b breaks it
    shifted = pre_estimate(rf.w_motor, rf.w_load, fine[1] - fine[0], 0, fine.size - 1000)
    assert abs(shifted - THETA) > 1e-3 * THETA


# --- (b) commutation instants, eq. 9 ------------------------------------------------


@pytest.mark.parametrize("a", [A1, A2])
def test_commutation_instants_noiseless(clean, a):
    """Eq. 9 on noise-free data: t_b within 2 samples, t_c within 3 samples.

    t_c comes out ~2.4 samples early on the paper drive: F_1 of eq. 9 models the load
    speed as constant on [t_s, t_c], while the unloading shaft already slows the load
    there (the brief's 2-sample target is met for t_b only with the paper's eq. 9; see
    ``onset="unloading"`` below for t_c).
    """
    r = clean[a]
    t_c, t_b = passage(r)
    rec = Record(r.t, r.torque, r.w_motor, r.w_load)
    com = commutation_instants(rec, ALPHA)
    assert com.t_s == pytest.approx(T_S)
    assert abs(com.t_c - t_c) <= 3 * TS
    assert abs(com.t_b - t_b) <= 2 * TS
    # the windows derived from the data satisfy the paper's inequalities
    assert com.t_s < t_c < com.t_s + com.dt1 < t_b
    t_a = [e.time for e in r.events if e.time > t_b][0]
    assert com.t_s + com.dt2 < t_b < com.t_s + com.dt3 < t_a


@pytest.mark.parametrize("a", [A1, A2])
@pytest.mark.parametrize(("k_scale", "jm_scale"), [(1, 1), (0.3, 1), (3, 1), (1, 0.2), (1, 5)])
def test_unloading_onset_finds_t_c_within_two_samples(grid, a, k_scale, jm_scale):
    """``onset="unloading"``: the cubic fall into the free decay puts t_c within 2 samples.

    The paper's constant onset is 2.4 samples early on the paper drive and up to 5.4 on
    a 0.3x shaft (measured here too, so that the gain is shown, not assumed).
    """
    p = dict(P_TRUE, k_sh=P_TRUE["k_sh"] * k_scale, J_M=P_TRUE["J_M"] * jm_scale)
    r = bk.TwoMassDrive(**p, theta=THETA).simulate(grid, signals.step_down(grid, a, t_s=T_S))
    t_c, t_b = passage(r)
    rec = Record(r.t, r.torque, r.w_motor, r.w_load)
    alpha = p["f_L"] / p["J_L"]
    cubic = commutation_instants(rec, alpha, onset="unloading")
    assert abs(cubic.t_c - t_c) <= 2 * TS
    assert cubic.t_b == commutation_instants(rec, alpha).t_b  # F_2 is unchanged
    if (k_scale, jm_scale) in ((1, 1), (0.3, 1)):
        assert commutation_instants(rec, alpha).t_c < t_c - 2 * TS
    with pytest.raises(InputError, match="onset must be 'constant' or 'unloading', got 'cubic'"):
        commutation_instants(rec, alpha, onset="cubic")


def test_step_down_located_and_required(clean):
    r = clean[A1]
    rec = Record(r.t, r.torque, r.w_motor, r.w_load, name="exp.csv")
    i_s, t_s, before, after = find_step_down(rec)
    assert (i_s, before, after) == (int(round(T_S / TS)), A1, 0.0)
    up = Record(r.t, signals.step(r.t, A1, t_step=1.0), r.w_motor, r.w_load, name="up.csv")
    with pytest.raises(InputError, match=r"up\.csv: the torque has no step-down"):
        find_step_down(up)


def test_record_without_passage_is_refused(grid):
    """A step-down after which the speeds show no impact: an error naming the record."""
    torque = signals.step_down(grid, A1, t_s=T_S)
    # held, then a smooth decay without the rebound of an impact (constant speeds are
    # refused earlier, by every identifier)
    flat = np.where(grid < T_S, 15.7, 15.7 * np.exp(-np.clip(grid - T_S, 0.0, None)))
    rec = Record(grid, torque, flat, flat, name="flat.csv")
    with pytest.raises(InputError, match=r"^flat\.csv: .*no impact"):
        TwoStepIdentifier(PRIOR).fit(rec)


def test_fir_is_zero_phase_and_validated():
    t = np.arange(0, 10, TS)
    x = np.sin(2.0 * t)  # 2 rad/s, well inside the pass band
    y = fir_lowpass(x, 20.0, TS)
    mid = slice(2000, 8000)
    assert np.max(np.abs(y[mid] - x[mid])) < 0.01  # no delay, unit gain
    z = fir_lowpass(np.sin(300.0 * t), 20.0, TS)  # far in the stop band
    assert np.max(np.abs(z[mid])) < 0.01
    with pytest.raises(InputError, match="cutoff must be below the Nyquist"):
        fir_lowpass(x, 4000.0, TS)
    with pytest.raises(InputError, match="numtaps must be odd"):
        fir_lowpass(x, 20.0, TS, numtaps=10)


@pytest.mark.parametrize("cutoff", [30.0, 200.0])
def test_a_span_of_the_fir_output_is_the_whole_outputs_to_the_bit(cutoff):
    """``span=`` filters only the samples its outputs read: the same sums, so the same
    values, near both ends of the signal (their edge padding) and inside it."""
    x = np.cumsum(np.random.default_rng(4).standard_normal(20_001))
    whole = fir_lowpass(x, cutoff, TS)
    for span in [(0, 50), (3, 400), (10_000, 10_300), (10_001, 10_777), (19_900, 20_001),
                 (5, 20_000), (0, 20_001)]:
        np.testing.assert_array_equal(fir_lowpass(x, cutoff, TS, span=span),
                                      whole[span[0] : span[1]])
    for span, said in (((5, 5), r"span must satisfy 0 <= start < stop <= len\(x\) = 20001"),
                       ((0, 20_002), "span must satisfy"),
                       ((-1, 4), "span's start must be an integer >= 0, got -1"),
                       ((0.5, 4), "span's start must be an integer"),
                       (7, "span must be two sample indices")):
        with pytest.raises(InputError, match=said):
            fir_lowpass(x, cutoff, TS, span=span)


@pytest.mark.parametrize("numtaps", [3, 11, 661, 1651])
@pytest.mark.parametrize("cutoff", [0.003, 0.05, 0.5, 0.97])
def test_fir_taps_match_scipy_firwin(numtaps, cutoff):
    from scipy.signal import firwin

    from backlashkit.identify.commutation import firwin_hamming as _firwin_hamming

    np.testing.assert_allclose(_firwin_hamming(numtaps, cutoff), firwin(numtaps, cutoff),
                               rtol=1e-12, atol=1e-15)


# --- (c) the two estimators on the paper's protocol ---------------------------------


def protocol_run(grid, prior, seed, snr1):
    """(two-step estimator, regression estimator) on one noisy run of the protocol."""
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    s1, s2 = ss.spawn(2)
    r1 = TRUE.simulate(grid, signals.step_down(grid, A1, t_s=T_S))
    r2 = TRUE.simulate(grid, signals.step_down(grid, A2, t_s=T_S))
    rec1 = noisy_record(r1, *snr1, s1, "step1")
    rec2 = noisy_record(r2, 35.7, 35.6, s2, "step2")
    two = TwoStepIdentifier(prior).fit(rec1, final_records=rec2)
    reg = RegressionIdentifier(prior).fit(rec2)
    return two, reg


def test_two_step_exact_prior_clean_step1(grid):
    """Exact prior, step 1 at 60 dB: theta within 5 % (measured: -2.3 %).

    The pre-estimate is biased low by the FIR filters (the 50 rad/s filter smears the
    motor-speed dip of the passage): measured -11 %, like the paper's -6 .. -11 %.
    """
    two, _ = protocol_run(grid, PRIOR, 11, (60.0, 60.0))
    assert -0.15 < (two.theta_ini_ - THETA) / THETA < -0.05
    assert abs(two.theta_ - THETA) / THETA < 0.05


def test_two_step_final_step_is_the_least_squares_minimum(grid):
    """Exact prior, 35 dB step-2 record: W_1 has its minimum at theta*, so with an
    interval wide enough to hold it (n_theta = 0.3 around the -11 % pre-estimate) the
    final step lands on theta* (1 %); with the paper's n_theta = 0.1 it stops at the
    upper bound 1.1 theta_ini."""
    ss = np.random.SeedSequence(7)
    s1, s2 = ss.spawn(2)
    rec1 = noisy_record(TRUE.simulate(grid, signals.step_down(grid, A1, t_s=T_S)), 60, 60, s1)
    rec2 = noisy_record(TRUE.simulate(grid, signals.step_down(grid, A2, t_s=T_S)), 35.7, 35.6, s2)
    wide = TwoStepIdentifier(PRIOR, n_theta=0.3).fit(rec1, final_records=rec2)
    assert wide.bounds_[0] < THETA < wide.bounds_[1]
    assert wide.theta_ == pytest.approx(THETA, rel=0.01)
    narrow = TwoStepIdentifier(PRIOR).fit(rec1, final_records=rec2)
    assert narrow.theta_ini_ == pytest.approx(wide.theta_ini_)
    assert narrow.bounds_[1] < THETA
    assert narrow.theta_ == pytest.approx(narrow.bounds_[1], rel=1e-3)


def test_paper_snr_scatter_of_pre_estimate(grid):
    """At the paper's step-1 SNR (6.43 dB on w_L, NOTES definition) eq. 6 scatters far
    more than the paper's Table 1 (std 2.6e-3 rad): measured std ~1e-2 rad over 10 runs,
    even with an exact prior, and a run may be refused (eq. 6 not positive). Recorded
    here so a change of the method or of the SNR definition shows up."""
    seeds = np.random.SeedSequence(6430).spawn(10)
    ini, refused = [], 0
    r1 = TRUE.simulate(grid, signals.step_down(grid, A1, t_s=T_S))
    for s in seeds:
        rec = noisy_record(r1, 17.4, 6.43, s, "step1")
        try:
            ini.append(TwoStepIdentifier(PRIOR, n_grid=3).fit(rec).theta_ini_)
        except InputError as exc:  # eq. 6 <= 0 on a badly located passage: refused
            assert str(exc).startswith("step1: ")
            refused += 1
    ini = np.asarray(ini)
    assert refused <= 3 and np.all(ini > 0)
    assert np.std(ini, ddof=1) > 4e-3
    assert 0.3 * THETA < np.mean(ini) < 1.2 * THETA


def test_noisy_prior_two_step_beats_regression(grid):
    """Paper A's claim (Tables 1-2): with Err_p = 40 % the pre-estimate keeps the least
    squares out of the wrong minima the regression falls into. Step 1 at 60 dB (at the
    paper's 6.43 dB eq. 6 itself is the dominant error, see above); 10 seeded runs."""
    rng_seeds = np.random.SeedSequence(40).spawn(10)
    two_err, reg_err = [], []
    for s in rng_seeds:
        sp, sr = s.spawn(2)
        x = np.random.default_rng(sp).uniform(-1.0, 1.0, len(P_TRUE))
        prior = bk.TwoMassDrive(
            **{k: v * (1 - 0.4 * xi) for (k, v), xi in zip(P_TRUE.items(), x, strict=True)}
        )
        two, reg = protocol_run(grid, prior, sr, (60.0, 60.0))
        two_err.append(two.theta_ - THETA)
        reg_err.append(reg.theta_ - THETA)
    rms_two = float(np.sqrt(np.mean(np.square(two_err))))
    rms_reg = float(np.sqrt(np.mean(np.square(reg_err))))
    assert rms_two < 0.25 * THETA
    assert rms_two < rms_reg


def test_regression_exact_prior_finds_theta(clean):
    r = clean[A2]
    reg = RegressionIdentifier(PRIOR).fit((r.t, r.torque, r.w_motor, r.w_load))
    assert reg.theta_ == pytest.approx(THETA, rel=1e-3)
    assert reg.t_s_ == [pytest.approx(T_S)]


def test_parameters_validated(clean):
    r = clean[A1]
    rec = (r.t, r.torque, r.w_motor, r.w_load)
    with pytest.raises(InputError, match="n_theta must be < 1, got 1.5"):
        TwoStepIdentifier(PRIOR, n_theta=1.5).fit(rec)
    with pytest.raises(InputError, match="prior must be a TwoMassDrive"):
        TwoStepIdentifier({"J_M": 1}).fit(rec)
    with pytest.raises(InputError, match="records must hold at least one record"):
        RegressionIdentifier(PRIOR).fit([])
    with pytest.raises(InputError, match=r"records\[0\]: w_load must have one sample per t"):
        RegressionIdentifier(PRIOR).fit([(r.t, r.torque, r.w_motor, r.w_load[:-1])])


# --- (d) the CLI ------------------------------------------------------------------------


def cli(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def experiment_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("identify") / "exp.csv"
    code = main(["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.157",
                 "--hold", "40", "--snr-motor", "60", "--snr-load", "60", "--seed", "1",
                 "--out", str(path)])
    assert code == 0
    return path


def test_cli_two_step_json(experiment_csv, capsys, clean):
    code, out, err = cli(["identify", str(experiment_csv), "--drive", DRIVE_TOML, "--json",
                          "--method", "two-step"],
                         capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["method"] == "two-step"
    assert doc["std"] is None and doc["ci95"] is None
    assert abs(doc["theta"] - THETA) < 0.1 * THETA
    assert 0.8 * THETA < doc["theta_ini"] < THETA
    (rec,) = doc["records"]
    t_c, t_b = passage(clean[A1])
    assert rec["file"] == str(experiment_csv)
    # eq. 9 anchors F_1, F_2 on single noisy samples: even at 60 dB t_c moves by ms
    assert abs(rec["t_c"] - t_c) < 0.010 and abs(rec["t_b"] - t_b) < 0.005


def test_cli_regression_and_table(experiment_csv, capsys):
    code, out, err = cli(["identify", str(experiment_csv), "--drive", DRIVE_TOML,
                          "--method", "regression", "--json"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["method"] == "regression" and doc["theta_ini"] is None
    assert doc["records"][0]["t_c"] is None
    assert doc["theta"] == pytest.approx(THETA, rel=0.02)
    code, out, err = cli(["identify", str(experiment_csv), "--drive", DRIVE_TOML], capsys)
    assert code == 0
    assert "theta_ini" in out and "theta     =" in out and "exp.csv" in out
    # the per-file table holds the columns with a value: the joint method's one
    # pre-estimate for all files is the line under it, not a "-" in every row
    header, row = out.splitlines()[1:3]
    assert header.split() == ["file", "t_s", "(s)", "t_c", "(s)", "t_b", "(s)"], out
    assert len(row.split()) == 4 and "-" not in row.split()[1:], out
    assert out.splitlines()[3].startswith("theta_ini = "), out
    code, out, err = cli(["identify", str(experiment_csv), "--drive", DRIVE_TOML,
                          "--method", "regression"], capsys)
    assert code == 0
    header, row = out.splitlines()[1:3]  # no contact instants, no pre-estimate
    assert header.split() == ["file", "t_s", "(s)"] and len(row.split()) == 2, out


def _write(path, text):
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(
    "kind, pattern",
    [
        ("missing", r"no column 'w_load'"),
        ("flat", r"w_motor is constant"),  # the record checks come before the step-down's
        ("garbage", r"line 3, column 'torque': 'abc' is not a number"),
        ("nofile", r"file not found: .*absent\.csv \(one of the records\): check the path"),
    ],
)
def test_cli_bad_inputs(tmp_path, capsys, kind, pattern):
    t = np.arange(0.0, 2.0, TS)
    if kind == "missing":
        lines = ["t,torque,w_motor"] + [f"{float(x)!r},0.1,1.0" for x in t]
        path = _write(tmp_path / "m.csv", "\n".join(lines) + "\n")
    elif kind == "flat":
        lines = ["t,torque,w_motor,w_load"] + [f"{float(x)!r},0.1,1.0,1.0" for x in t]
        path = _write(tmp_path / "f.csv", "\n".join(lines) + "\n")
    elif kind == "garbage":
        text = "t,torque,w_motor,w_load\n0,1,1,1\n0.001,abc,1,1\n0.002,0,1,1\n"
        path = _write(tmp_path / "g.csv", text)
    else:
        path = str(tmp_path / "absent.csv")
    code, out, err = cli(["identify", path, "--drive", DRIVE_TOML, "--json"], capsys)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("backlashkit: error: ")
    assert "Traceback" not in err
    assert re.search(pattern, lines[0]), lines[0]


def test_cli_names_the_argument_of_a_missing_file(tmp_path, capsys, experiment_csv):
    """The missing file's message says which argument gave it, option or record."""
    absent = str(tmp_path / "absent.toml")
    for flag in (["--drive", absent], [f"--drive={absent}"]):
        code, out, err = cli(["identify", str(experiment_csv), *flag], capsys)
        assert code == 2 and out == ""
        assert err.strip() == (f"backlashkit: error: file not found: {absent} (given to "
                               "--drive): check the path")


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--method", "two-step", "--n-theta", "0"], "--n-theta must be > 0, got 0.0"),
        (["--method", "two-step", "--cutoff-motor", "-1"], "--cutoff-motor must be > 0"),
        (["--method", "two-step", "--cutoff-load", "5000"],
         "--cutoff-load must be below the Nyquist frequency pi/ts = 3141.59 rad/s of"),
        (["--prior-rel-std", "-1"], "--prior-rel-std must be >= 0"),
        (["--bootstrap", "1"], "--bootstrap must be an integer >= 2, got 1"),
        (["--bootstrap", "3", "--seed", "-1"], "--seed must be an integer >= 0"),
        (["--final-horizon", "nan"], "--final-horizon must be finite"),
    ],
)
def test_cli_errors_name_the_flag(experiment_csv, argv, message, capsys):
    # the library names its parameters (n_resamples); the CLI user typed a flag
    code, out, err = cli(["identify", str(experiment_csv), "--drive", DRIVE_TOML, *argv],
                         capsys)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err, err


def test_two_step_names_the_bad_cutoff(clean):
    rec = noisy_record(clean[A1], 40.0, 40.0, 0, name="e1")
    for kwargs, pattern in (({"cutoff_motor": 0.0}, "cutoff_motor must be > 0"),
                            ({"cutoff_load": 1e6}, "cutoff_load must be below the Nyquist "
                             r"frequency pi/ts = 3141\.59 rad/s of e1")):
        with pytest.raises(InputError, match=pattern):
            TwoStepIdentifier(PRIOR, **kwargs).fit(rec)


def test_cli_subprocess_no_traceback(tmp_path):
    bad = _write(tmp_path / "bad.csv", "\x00\x01 not a csv at all\n")
    proc = subprocess.run(
        [sys.executable, "-m", "backlashkit", "identify", bad, "--drive", DRIVE_TOML],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "Traceback" not in proc.stderr


def test_cli_unloading_onset(tmp_path, capsys, clean):
    """``--onset unloading`` on a noise-free record: t_c within 2 samples (paper: 2.4 early)."""
    path = tmp_path / "clean.csv"
    assert main(["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.157",
                 "--hold", "40", "--out", str(path)]) == 0
    capsys.readouterr()
    t_c = passage(clean[A1])[0]
    found = {}
    for onset in ("constant", "unloading"):
        code, out, err = cli(["identify", str(path), "--drive", DRIVE_TOML, "--json",
                              "--method", "two-step", "--onset", onset], capsys)
        assert code == 0, err
        doc = json.loads(out)
        assert doc["onset"] == onset
        found[onset] = doc["records"][0]["t_c"] - t_c
    assert abs(found["unloading"]) <= 2 * TS < abs(found["constant"])


def test_cli_final_records(experiment_csv, tmp_path, capsys):
    """Paper A's protocol from the CLI: pre-estimate on step 1, least squares on step 2."""
    step2 = tmp_path / "step2.csv"
    assert main(["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.942",
                 "--hold", "40", "--snr-motor", "35.7", "--snr-load", "35.6", "--seed", "2",
                 "--out", str(step2)]) == 0
    capsys.readouterr()
    code, out, err = cli(["identify", str(experiment_csv), "--final", str(step2), "--drive",
                          DRIVE_TOML, "--json", "--method", "two-step"], capsys)
    assert code == 0, err
    doc = json.loads(out)
    assert doc["final_records"] == [str(step2)]
    assert len(doc["records"]) == 1
    lo, hi = doc["search_interval"]
    assert lo == pytest.approx(0.9 * doc["theta_ini"])
    assert hi == pytest.approx(1.1 * doc["theta_ini"])
    assert lo <= doc["theta"] <= hi
    code, out, err = cli(["identify", str(experiment_csv), "--final", str(step2), "--drive",
                          DRIVE_TOML, "--method", "regression"], capsys)
    assert code == 2
    assert "--final only applies with --method two-step or joint (the default)" in err


def test_cli_reader_options_give_the_same_answer(experiment_csv, tmp_path, capsys):
    """A European export (';', decimal commas, rpm, no time column, other names) read
    with --delimiter/--decimal/--speed-unit/--sample-time/--columns gives the same fit."""
    import csv

    with open(experiment_csv) as fh:
        rows = list(csv.DictReader(fh))
    rpm = 60.0 / (2.0 * np.pi)
    eu = tmp_path / "export.csv"
    lines = ["Moment;n_mot;n_last"] + [
        ";".join(repr(x).replace(".", ",") for x in
                 (float(r["torque"]), float(r["w_motor"]) * rpm, float(r["w_load"]) * rpm))
        for r in rows
    ]
    eu.write_text("\n".join(lines) + "\n")
    base = ["identify", "--drive", DRIVE_TOML, "--method", "two-step", "--json"]
    code, out, err = cli([*base, str(experiment_csv)], capsys)
    assert code == 0, err
    ref = json.loads(out)
    code, out, err = cli([*base, str(eu), "--delimiter", ";", "--decimal", ",",
                          "--speed-unit", "rpm", "--sample-time", "0.001",
                          "--columns", "torque=Moment,w_motor=n_mot,w_load=n_last"], capsys)
    assert code == 0, err
    got = json.loads(out)
    assert got["theta"] == pytest.approx(ref["theta"], rel=1e-6)
    assert got["records"][0]["t_c"] == pytest.approx(ref["records"][0]["t_c"], abs=1e-9)
    # a bad mapping is one line naming the option
    code, out, err = cli([*base, str(eu), "--columns", "torque"], capsys)
    assert code == 2 and "--columns must be OURS=THEIRS" in err and err.count("\n") == 1


def test_cli_reads_npz(clean, tmp_path, capsys):
    r = clean[A1]
    path = tmp_path / "exp.npz"
    np.savez(path, t=r.t, torque=r.torque, w_motor=r.w_motor, w_load=r.w_load)
    code, out, err = cli(["identify", str(path), "--drive", DRIVE_TOML, "--method",
                          "regression", "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["theta"] == pytest.approx(THETA, rel=0.02)


@pytest.mark.parametrize("a", [1.0, 0.9999, 0.5, 1e-3])
def test_first_order_matches_its_recurrence(a):
    """The held speeds' rigid-body response, vectorised in blocks (several blocks at
    the fast decays), against the recurrence it replaces, on a random input."""
    from backlashkit.identify.step import first_order

    x = np.random.default_rng(7).normal(size=5000)
    want = np.zeros(x.size + 1)
    for k in range(1, want.size):
        want[k] = a * want[k - 1] + x[k - 1]
    np.testing.assert_allclose(first_order(x, a), want, rtol=1e-10, atol=1e-12)
