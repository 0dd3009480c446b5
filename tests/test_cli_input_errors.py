"""Bad input found by a QA pass over the command line: each case ends in one line on
stderr and exit status 2, never a traceback and never a number that means nothing.

The experiment is the short one of ``tests/test_identify_joint.py`` (paper A's drive,
0.942 N m from rest for 2 s, then 0; 4 s at Ts = 1 ms, 30 dB on both speeds).
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from backlashkit import signals
from backlashkit.cli import main
from backlashkit.errors import InputError
from backlashkit.identify import Record
from backlashkit.identify._lm import LMState as _LMState
from backlashkit.identify._lm import lm as _lm
from backlashkit.identify.joint import JointIdentifier
from backlashkit.io import read_drive_toml, write_csv

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DRIVE_TOML = str(EXAMPLES / "paper_drive.toml")


@pytest.fixture(scope="module")
def exp_csv(short_csv):
    return short_csv  # tests/conftest.py


@pytest.fixture(scope="module")
def exp(exp_csv):
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    return Record(t, u, w_m, w_l, name="exp.csv")


@pytest.fixture(scope="module")
def steady_csv(tmp_path_factory):
    """The short experiment as paper A's methods need it: started at the drive's steady
    state under the held 0.942 N m (from rest, 2 s are too brief for their model's
    steady start, and they refuse it), then 0 at 2 s; 4 s at Ts = 1 ms, 30 dB on both
    speeds."""
    drive = read_drive_toml(DRIVE_TOML)
    t = signals.time_grid(4.0, 1e-3)
    u = signals.step_down(t, 0.942, t_s=2.0)
    res = drive.simulate(t, u, initial_state=drive.steady_state(0.942))
    rng = np.random.default_rng(1)
    path = tmp_path_factory.mktemp("steady") / "exp.csv"
    write_csv(path, {"t": t, "torque": u,
                     "w_motor": signals.add_noise(res.w_motor, 30.0, rng=rng),
                     "w_load": signals.add_noise(res.w_load, 30.0, rng=rng)})
    return path


@pytest.fixture(scope="module")
def steady(steady_csv):
    t, u, w_m, w_l = np.loadtxt(steady_csv, delimiter=",", skiprows=1,
                                usecols=(0, 1, 2, 3)).T
    return Record(t, u, w_m, w_l, name="exp.csv")


def _one_line_error(capsys, argv) -> str:
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert err.count("\n") == 1 and err.startswith("backlashkit: error: "), err
    assert "Traceback" not in err
    return err


def test_a_record_given_twice_is_refused(exp_csv, capsys):
    err = _one_line_error(capsys, ["identify", str(exp_csv), str(exp_csv), "--drive",
                                   DRIVE_TOML])
    assert "exp.csv holds the same data as" in err and "give every record once" in err
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--final", str(exp_csv),
                                   "--drive", DRIVE_TOML])
    assert "holds the same data" in err


def test_a_constant_speed_is_refused(exp):
    flat = Record(exp.t, exp.torque, exp.w_motor, np.full(exp.t.size, 3.0), name="flat.csv")
    prior = read_drive_toml(DRIVE_TOML, require_theta=False).with_theta(None)
    with pytest.raises(InputError, match=r"^flat\.csv: w_load is constant \(3 rad/s\)"):
        JointIdentifier(prior).fit(flat)


def test_cli_refuses_a_constant_speed_for_every_method(exp_csv, tmp_path, capsys):
    t, u, w_m, _ = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "flat.csv"
    write_csv(path, {"t": t, "torque": u, "w_motor": w_m, "w_load": 0 * t + 3})
    for method in ("joint", "two-step", "regression"):
        err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML,
                                       "--method", method])
        assert "flat.csv: w_load is constant" in err


def test_speeds_the_model_cannot_explain_are_refused(exp):
    """Speeds that do not respond to the torque (noise around 0): no drive explains them
    better than their mean, and the fit says so instead of returning a theta."""
    rng = np.random.default_rng(0)
    noise = Record(exp.t, exp.torque, rng.normal(0, 1, exp.t.size),
                   rng.normal(0, 1, exp.t.size), name="noise.csv")
    prior = read_drive_toml(DRIVE_TOML, require_theta=False).with_theta(None)
    with pytest.raises(InputError, match=r"^noise\.csv: the identified model does not "
                       r"explain w_(motor|load) \(fit -?[\d.e+-]+ %, worse than its mean\)"):
        JointIdentifier(prior).fit(noise)


def test_final_horizon_must_span_samples(exp_csv, capsys):
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--final-horizon", "1e-6"])
    assert "--final-horizon must span at least 10 samples (0.01 s at Ts = 0.001 s)" in err


def test_a_prior_out_of_the_models_reach_is_one_line(exp_csv, tmp_path, capsys):
    text = Path(DRIVE_TOML).read_text()
    prior = tmp_path / "tiny.toml"
    prior.write_text(text.replace("J_M = 4.88e-3", "J_M = 1e-300"))
    assert "1e-300" in prior.read_text()
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", str(prior)])
    assert "exp.csv: the sample time 0.001 s cannot resolve the drive's ringing" in err
    # what the compiled core refuses reaches the user as one line too
    err = _one_line_error(capsys, ["simulate", DRIVE_TOML, "--experiment", "step-down",
                                   "--amplitude", "1e308", "--hold", "1",
                                   "--out", str(tmp_path / "big.csv")])
    assert "cannot compute with this input: the simulation diverged" in err


def test_report_never_writes_into_a_directory_that_is_not_empty(exp_csv, tmp_path, capsys):
    mine = tmp_path / "figs"
    mine.mkdir()
    (mine / "fit.png").write_text("my own figure")
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--method", "regression", "--report", str(mine)])
    assert "is not empty; pass --force" in err
    assert (mine / "fit.png").read_text() == "my own figure"


def test_control_outputs_must_differ_and_parents_must_be_directories(tmp_path, capsys):
    scenario = str(EXAMPLES / "tao1995.toml")
    same = str(tmp_path / "same.png")
    err = _one_line_error(capsys, ["control", scenario, "--trace", same, "--plot", same])
    assert "--plot and --trace must be different files" in err
    afile = tmp_path / "afile"
    afile.write_text("x")
    err = _one_line_error(capsys, ["control", scenario, "--trace", str(afile / "t.csv")])
    assert f"{afile} is a file, not a directory" in err
    err = _one_line_error(capsys, ["control", scenario, "--trace", str(tmp_path)])
    assert "is a directory; give a file name" in err
    bad = tmp_path / "bad.npz"
    bad.write_text("garbage")
    err = _one_line_error(capsys, ["identify", str(bad), "--drive", DRIVE_TOML])
    assert "bad.npz: not a NumPy .npz archive (no zip file)" in err


def test_lm_stops_where_the_model_cannot_be_simulated():
    """A start the model cannot simulate (cost inf) returns at once; a Jacobian that
    cannot be computed ends the iteration instead of raising."""
    calls = []

    def jac_never(z, r):
        calls.append(z)
        raise AssertionError("no Jacobian at an infinite cost")

    st = _lm(lambda z: np.full(1, np.inf), jac_never, np.zeros(2), max_iter=5)
    assert isinstance(st, _LMState) and st.done and math.isinf(st.cost) and not calls

    def jac_fails(z, r):
        raise ValueError("sample time too long for the drive's fastest mode")

    st = _lm(lambda z: z - 1.0, jac_fails, np.zeros(2), max_iter=5)
    assert st.done and st.cost == pytest.approx(2.0) and np.all(st.z == 0.0)


def test_snr_out_of_float_range_is_refused(tmp_path, capsys):
    err = _one_line_error(capsys, ["simulate", DRIVE_TOML, "--experiment", "step-down",
                                   "--amplitude", "0.157", "--hold", "1", "--snr-motor", "1e6",
                                   "--seed", "1", "--out", str(tmp_path / "s.csv")])
    assert "--snr-motor" in err and "between -300 and 300 dB" in err


def test_columns_mapped_twice_are_refused(exp_csv, capsys):
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--columns", "w_motor=w_load"])
    assert "'w_motor' and 'w_load' both read the file's column 'w_load'" in err
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--columns", "t=t,t=x"])
    assert "--columns maps 't' twice" in err


def test_uncertainty_of_theta_is_refused(exp_csv, tmp_path, capsys):
    prior = tmp_path / "prior.toml"
    prior.write_text(Path(DRIVE_TOML).read_text() + "\n[uncertainty]\ntheta = 0.1\n")
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", str(prior)])
    assert "[uncertainty] theta: the backlash is what identify estimates" in err


def test_an_empty_uncertainty_table_is_refused(exp_csv, tmp_path, capsys):
    """Read as no table it estimated every parameter, while Python's ``{}`` held them
    all: both refuse it now, naming the two meanings."""
    prior = tmp_path / "prior.toml"
    prior.write_text(Path(DRIVE_TOML).read_text() + "\n[uncertainty]\n")
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", str(prior)])
    assert f"{prior}: [uncertainty] is empty; list the parameters' relative stds" in err
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    for rel, match in (({}, r"^prior_rel_std is an empty dict: give 0 to hold"),
                       ({"theta": 0.1}, r"^prior_rel_std\['theta'\]: the backlash is what")):
        with pytest.raises(InputError, match=match):
            JointIdentifier(read_drive_toml(DRIVE_TOML).with_theta(None),
                            prior_rel_std=rel).fit(Record(t, u, w_m, w_l))


@pytest.mark.parametrize("method", ["two-step", "regression"])
def test_paper_a_methods_say_they_do_not_read_the_uncertainty_table(steady_csv, tmp_path,
                                                                    capsys, method):
    prior = tmp_path / "prior.toml"
    prior.write_text(Path(DRIVE_TOML).read_text() + "\n[uncertainty]\nk_sh = 0.1\n")
    assert main(["identify", str(steady_csv), "--drive", str(prior), "--method", method,
                 "--json"]) == 0
    notes = " ".join(json.loads(capsys.readouterr().out)["notes"])
    assert (f"the [uncertainty] table of {prior} is read by --method joint only: --method "
            f"{method} holds the linear parameters at the prior's values") in notes


@pytest.mark.parametrize("method", ["two-step", "regression"])
def test_paper_a_methods_print_their_friction_model(steady_csv, capsys, method):
    """The text output says which friction model paper A's methods fitted, as --json
    does: viscous, or the Coulomb torques it found."""
    assert main(["identify", str(steady_csv), "--drive", DRIVE_TOML, "--method", method]) == 0
    assert "friction  = viscous (no Coulomb torques)" in capsys.readouterr().out
    assert main(["identify", str(steady_csv), "--drive", DRIVE_TOML, "--method", method,
                 "--friction", "coulomb", "--json"]) == 0
    extra = json.loads(capsys.readouterr().out)
    assert main(["identify", str(steady_csv), "--drive", DRIVE_TOML, "--method", method,
                 "--friction", "coulomb"]) == 0
    assert (f"friction  = coulomb: fc_M = {extra['fc_M']:.4g} N m, fc_L = "
            f"{extra['fc_L']:.4g} N m") in capsys.readouterr().out


def test_time_in_ms_is_refused_for_every_method(exp_csv, tmp_path, capsys):
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "ms.csv"
    write_csv(path, {"t": 1000 * t, "torque": u, "w_motor": w_m, "w_load": w_l})
    for method in ("joint", "two-step", "regression"):
        err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML,
                                       "--method", method])
        assert "ms.csv: the sample time 1 s cannot resolve the drive's ringing" in err
        assert "a time column in ms reads as s" in err


def test_speeds_in_rpm_read_as_rad_per_s_are_refused(exp_csv, tmp_path, capsys):
    """The held speeds are 9.5 times the prior's, which names rpm: refused before the
    fit; with --allow-far-from-prior the fit moves J_M x0.1 and answers with the note
    beyond 3x. Swapped speed columns hold the prior's speeds and move J_M and k_sh about
    x6: refused after the fit."""
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "rpm.csv"
    rpm = 60 / (2 * np.pi)
    write_csv(path, {"t": t, "torque": u, "w_motor": rpm * w_m, "w_load": rpm * w_l})
    err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML,
                                   "--interval", "fisher"])
    # the record whose held speeds are off is named, and the flag that reads rpm
    assert "rpm.csv: under the torque held before the step-down" in err, err
    assert "the speeds are 9.5" in err and "the fit moved" not in err, err
    assert "rpm read as rad/s? then give --speed-unit rpm" in err
    assert "pass --allow-far-from-prior" in err
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--allow-far-from-prior"]) == 0
    out, _ = capsys.readouterr()
    assert "note: the fit moved J_M x0.1" in out and "rpm read as rad/s?" in out
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--interval", "fisher", "--columns",
                                   "w_motor=w_load,w_load=w_motor"])
    assert "the fit moved" in err and "w_motor and w_load swapped?" in err


@pytest.mark.parametrize("method", ["two-step", "regression"])
def test_held_speed_far_from_the_priors_steady_state_is_refused(exp_csv, steady_csv, tmp_path,
                                                               capsys, method):
    """The paper's methods simulate the prior from the held speed: in rpm it is 9.5 times
    the prior's (refused; --allow-far-from-prior answers with a note); a
    speed scaled by 1e-300 is refused too, instead of a theta of 1e-302 rad."""
    t, u, w_m, w_l = np.loadtxt(steady_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    for name, factor in (("rpm", 60 / (2 * np.pi)), ("tiny", 1e-300)):
        path = tmp_path / f"{name}.csv"
        write_csv(path, {"t": t, "torque": u, "w_motor": factor * w_m,
                         "w_load": factor * w_l})
        err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML,
                                       "--method", method])
        assert f"{name}.csv: under the torque held before the step-down" in err
        gain = float(re.search(r"the speeds are (\S+) times the prior's", err).group(1))
        assert gain == pytest.approx(factor, rel=0.01) and "rpm read as rad/s?" in err
        assert "use --method joint" in err and "--allow-far-from-prior" in err
    assert main(["identify", str(tmp_path / "rpm.csv"), "--drive", DRIVE_TOML, "--method",
                 method, "--allow-far-from-prior", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert any("are 9.5" in n and "times the prior's" in n for n in out["notes"])
    assert out["records"][0]["held_speed_gain"] == pytest.approx(60 / (2 * np.pi), rel=0.01)
    assert main(["identify", str(steady_csv), "--drive", DRIVE_TOML, "--method", method,
                 "--json"]) == 0  # the right units: no note of it
    out = json.loads(capsys.readouterr().out)
    assert not any("times the prior's" in n for n in out["notes"])
    assert main(["identify", str(exp_csv), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--json"]) == 0
    out, _ = capsys.readouterr()
    assert '"far_from_prior": []' in out
    held = json.loads(out)["records"][0]["held_noise_lag1"]  # a 2 s hold is too brief
    assert held == [None, None]  # to see the noise on (the ringing decays over 7 s)


def test_the_library_warns_of_a_prior_mismatch(exp, steady):
    """The library refuses what ``identify`` refuses: speeds in rpm are 9.55 times the
    prior's held speed (beyond REFUSE_FROM_PRIOR); with ``allow_far_from_prior=True``
    it answers with a PriorMismatchWarning and says so in ``held_speed_gains_`` (on the
    record started steady, as paper A's methods need). The joint fit refuses the same
    held speeds before it fits; with ``allow_far_from_prior=True`` it moves J_M x0.1
    and warns (``far_from_prior_``)."""
    from scipy.signal import lfilter

    from backlashkit import PriorMismatchWarning, RegressionIdentifier, TwoStepIdentifier
    from backlashkit.identify import find_step_down, held_speed_gain
    from backlashkit.identify.intervals import FisherInterval

    prior = read_drive_toml(DRIVE_TOML, require_theta=False).with_theta(None)
    rpm = 60 / (2 * np.pi)
    bad = Record(exp.t, exp.torque, rpm * exp.w_motor, rpm * exp.w_load, name="rpm.csv")
    gain = held_speed_gain(exp, prior)
    # the same least squares with the rigid body's response from scipy's filter
    i_s = find_step_down(exp)[0]
    f, j = prior.f_M + prior.f_L, prior.J_M + prior.J_L
    a = math.exp(-f * exp.ts / j)
    rest = lfilter([0.0, (1 - a) / f], [1.0, -a], exp.torque[:i_s])
    v = (prior.J_M * exp.w_motor[:i_s] + prior.J_L * exp.w_load[:i_s]) / j
    basis = np.column_stack([rest, a ** np.arange(i_s)])
    assert gain == pytest.approx(np.linalg.lstsq(basis, v, rcond=None)[0][0], rel=1e-9)
    assert gain == pytest.approx(1.0, abs=0.02)  # paper_drive.toml is the record's drive
    assert held_speed_gain(bad, prior) == pytest.approx(rpm * gain, rel=1e-9)
    bad_steady = Record(steady.t, steady.torque, rpm * steady.w_motor, rpm * steady.w_load,
                        name="rpm.csv")
    steady_gain = held_speed_gain(steady, prior)
    for cls in (TwoStepIdentifier, RegressionIdentifier):
        with pytest.raises(InputError, match=r"^rpm\.csv: .* 9\.\d+ times the prior's.*"
                                             r"use JointIdentifier .* allow_far_from_prior=True$"):
            cls(prior).fit(bad_steady)
        with pytest.warns(PriorMismatchWarning, match=r"^rpm\.csv: .* 9\.\d+ times the "
                                                      r"prior's.*rpm read as rad/s\?"):
            est = cls(prior, allow_far_from_prior=True).fit(bad_steady)
        assert est.held_speed_gains_ == [pytest.approx(rpm * steady_gain, rel=1e-9)]
        with warnings.catch_warnings():
            warnings.simplefilter("error", PriorMismatchWarning)
            assert cls(prior).fit(steady).held_speed_gains_ == [
                pytest.approx(steady_gain, rel=1e-9)]
    joint = JointIdentifier(prior, interval=FisherInterval())
    with pytest.raises(InputError, match=r"^rpm\.csv: under the torque held .* 9\.5\d* "
                                         r"times the prior's.*"
                                         r"speed_unit='rpm' to read_records.*"
                                         r"allow_far_from_prior=True$"):
        joint.fit(bad)
    assert not hasattr(joint, "theta_")  # refused before it holds an answer
    with pytest.warns(PriorMismatchWarning, match=r"the fit moved J_M x0\.1"):
        est = JointIdentifier(prior, interval=FisherInterval(),
                              allow_far_from_prior=True).fit(bad)
    assert "J_M" in est.far_from_prior_
    # a tiny torque (units) is still answered, the same record as records and as
    # final_records warns once; bad arguments are named, a too-short hold gives NaN
    tiny = Record(exp.t, 1e-15 * exp.torque, exp.w_motor, exp.w_load)
    assert held_speed_gain(tiny, prior) == pytest.approx(1e15 * gain, rel=1e-6)
    with pytest.warns(PriorMismatchWarning) as caught:
        TwoStepIdentifier(prior, allow_far_from_prior=True).fit([bad_steady],
                                                                final_records=[bad_steady])
    assert len([w for w in caught if w.category is PriorMismatchWarning]) == 1
    with pytest.raises(InputError, match=r"needs f_M \+ f_L > 0"):
        held_speed_gain(exp, prior.__class__(**{**prior.__dict__, "f_M": 0.0, "f_L": 0.0}))
    with pytest.raises(InputError, match="record must be a Record, got str"):
        held_speed_gain("exp.csv", prior)
    early = Record(exp.t, np.where(np.arange(exp.t.size) < 2, 0.942, 0.0), exp.w_motor,
                   exp.w_load)
    assert math.isnan(held_speed_gain(early, prior))


def test_what_the_core_cannot_simulate_names_the_record(exp_csv, steady_csv, tmp_path,
                                                         capsys):
    """A torque of 1e300 N m makes the joint fit's drive chatter, speeds of 1e300 rad/s
    the two-step method's prior (started at that held speed): the compiled core's
    refusal comes with the file's name, on one line (it said only "cannot compute
    with this input" before)."""
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    write_csv(tmp_path / "torque.csv", {"t": t, "torque": 1e300 * u, "w_motor": w_m,
                                        "w_load": w_l})
    t, u, w_m, w_l = np.loadtxt(steady_csv, delimiter=",", skiprows=1,
                                usecols=(0, 1, 2, 3)).T
    write_csv(tmp_path / "speeds.csv", {"t": t, "torque": u, "w_motor": 1e300 * w_m,
                                        "w_load": 1e300 * w_l})
    err = _one_line_error(capsys, ["identify", str(tmp_path / "torque.csv"), "--drive",
                                   DRIVE_TOML])
    assert "torque.csv: cannot simulate the drive on this record: contact chatter" in err
    err = _one_line_error(capsys, ["identify", str(tmp_path / "speeds.csv"), "--drive",
                                   DRIVE_TOML, "--method", "two-step",
                                   "--allow-far-from-prior"])
    assert "speeds.csv: cannot simulate the prior on this record: contact chatter" in err


def test_two_step_at_the_edge_of_its_search_is_noted(steady_csv, capsys):
    """On this short 0.942 N m record alone (paper A uses it for step 2 only) the eq. 6
    pre-estimate is off and the least squares ends at an edge of its window."""
    assert main(["identify", str(steady_csv), "--drive", DRIVE_TOML, "--method", "two-step"]) == 0
    out, _ = capsys.readouterr()
    assert re.search(r"note: theta is at the (lower|upper) end of the search interval: the "
                     r"cost's minimum may lie beyond it \(widen --n-theta\)", out), out


@pytest.mark.parametrize("method", ["two-step", "regression"])
def test_a_drive_still_speeding_up_is_refused_by_paper_a_methods(exp_csv, capsys, method):
    """Paper A's methods start their model at a steady state under the held torque. On
    the short record from rest (2 s held, where the prior's time constant is 7.3 s)
    76 % of the held torque still accelerates the drive: they refuse it, naming the
    record, the share and what to do."""
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--method", method])
    assert ("exp.csv: the drive is still speeding up at the step-down at t = 2 s (76 % of "
            "the held torque still accelerates the prior's rigid body)") in err
    assert "(J_M + J_L) / (f_M + f_L) = 7.29 s" in err and "use --method joint" in err


def test_the_unsteady_share_against_its_closed_form_and_paper_a_protocol():
    """From rest under a torque held ``T`` seconds the share still accelerating the
    drive is the rigid body's ``exp(-F T / J)`` (its closed form; the shaft's ringing,
    over after about a second, keeps the two speeds apart only at first). Paper A's
    protocol records with priors drawn 50 % off (its tables go to 40 %) stay below
    half of :data:`HELD_UNSTEADY` (``pytest -s`` prints their largest share)."""
    from backlashkit.identify import held_unsteady_share
    from backlashkit.identify.step import HELD_UNSTEADY
    from backlashkit.papers.ravanbod2002 import protocol_records

    drive = read_drive_toml(DRIVE_TOML)
    prior = drive.with_theta(None)
    rate = (drive.f_M + drive.f_L) / (drive.J_M + drive.J_L)
    for hold in (2.0, 10.0, 40.0):
        t = signals.time_grid(hold + 2.0, 1e-3)
        u = signals.step_down(t, 0.942, t_s=hold)
        res = drive.simulate(t, u)
        rec = Record(t, u, res.w_motor, res.w_load, name="clean.csv")
        assert held_unsteady_share(rec, prior) == pytest.approx(math.exp(-rate * hold),
                                                                rel=0.02, abs=1e-3)
    shares = []
    for seq in np.random.SeedSequence(2002).spawn(100):
        rec1, rec2, drawn = protocol_records(0.5, seq)
        shares += [held_unsteady_share(rec1, drawn), held_unsteady_share(rec2, drawn)]
    print(f"paper A's protocol, priors 50 % off, 100 draws: largest share {max(shares):.3f}")
    assert max(shares) < HELD_UNSTEADY / 2


def test_a_zero_friction_the_fit_would_estimate_is_refused(exp, exp_csv, tmp_path, capsys):
    """A prior friction of 0 (often written for "unknown") cannot be estimated on the
    fit's log scale: it used to stay at 0 unsaid. The fit refuses it, in the library's
    and the command line's words, and names both remedies; relative stds of the others
    alone hold it at 0."""
    from backlashkit.identify.joint import check_estimated_nonzero

    text = Path(DRIVE_TOML).read_text()
    prior = tmp_path / "fsh0.toml"
    prior.write_text(re.sub(r"(?m)^f_sh = \S+", "f_sh = 0.0", text))
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", str(prior)])
    assert ("the prior's f_sh is 0, but the fit estimates it, on a log scale from the "
            f"prior's value, so it would stay at 0: give a first guess > 0 (f_sh in the "
            f"[drive] table of {prior}; its order of magnitude is enough), or hold it at 0 "
            "with a relative std for each other linear parameter alone (an [uncertainty] "
            f"table in {prior} that lists the others and not f_sh, without "
            "--prior-rel-std)") in err
    drive = read_drive_toml(str(prior), require_theta=False).with_theta(None)
    with pytest.raises(InputError, match=r"TwoMassDrive\(f_sh=\.\.\.\).*"
                                         r"prior_rel_std=\{\.\.\.\} without 'f_sh'"):
        JointIdentifier(drive).fit(exp)
    with pytest.raises(InputError, match="the prior's f_sh is 0"):
        JointIdentifier(drive, prior_rel_std=0.2).fit(exp)
    others = {n: 0.2 for n in ("J_M", "J_L", "k_sh", "f_M", "f_L")}
    check_estimated_nonzero(drive, others)  # held at 0: nothing to refuse


def test_a_regression_at_zero_says_so(steady, steady_csv, tmp_path, capsys):
    """With a prior whose shaft is five times too soft, the regression's criterion is
    smallest at theta = 0 on this record: the library says so (not that a minimum may
    lie below 0) and names the prior, and the command line prints the library's words
    as its note."""
    from backlashkit.errors import SearchEdgeWarning
    from backlashkit.identify.two_step import RegressionIdentifier

    said = ("theta is 0, the lower end of the search interval: the criterion is smallest "
            "without backlash on these records (check the prior's linear parameters")
    drive = read_drive_toml(DRIVE_TOML, require_theta=False)
    soft = drive.__class__(**{**drive.__dict__, "k_sh": drive.k_sh / 5})
    with pytest.warns(SearchEdgeWarning, match=re.escape(said)):
        fit = RegressionIdentifier(soft).fit(steady)
    assert fit.theta_ == 0.0 and fit.search_edges_ == ["lower"]
    prior = tmp_path / "soft.toml"
    prior.write_text(Path(DRIVE_TOML).read_text().replace(f"k_sh = {drive.k_sh!r}",
                                                          f"k_sh = {drive.k_sh / 5!r}"))
    assert prior.read_text() != Path(DRIVE_TOML).read_text()
    assert main(["identify", str(steady_csv), "--drive", str(prior), "--method",
                 "regression"]) == 0
    out, _ = capsys.readouterr()
    assert f"note: {said}" in out and "beyond it" not in out, out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seed", "3"], "--seed only applies with --bootstrap"),
        (["--jobs", "2"], "--jobs only applies with --bootstrap"),
        (["--jobs", "0", "--bootstrap", "3"], "jobs must be an integer >= 1"),
        (["--n-theta", "0.2"], "--n-theta only applies with --method two-step"),
        (["--cutoff-load", "10", "--method", "regression"],
         "--cutoff-load only applies with --method two-step"),
        (["--onset", "unloading"], "--onset only applies with --method two-step"),
        (["--prior-rel-std", "0.1", "--method", "two-step"],
         "--prior-rel-std only applies with --method joint"),
    ],
)
def test_options_of_another_method_are_refused(exp_csv, capsys, argv, message):
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML, *argv])
    assert message in err


