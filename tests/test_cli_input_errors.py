"""Bad input found by a QA pass over the command line: each case ends in one line on
stderr and exit status 2, never a traceback and never a number that means nothing.

The experiment is the short one of ``tests/test_identify_joint.py`` (paper A's drive,
0.942 N m from rest for 2 s, then 0; 4 s at Ts = 1 ms, 30 dB on both speeds).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from backlashkit.cli import main
from backlashkit.errors import InputError
from backlashkit.identify import Record
from backlashkit.identify_joint import JointIdentifier, _lm, _LMState
from backlashkit.io import read_drive_toml, write_csv

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DRIVE_TOML = str(EXAMPLES / "paper_drive.toml")


@pytest.fixture(scope="module")
def exp_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("qa") / "exp.csv"
    assert main(["simulate", DRIVE_TOML, "--experiment", "step-down", "--amplitude", "0.942",
                 "--hold", "2", "--snr-motor", "30", "--snr-load", "30", "--seed", "1",
                 "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def exp(exp_csv):
    t, u, w_m, w_l = np.loadtxt(exp_csv, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3)).T
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
    assert "cannot compute with this input: sample time 0.001 s is far too long" in err


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
    assert "afile" in err and ("not a directory" in err or "is a file" in err)


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