def test_records_ending_at_the_step_down_are_refused(exp_csv, tmp_path, capsys):
    """The torque of the file steps down 5 samples before its end (while its speeds
    react 2 s earlier: a torque column from another run): no passage through the
    backlash can follow; refused for every method, before any fit (the fit used to
    answer, with a note that its model never lost contact)."""
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "late.csv"
    write_csv(path, {"t": t, "torque": np.where(np.arange(t.size) < t.size - 5, 0.942, 0.0),
                     "w_motor": w_m, "w_load": w_l})
    for method in ("joint", "two-step", "regression"):
        err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML,
                                       "--method", method])
        assert re.search(r"late\.csv: the record ends 0\.004 s after the step-down at "
                         r"t = 3\.996 s: record at least 0\.096 s after it \(two periods of "
                         r"the prior's ringing\)", err), err


# --- the second QA pass ---------------------------------------------------------------


def test_unix_time_stamps_are_uniform_within_their_rounding(exp_csv, tmp_path, capsys):
    """Time stamps of 1.7e9 s are stored to 2.4e-7 s in float64: the steps of a file
    written uniformly to the microsecond differ by that much, which is no non-uniform
    sampling; the answer is the one of the same file with t from 0."""
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "epoch.csv"
    lines = ["t,torque,w_motor,w_load"] + [f"{1.7e9 + a:.6f},{b:.17g},{c:.17g},{d:.17g}"
                                          for a, b, c, d in zip(t, u, w_m, w_l, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    runs = []
    for f in (exp_csv, path):
        assert main(["identify", str(f), "--drive", DRIVE_TOML, "--interval", "fisher",
                     "--json"]) == 0
        runs.append(json.loads(capsys.readouterr().out))
    assert runs[1]["records"][0]["t_s"] == pytest.approx(1.7e9 + 2.0)
    assert runs[1]["theta"] == pytest.approx(runs[0]["theta"], rel=1e-4)


def test_outputs_the_system_refuses_are_refused_before_computing(exp_csv, tmp_path, capsys):
    if not Path("/proc/self").is_dir():
        pytest.skip("needs /proc (Linux)")
    for argv, flag in (
        (["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.157",
          "--hold", "1", "--out", "/proc/x.csv"], "--out"),
        (["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.157",
          "--hold", "1", "--out", str(tmp_path / "ok.csv"), "--plot", "/proc/p.png"], "--plot"),
        (["control", str(EXAMPLES / "tao1995.toml"), "--trace", "/proc/x.csv"], "--trace"),
        (["reproduce", "ravanbod2002", "--runs", "2", "--json-out", "/proc/x.json"],
         "--json-out"),
        (["identify", str(exp_csv), "--drive", DRIVE_TOML, "--report", "/proc/rep"],
         "the report into"),
    ):
        err = _one_line_error(capsys, argv)
        assert f"cannot write {flag} /proc/" in err, err
    assert not (tmp_path / "ok.csv").exists()  # --out is not written when --plot cannot be


def test_parameters_held_by_the_uncertainty_table_are_noted(exp_csv, tmp_path, capsys):
    drive = tmp_path / "prior.toml"
    drive.write_text(Path(DRIVE_TOML).read_text().replace("theta", "# theta")
                     + "\n[uncertainty]\nJ_L = 0.1\n")
    assert main(["identify", str(exp_csv), "--drive", str(drive), "--interval", "fisher",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["estimated"] == ["theta", "J_L"]
    assert list(doc["prior_pull"]) == ["J_L"]  # the right prior: under its limit
    corr = np.array(doc["correlation"])
    assert corr.shape == (2, 2) and np.allclose(np.diag(corr), 1.0)
    assert corr[0, 1] == pytest.approx(corr[1, 0]) and abs(corr[0, 1]) < 1
    assert abs(doc["prior_pull"]["J_L"]) < 3.29
    assert ("J_M, k_sh, f_M, f_L, f_sh held at the prior's values: [uncertainty] lists J_L "
            "only") in " ".join(doc["notes"])


def test_report_of_a_record_ending_soon_after_the_step_down(exp_csv, tmp_path, capsys):
    """The joint fit needs two ringing periods after the step-down; its report shows
    what was recorded (it used to fail on the two-step method's 1 s window)."""
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    keep = t <= 2.3  # the step-down is at 2 s
    path = tmp_path / "soon.csv"
    write_csv(path, {"t": t[keep], "torque": u[keep], "w_motor": w_m[keep],
                     "w_load": w_l[keep]})
    rep = tmp_path / "rep"
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--report", str(rep)]) == 0, capsys.readouterr().err
    assert (rep / "index.html").is_file()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.157",
          "--level-after", "0.3", "--hold", "1", "--out", "{tmp}/x.csv"],
         "the amplitude (0.157 N m) must be above the level after (0.3 N m)"),
        (["identify", "-", "--drive", DRIVE_TOML], "identify reads files, not the standard input"),
        (["identify", "{exp}", "--drive", DRIVE_TOML, "--report", ""],
         "--report needs a directory name"),
        (["identify", "{exp}", "--drive", "{tmp}/nodrive.toml"],
         "(the drive's parameters belong under a [drive] line)"),
        (["control", "{tmp}/fast.toml"],
         "[reference] frequency 1e+06 rad/s is at or above the Nyquist frequency"),
        (["identify", "{tmp}/mirror.csv", "--drive", DRIVE_TOML],
         "this one rises from a negative level: negate the torque and both speeds"),
        (["reproduce", "ravanbod2002", "--err-p", "0.1,0.1", "--runs", "2"],
         "--err-p lists a value twice ('0.1,0.1')"),
    ],
)
def test_second_qa_pass_errors(exp_csv, tmp_path, capsys, argv, message):
    (tmp_path / "nodrive.toml").write_text("J_M = 4.88e-3\nJ_L = 6.8e-2\nk_sh = 78.0\n")
    (tmp_path / "fast.toml").write_text(
        (EXAMPLES / "tao1995.toml").read_text().replace("frequency = [1.3]", "frequency = [1e6]"))
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    write_csv(tmp_path / "mirror.csv", {"t": t, "torque": -u, "w_motor": -w_m, "w_load": -w_l})
    argv = [a.format(tmp=tmp_path, exp=exp_csv) for a in argv]
    err = _one_line_error(capsys, argv)
    assert message in err, err


def test_second_qa_pass_notes(exp_csv, tmp_path, capsys):
    """Two step-downs in one record are noted (the largest is used); a simulation whose
    sample time cannot show the ringing is noted (identify would refuse its file)."""
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    twice = np.where((t > 0.5) & (t < 1.0), 0.5, u)  # a short dip before the step-down
    write_csv(tmp_path / "twice.csv", {"t": t, "torque": twice, "w_motor": w_m, "w_load": w_l})
    assert main(["identify", str(tmp_path / "twice.csv"), "--drive", DRIVE_TOML,
                 "--interval", "fisher", "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert any("the torque steps down more than once" in n and "at t = 2 s" in n
               for n in notes), notes
    assert main(["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.157",
                 "--hold", "1", "--ts", "0.1", "--out", str(tmp_path / "coarse.csv")]) == 0
    err = capsys.readouterr().err
    assert "note: the sample time 0.1 s cannot resolve the drive's ringing" in err


def test_a_speed_glitch_is_refused(exp):
    """One sample of 1e300 (or any lone sample far off its neighbours) used to end in
    'fit nan %' (the drives of benchmarks/robustness_joint.py pass: the next test)."""
    w = exp.w_motor.copy()
    w[100] = 1e300
    prior = read_drive_toml(DRIVE_TOML, require_theta=False).with_theta(None)
    with pytest.raises(InputError, match=r"^exp\.csv: w_motor has 1 single-sample spike\(s\), "
                                         r"the largest at t = 0\.1 s \(sample 100: 1e\+300"):
        JointIdentifier(prior).fit(Record(exp.t, exp.torque, w, exp.w_load, name="exp.csv"))
    w[100] = exp.w_motor[100] + 0.5 * np.ptp(exp.w_motor)  # a glitch of half the range
    with pytest.raises(InputError, match="single-sample spike"):
        JointIdentifier(prior).fit(Record(exp.t, exp.torque, w, exp.w_load, name="exp.csv"))
    # an encoder's counts (4096 per turn at 1 kHz: 1.53 rad/s steps) dither by a count or
    # two with most samples equal to their neighbours: no spike
    from backlashkit.identify.record import check_spikes

    q = 2 * np.pi * 1000 / 4096
    check_spikes(Record(exp.t, exp.torque, np.round(exp.w_motor / q) * q,
                        np.round(exp.w_load / q) * q, name="encoder.csv"))
    # nor does a drive resting at exactly 0 (an encoder at standstill) for 60 % of the
    # record, with little noise elsewhere: its noise is judged where it moves
    n = exp.t.size
    rest = np.zeros(int(1.5 * n))
    t = np.arange(n + rest.size) * exp.ts
    check_spikes(Record(t, np.r_[rest, exp.torque], np.r_[rest, exp.w_motor],
                        np.r_[rest, exp.w_load], name="rest.csv"))


def test_wrong_types_in_the_python_api_are_named(exp):
    import backlashkit as bk

    prior = read_drive_toml(DRIVE_TOML, require_theta=False).with_theta(None)
    with pytest.raises(InputError, match="^records must be a Record or a sequence of "
                                         "Records, got NoneType$"):
        JointIdentifier(prior).fit(None)
    with pytest.raises(InputError, match=r"got str \(a file\? read it with "
                                         r"backlashkit\.read_records\)"):
        JointIdentifier(prior).fit("exp.csv")
    # a table of the four columns, which iterates as 100 records of one sample each
    with pytest.raises(InputError, match=re.escape(
            "got a (100, 4) array: for columns t, torque, w_motor, w_load give "
            "Record(*array.T)")):
        JointIdentifier(prior).fit(np.zeros((100, 4)))
    with pytest.raises(InputError, match="^final_horizon must be a real number, got '1'$"):
        JointIdentifier(prior, search=bk.JointSearch(final_horizon="1")).fit(exp)
    with pytest.raises(InputError, match="^J_M must be a real number, got '0.1'$"):
        bk.TwoMassDrive(J_M="0.1", J_L=1.0, k_sh=1.0, f_M=0.0, f_L=0.0, f_sh=0.0)


def test_a_torque_without_a_held_level_is_refused(exp, tmp_path, capsys):
    """A sine has a largest drop too, but no level held before it; a step-down along a
    50 ms ramp is paper A's experiment all the same."""
    t = exp.t
    for name, torque, refused in (
        ("sine.csv", 0.5 + 0.4 * np.sin(2.0 * t), True),
        ("ramp.csv", np.clip(0.942 * (2.05 - t) / 0.05, 0.0, 0.942), False),
    ):
        write_csv(tmp_path / name, {"t": t, "torque": torque, "w_motor": exp.w_motor,
                                    "w_load": exp.w_load})
        argv = ["identify", str(tmp_path / name), "--drive", DRIVE_TOML, "--interval", "fisher"]
        if refused:
            err = _one_line_error(capsys, argv)
            assert "sine.csv: the torque is not held before its largest drop" in err
        else:
            assert main(argv) == 0, capsys.readouterr().err
            capsys.readouterr()


def test_third_qa_pass(exp, exp_csv, tmp_path, capsys):
    """A step-down in two stages 0.15 s apart is one experiment (noted); a PRBS is not;
    a float32 .mat torque simulates; reproduce tao1995 probes its outputs first; an
    all-zero [uncertainty] says why the parameters are held; a broken symbolic link and
    UTF-16 without its mark are named."""
    import scipy.io

    t = exp.t
    two = np.where(t < 1.85, 0.942, np.where(t < 2.0, 0.6, 0.0))
    write_csv(tmp_path / "two.csv", {"t": t, "torque": two, "w_motor": exp.w_motor,
                                     "w_load": exp.w_load})
    assert main(["identify", str(tmp_path / "two.csv"), "--drive", DRIVE_TOML, "--interval",
                 "fisher", "--json", "--allow-far-from-prior"]) == 0
    assert any("steps down more than once" in n
               for n in json.loads(capsys.readouterr().out)["notes"])
    prbs = np.where(np.sin(7.0 * t) > 0, 0.5, -0.5)
    write_csv(tmp_path / "prbs.csv", {"t": t, "torque": prbs, "w_motor": exp.w_motor,
                                      "w_load": exp.w_load})
    err = _one_line_error(capsys, ["identify", str(tmp_path / "prbs.csv"), "--drive", DRIVE_TOML])
    assert "the torque steps down 4 times" in err
    scipy.io.savemat(tmp_path / "tq.mat", {"t": t.astype(np.float32),
                                           "torque": exp.torque.astype(np.float32)})
    assert main(["simulate", DRIVE_TOML, "--torque", str(tmp_path / "tq.mat"), "--out",
                 str(tmp_path / "s.csv")]) == 0
    capsys.readouterr()
    if Path("/proc/self").is_dir():
        err = _one_line_error(capsys, ["reproduce", "tao1995", "--json-out", "/proc/x.json"])
        assert "cannot write --json-out /proc/x.json" in err
    zero = tmp_path / "zero.toml"
    zero.write_text(Path(DRIVE_TOML).read_text() + "\n[uncertainty]\n" + "".join(
        f"{n} = 0\n" for n in ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")))
    assert main(["identify", str(exp_csv), "--drive", str(zero), "--interval", "fisher",
                 "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert notes == ["J_M, J_L, k_sh, f_M, f_L, f_sh held at the prior's values: "
                     "[uncertainty] gives them a relative std of 0 (known exactly)"]
    (tmp_path / "dangling.csv").symlink_to(tmp_path / "nowhere.csv")
    err = _one_line_error(capsys, ["simulate", DRIVE_TOML, "--experiment", "step-down",
                                   "--amplitude", "0.157", "--hold", "1", "--out",
                                   str(tmp_path / "dangling.csv")])
    assert "a broken symbolic link" in err
    (tmp_path / "u16.csv").write_bytes(Path(exp_csv).read_text().encode("utf-16-le"))
    err = _one_line_error(capsys, ["identify", str(tmp_path / "u16.csv"), "--drive", DRIVE_TOML])
    assert "UTF-16 text without a byte-order mark?" in err


@pytest.mark.parametrize("j_l", [1.0e-2, 6.8e-2, 0.25])
def test_no_glitch_in_the_robustness_drives(j_l):
    """The 27 scenarios of benchmarks/robustness_joint.py (J_L/J_M about 2, 14, 51;
    theta 0.5, 2, 5 deg; both experiments), noise-free and at 20, 30, 40 dB: impacts
    and rattling are no single-sample spikes."""
    import backlashkit as bk
    from backlashkit import signals
    from backlashkit.identify.record import check_spikes

    p = read_drive_toml(DRIVE_TOML, require_theta=False)
    t = signals.time_grid(80.0, 1e-3)
    rng = np.random.default_rng(0)
    for theta_deg in (0.5, 2.0, 5.0):
        drive = bk.TwoMassDrive(J_M=p.J_M, J_L=j_l, k_sh=p.k_sh, f_M=p.f_M, f_L=p.f_L,
                                f_sh=p.f_sh, theta=np.deg2rad(theta_deg))
        for a in (0.157, 0.942):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", bk.SensitivityWarning)
                r = drive.simulate(t, signals.step_down(t, a, t_s=40.0))
            check_spikes(Record(t, r.torque, r.w_motor, r.w_load))
            for snr in (20.0, 30.0, 40.0):
                check_spikes(Record(t, r.torque, signals.add_noise(r.w_motor, snr, rng=rng),
                                    signals.add_noise(r.w_load, snr, rng=rng)))


@pytest.mark.parametrize("counts_per_rev", [4096.0, None])
def test_encoder_angles_of_a_slow_drive_are_no_glitches(counts_per_rev):
    """A 4096-count encoder on a drive held at 0.3 N m: its speeds, differenced from the
    angles, step by one count (1.53 rad/s) in a range of a few counts a sample (the
    assertion below). Read as counts or as angles in rad (whose differences also differ
    by rounding where the counts are equal), those steps were refused as
    "single-sample spikes" (a QA pass)."""
    import backlashkit as bk
    from backlashkit import signals
    from backlashkit.identify.record import check_spikes

    p = read_drive_toml(DRIVE_TOML, require_theta=False)
    drive = bk.TwoMassDrive(J_M=p.J_M, J_L=p.J_L, k_sh=p.k_sh, f_M=p.f_M, f_L=p.f_L,
                            f_sh=p.f_sh, theta=0.03, fc_M=0.02, fc_L=0.04)
    t = signals.time_grid(5.0, 1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bk.SensitivityWarning)
        r = drive.simulate(t, signals.step_down(t, 0.3, t_s=2.0))
    enc = bk.Encoder(4096)
    counts = [enc.counts(r.phi_motor), enc.counts(r.phi_load)]
    if counts_per_rev is None:
        phi = [c * enc.resolution for c in counts]
        rec = Record.from_positions(t, r.torque, *phi)
    else:
        rec = Record.from_positions(t, r.torque, *counts, counts_per_rev=counts_per_rev)
    assert np.ptp(rec.w_load) < 5 * enc.resolution / 1e-3  # a few counts a sample
    check_spikes(rec)
    w = rec.w_load.copy()
    w[3000] += 50 * enc.resolution / 1e-3  # a glitch of 50 counts still is one
    with pytest.raises(InputError, match="single-sample spike"):
        check_spikes(Record(t, r.torque, rec.w_motor, w))


def test_a_closed_stdout_stops_quietly(steady_csv):
    """``backlashkit identify ... --json | head -c 10``: no error message when the reader
    closes the pipe before the answer is written."""
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "backlashkit", "identify", str(steady_csv), "--drive", DRIVE_TOML,
         "--method", "two-step", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait() == 1 and err == ""


def test_noise_free_records_are_said_so(tmp_path, capsys):
    """A simulated record without noise leaves a residual of numerical error only: the
    note says so, instead of calling it coloured noise (try --noise ar)."""
    path = tmp_path / "clean.csv"
    assert main(["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.942",
                 "--hold", "2", "--duration", "4", "--out", str(path)]) == 0
    capsys.readouterr()
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["theta"] == pytest.approx(math.radians(2.0), rel=1e-3)
    (note,) = [n for n in doc["notes"] if "spread" in n]
    assert "(noise-free, simulated records?)" in note
    assert not any("--noise ar" in n for n in doc["notes"])


def test_the_library_holds_the_contract(exp):
    """What ``identify`` refuses, the library refuses with the same rule: a record given
    twice, a record that is no step-down experiment (a PRBS), a prior 5 times off; the
    advice names the Python option, and the command line words the same error with its
    flag (one rule, two wordings)."""
    import pickle

    from backlashkit import TwoStepIdentifier
    from backlashkit.cli.main import word
    from backlashkit.errors import Option, PriorMismatchWarning, StepDownWarning
    from backlashkit.identify import as_records, check_fit_near_prior, check_step_downs

    prior = read_drive_toml(DRIVE_TOML, require_theta=False).with_theta(None)
    with pytest.raises(InputError, match="exp.csv holds the same data as exp.csv"):
        as_records([exp, exp])
    prbs = Record(exp.t, np.where(np.sin(7.0 * exp.t) > 0, 0.5, -0.5), exp.w_motor,
                  exp.w_load, name="prbs")
    with pytest.raises(InputError, match=r"^prbs: the torque steps down 4 times"):
        TwoStepIdentifier(prior).fit(prbs)
    two = Record(exp.t, np.where(exp.t < 1.85, 0.942, np.where(exp.t < 2.0, 0.6, 0.0)),
                 exp.w_motor, exp.w_load, name="two")
    with pytest.warns(StepDownWarning, match=r"^two: the torque steps down more than once"):
        assert check_step_downs([two], prior) == [2]
    far = {"J_M": 0.1 * prior.J_M, "k_sh": 3.5 * prior.k_sh}
    with pytest.raises(InputError, match=r"moved J_M x0\.1 from the prior") as info:
        check_fit_near_prior(far, prior)
    assert str(info.value).endswith("pass allow_far_from_prior=True")
    flags = {"allow_far_from_prior": "--allow-far-from-prior"}
    assert word(info.value, flags).endswith("pass --allow-far-from-prior")
    back = pickle.loads(pickle.dumps(info.value))  # a worker process's error keeps its parts
    assert word(back, flags) == word(info.value, flags)
    with pytest.warns(PriorMismatchWarning, match=r"J_M x0\.1, k_sh x3\.5 from the prior"):
        assert check_fit_near_prior(far, prior, allow_far_from_prior=True) == ["J_M", "k_sh"]
    # where the prior's own parameters fit the records about as well as the estimate, the
    # records do not contradict it: nothing is far
    from backlashkit.identify.step import FAR_RISE
    with pytest.warns(PriorMismatchWarning, match=r"J_M x0\.1, k_sh x3\.5 from the prior"):
        check_fit_near_prior(far, prior, allow_far_from_prior=True, prior_rise=FAR_RISE + 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_fit_near_prior(far, prior, prior_rise=FAR_RISE) == []
    # nor is a move within FAR_Z of the parameter's own standard errors: J_M x0.1 is
    # log 10 = 2.303 off, k_sh x3.5 1.253
    from backlashkit.identify.step import FAR_Z
    with pytest.warns(PriorMismatchWarning, match=r"moved k_sh x3\.5 from the prior"):
        assert check_fit_near_prior(far, prior, log_std={"J_M": 2.31 / FAR_Z,
                                                         "k_sh": 1.25 / FAR_Z}) == ["k_sh"]
    error = InputError("final_horizon must be > 0, got -1")  # a validation message
    assert word(error, {"final_horizon": "--final-horizon"}).startswith("--final-horizon must")
    assert str(InputError("a ", Option("resample", "linear"))) == "a resample='linear'"


# --- messages in the user's words (issue 21) --------------------------------------------

#: Paper notation that no message or help text may show (equation numbers, the
#: criterion's and the windows' symbols, the torque's formula).
PAPER_NOTATION = re.compile(r"\beq\. ?\d|W_1|\bdt4\b|\bdt_4\b|C_M = a 1\(t\)|\ba_[12]\b|"
                            r"paper A's experiment")


def test_the_two_step_methods_refusals_name_the_quantity(exp, exp_csv, tmp_path, capsys):
    """Each refusal of the two-step method's windows says what was expected in words,
    not with the paper's equation numbers or symbols, and what to do."""
    from backlashkit.identify.commutation import commutation_instants

    alpha = 0.5e-2 / 6.8e-2  # the prior's f_L / J_L
    cases = [
        ({"dt1": 0.001, "dt2": 0.01, "dt3": 0.05},
         "the windows searched for the contact loss and the impact after the step-down "
         "must each span at least 2 samples, got 0.001 s and 0.04 s at a sample time of "
         "0.001 s (lengthen dt1 and the span from dt2 to dt3, or record at a higher "
         "sample rate)"),
        ({"dt1": 0.05, "dt2": 0.01, "dt3": 2.5},
         "the record ends at t = 4 s, before the end of the window searched for the "
         "impact, t = 4.5 s (2.5 s after the step-down at t = 2 s): record longer after "
         "the step-down"),
        ({"dt1": 0.1, "dt2": 0.001, "dt3": 0.005},
         "comes before the contact loss, located at t = "),
    ]
    for windows, message in cases:
        with pytest.raises(InputError) as info:
            commutation_instants(exp, alpha, **windows)
        assert message in str(info.value) and not PAPER_NOTATION.search(str(info.value))
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    keep = t <= 2.5  # the step-down is at 2 s
    path = tmp_path / "half.csv"
    write_csv(path, {"t": t[keep], "torque": u[keep], "w_motor": w_m[keep],
                     "w_load": w_l[keep]})
    err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML,
                                   "--method", "two-step"])
    assert ("half.csv: the final least squares fits the motor speed over the 1 s after the "
            "step-down at t = 2 s, but the record ends at t = 2.5 s (record at least 1 s "
            "after the step-down") in err


@pytest.mark.parametrize("command", [["identify"], ["simulate"], ["control"],
                                     ["reproduce", "ravanbod2002"], ["fleet"]])
def test_help_has_no_paper_notation(command, capsys):
    """--help names quantities, not the paper's equation numbers or symbols; the
    separators are listed readably (not as ``{,,;,tab}``)."""
    assert main([*command, "--help"]) == 0
    out = capsys.readouterr().out
    assert not PAPER_NOTATION.search(out), PAPER_NOTATION.search(out)
    assert "{,,;,tab}" not in out and "{.,,}" not in out


def test_the_correlation_of_a_held_parameter_is_none_without_a_numpy_note():
    """A parameter held by the prior has a std of 0, and its covariances with the others
    round to tiny values of either sign: their quotients are inf and -inf, whose sum
    NumPy warned of as "invalid value encountered in add", which the command line
    printed as a note (``--prior-rel-std 0`` on a drive file with a loop)."""
    from backlashkit.cli.identify import _correlation

    cov = np.array([[4.0, 1e-20], [-1e-20, 0.0]])
    with np.errstate(all="raise"):
        corr = _correlation(cov)
    assert corr == [[1.0, None], [None, None]]


def test_a_misspelled_option_is_named_with_the_one_meant(exp_csv, capsys):
    """argparse says only that --drive is missing when it is misspelled, and sends an
    unknown option of a subcommand to the top level's help, which does not list it:
    the line names the option meant and the subcommand's help."""
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drvie", DRIVE_TOML])
    assert err.startswith("backlashkit: error: the following arguments are required: "
                          "--drive; --drvie: did you mean --drive? "
                          "(see 'backlashkit identify --help')")
    err = _one_line_error(capsys, ["identify", str(exp_csv), "--drive", DRIVE_TOML,
                                   "--metod", "joint"])
    assert ("unrecognized arguments: --metod joint; --metod: did you mean --method? "
            "(see 'backlashkit identify --help')") in err
    err = _one_line_error(capsys, ["simulate", "--out", "x.csv", "--zzz"])
    assert "did you mean" not in err and "(see 'backlashkit simulate --help')" in err
    # a subcommand or a value of a choice, misspelled
    err = _one_line_error(capsys, ["identfy", "x.csv"])
    assert "invalid choice: 'identfy'" in err and "; did you mean 'identify'?" in err, err
    err = _one_line_error(capsys, ["simulate", DRIVE_TOML, "--experiment", "step-dwn",
                                   "--out", "x.csv"])
    assert "; did you mean 'step-down'?" in err, err
    assert "did you mean" not in _one_line_error(capsys, ["zzz"])


def test_a_value_that_starts_with_a_dash_is_shown_after_an_equals_sign(capsys):
    """argparse takes ``-1,5`` for an option (it is no plain negative number) and says
    only that --h-range expects an argument."""
    err = _one_line_error(capsys, ["delay-margin", "paper-ex1", "--h-range", "-1,5"])
    assert ("argument --h-range: expected one argument; a value that starts with '-' goes "
            "after '=': --h-range=-1,5 (see 'backlashkit delay-margin --help')") in err, err
    err = _one_line_error(capsys, ["delay-margin", "paper-ex1", "--h-range"])
    assert "goes after '='" not in err, err


@pytest.mark.parametrize(("name", "speeds", "torque", "said", "remedy"), [
    ("degs", 180 / np.pi, 1.0, "deg/s read as rad/s?", "then give --speed-unit deg/s;"),
    ("mNm", 1.0, 1e3, "a torque in mN m read as N m?", "then give the torque in N m;"),
    ("radrpm", 2 * np.pi / 60, 1.0, "rad/s read as rpm?", "then give --speed-unit rad/s;"),
])
def test_a_unit_mistake_is_named_from_the_held_speeds(steady_csv, tmp_path, capsys, name,
                                                      speeds, torque, said, remedy):
    """Both refusals name the unit mistake that the held speeds' ratio to the prior's
    points to (not rpm for every one), the joint fit's before it fits (the QA pass's
    torque in mN m was refused with a generic misfit after 12.7 s); speeds in deg/s
    are read with --speed-unit deg/s, and answer as in rad/s."""
    t, u, w_m, w_l = np.loadtxt(steady_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / f"{name}.csv"
    write_csv(path, {"t": t, "torque": torque * u, "w_motor": speeds * w_m,
                     "w_load": speeds * w_l})
    for method in ("regression", "joint"):
        argv = ["identify", str(path), "--drive", DRIVE_TOML, "--method", method]
        if method == "joint":
            argv += ["--interval", "fisher"]
        err = _one_line_error(capsys, argv)
        assert f"check the units: {said} {remedy} else the time's units" in err, err
        # from the held speeds alone, not from a fit, where friction cannot slow them
        # that far (step.FRICTION_SLOWS): rad/s read as rpm is refused after the fit
        if method == "joint":
            before = name != "radrpm"
            assert ("under the torque held before the step-down" in err) == before, err
            assert ("the fit moved" in err) != before, err
    if name == "degs":
        assert main(["identify", str(path), "--drive", DRIVE_TOML, "--method", "regression",
                     "--speed-unit", "deg/s", "--json"]) == 0
        deg = json.loads(capsys.readouterr().out)["theta"]
        assert main(["identify", str(steady_csv), "--drive", DRIVE_TOML, "--method",
                     "regression", "--json"]) == 0
        assert deg == pytest.approx(json.loads(capsys.readouterr().out)["theta"], rel=1e-6)


def test_swapped_speeds_are_suspected_by_the_two_step_method(steady_csv, capsys):
    """With the load's speed read as the motor's, no motor speed rises after the
    step-down (the impact on the other flank): the refusal asks whether the columns are
    swapped, as the joint fit's does."""
    err = _one_line_error(capsys, ["identify", str(steady_csv), "--drive", DRIVE_TOML,
                                   "--method", "two-step", "--columns",
                                   "w_motor=w_load,w_load=w_motor"])
    assert "no impact on the negative flank found (are w_motor and w_load swapped?" in err


def test_common_scale_needs_every_parameter_moved_together():
    """``common_scale`` is the estimates' common ratio to the prior where each lies
    within SCALE_TOGETHER of it and it is beyond SCALE_NOTE; a prior's independent
    errors, or a small common move, give None."""
    from backlashkit.identify.step import SCALE_NOTE, SCALE_TOGETHER, common_scale

    prior = read_drive_toml(DRIVE_TOML, require_theta=False)
    names = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")

    def moved(*ratios):
        return {n: r * getattr(prior, n) for n, r in zip(names, ratios, strict=True)}

    assert common_scale(moved(0.5, 0.51, 0.49, 0.5, 0.52, 0.5), prior) == pytest.approx(
        0.50324, rel=1e-4)
    assert common_scale(moved(*[4.0] * 6), prior) == pytest.approx(4.0)
    assert common_scale(moved(*[1 / (0.99 * SCALE_NOTE)] * 6), prior) is None
    # one estimate outside the band about their mean (which it pulls): no common move
    assert common_scale(moved(0.5, 0.5, 0.5, 0.5, 0.5, 0.5 * SCALE_TOGETHER ** 1.25),
                        prior) is None
    assert common_scale(moved(0.4, 0.7, 0.5, 1.3, 0.5, 0.6), prior) is None
    assert common_scale({"J_M": 0.5 * prior.J_M, "k_sh": 0.5 * prior.k_sh}, prior) is None


def test_speeds_twice_too_large_are_named_from_the_common_move(steady_csv, tmp_path, capsys):
    """Speeds twice the drive's (a motor's electrical speed with two pole pairs) fit
    exactly with every linear parameter halved and theta doubled: no parameter is
    far (x3) from the prior, yet the note names the common move and the speeds' scale
    (the QA pass's record answered with no note at all)."""
    t, u, w_m, w_l = np.loadtxt(steady_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "x2.csv"
    write_csv(path, {"t": t, "torque": u, "w_motor": 2 * w_m, "w_load": 2 * w_l})
    assert main(["identify", str(path), "--drive", DRIVE_TOML, "--interval", "fisher",
                 "--json"]) == 0
    (note,) = [n for n in json.loads(capsys.readouterr().out)["notes"]
               if "every linear parameter moved" in n]
    # the common ratio of a 4 s record at 30 dB lies near one half, not on it
    assert re.search(r"moved by about x0\.(4[5-9]|5[0-5])\d* together, as speeds 2\.?\d* "
                     "times too large", note), note
    assert "pole pairs" in note and "--speed-unit" in note, note


def test_a_file_of_the_other_measure_names_the_option_that_reads_it(tmp_path, capsys):
    """A file of encoder angles read as speeds, or of speeds read as angles, names the
    option that reads what it holds (the QA pass had the generic "map the file's names
    with --columns"); counts read as rad name --counts-per-rev; a workbook is no CSV."""
    t = np.arange(200) * 1e-3
    counts = np.floor(np.linspace(0.0, 4e3, 200))
    angles = tmp_path / "counts.csv"
    write_csv(angles, {"t": t, "torque": np.ones(200), "phi_motor": counts,
                       "phi_load": counts})
    speeds = tmp_path / "speeds.csv"
    write_csv(speeds, {"t": t, "torque": np.ones(200), "w_motor": np.ones(200),
                       "w_load": np.ones(200)})
    err = _one_line_error(capsys, ["identify", str(angles), "--drive", DRIVE_TOML])
    assert "no column 'w_motor', 'w_load' but the encoders' angles" in err, err
    assert "--angles (in rad) or --counts-per-rev N (in counts)" in err, err
    err = _one_line_error(capsys, ["identify", str(speeds), "--drive", DRIVE_TOML, "--angles"])
    assert "no column 'phi_motor', 'phi_load' but the speeds" in err, err
    assert "leave out --angles and --counts-per-rev" in err, err
    err = _one_line_error(capsys, ["identify", str(angles), "--drive", DRIVE_TOML, "--angles"])
    assert "hold whole numbers only (a travel of up to 4000)" in err, err
    assert "encoder counts read as rad? give --counts-per-rev N" in err, err
    book = tmp_path / "data.xlsx"
    book.write_bytes(b"PK\x03\x04" + bytes(60))
    err = _one_line_error(capsys, ["identify", str(book), "--drive", DRIVE_TOML])
    assert "is a zip archive (an Excel .xlsx workbook?), not CSV text" in err, err


def test_speeds_against_the_torque_are_refused_before_the_fit(steady_csv, tmp_path, capsys):
    """Speeds negated (a sign counted the other way) hold -1 times the prior's held
    speed: refused before the fit with that cause, where the fit refused them only as a
    generic misfit (the QA pass: fit -172 %)."""
    t, u, w_m, w_l = np.loadtxt(steady_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
    path = tmp_path / "signflip.csv"
    write_csv(path, {"t": t, "torque": u, "w_motor": -w_m, "w_load": -w_l})
    err = _one_line_error(capsys, ["identify", str(path), "--drive", DRIVE_TOML])
    assert re.search(r"signflip\.csv: under the torque held before the step-down at t = 2 s "
                     r"the speeds are -1(\.0\d*)? times the prior's: they turn against the "
                     r"torque; negate the speeds \(or the torque\)", err), err


def test_the_record_table_widens_for_unix_time_stamps():
    """A record timed in Unix seconds (1.7e9) overflowed the table's 10 characters and
    shifted the columns after it (a QA pass)."""
    from backlashkit.cli._identify_text import _record_table

    lines = _record_table([
        {"file": "a.csv", "t_s": 1700000002.0, "t_c": 1700000002.0151, "t_b": None,
         "theta_ini": 0.0123},
        {"file": "b.csv", "t_s": 2.0, "t_c": 2.01, "t_b": 2.05, "theta_ini": None}])
    ends = {len(line) for line in lines}
    assert len(ends) == 1, lines  # every line as long: the columns line up
    heads = lines[0].split()
    assert heads[:3] == ["file", "t_s", "(s)"]
    assert lines[1].index("1700000002.0000") < lines[1].index("1700000002.0151")
    assert lines[2].rstrip().endswith("-")
