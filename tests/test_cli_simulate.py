"""``backlashkit simulate``: outputs, experiments, noise, and the bad-input matrix."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.identify.readers import read_torque
from backlashkit.io import read_drive_toml

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DRIVE = str(EXAMPLES / "paper_drive.toml")
TORQUE = str(EXAMPLES / "torque_example.csv")
PAPER_EXPERIMENT = ["--experiment", "step-down", "--amplitude", "0.157", "--hold", "40"]


def run(argv, capsys):
    """Run the CLI in-process; return (status, stdout, stderr)."""
    try:
        code = main(["simulate", *argv])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def read(path) -> dict[str, np.ndarray]:
    """The columns of a CSV file written by the command (parsed exactly)."""
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, k] for k, name in enumerate(header)}


def header(path) -> str:
    with open(path) as fh:
        return fh.readline().strip()


# --- --torque ------------------------------------------------------------------------


def test_torque_file_gives_exact_columns_on_the_same_grid(tmp_path, capsys):
    out = tmp_path / "r.csv"
    code, stdout, err = run([DRIVE, "--torque", TORQUE, "--out", str(out)], capsys)
    assert code == 0 and stdout == "" and "wrote" in err
    assert header(out) == "t,w_motor,w_load,phi_d"
    cols = read(out)
    t, u = read_torque(TORQUE)
    ref = read_drive_toml(DRIVE).simulate(t, u)
    # written at full precision: bit-for-bit equal to the library's result
    assert np.array_equal(cols["t"], t)
    assert np.array_equal(cols["w_motor"], ref.w_motor)
    assert np.array_equal(cols["w_load"], ref.w_load)
    assert np.array_equal(cols["phi_d"], ref.phi_d)


def test_json_summary(tmp_path, capsys):
    out = tmp_path / "r.csv"
    code, stdout, _ = run([DRIVE, "--torque", TORQUE, "--out", str(out), "--json"], capsys)
    assert code == 0
    summary = json.loads(stdout)
    t, u = read_torque(TORQUE)
    ref = read_drive_toml(DRIVE).simulate(t, u)
    assert summary["n_samples"] == t.size
    assert summary["output"] == str(out)
    assert summary["near_grazing"] == 0
    assert summary["law"] == "paper" and summary["torque_file"] == TORQUE
    assert [(e["time"], e["kind"], e["flank"]) for e in summary["events"]] == [
        (e.time, e.kind, e.flank) for e in ref.events
    ]
    assert {e["kind"] for e in summary["events"]} == {"contact_made", "contact_lost"}
    drive = read_drive_toml(DRIVE)
    assert summary["model"] == {**dataclasses.asdict(drive), "fs_M": 0.0, "fs_L": 0.0,
                                "tau_i": None}
    assert summary["encoder"] is None


def test_json_says_the_friction_loop_and_encoder_simulated(tmp_path, capsys):
    """The summary said nothing of the Coulomb torques, the loop or the encoder a run
    simulated (a QA pass)."""
    toml = tmp_path / "real.toml"
    toml.write_text(Path(DRIVE).read_text() + "fc_M = 0.02\nfc_L = 0.04\nfs_L = 0.05\n"
                    "\n[actuator]\ntau_i = 0.003\n")
    code, stdout, err = run([str(toml), "--experiment", "step-down", "--amplitude", "0.5",
                             "--hold", "1", "--duration", "2", "--encoder", "4096",
                             "--out", str(tmp_path / "r.csv"), "--json"], capsys)
    assert code == 0, err
    summary = json.loads(stdout)
    model = summary["model"]
    assert (model["fc_M"], model["fc_L"], model["fs_M"], model["fs_L"]) == (0.02, 0.04, 0.02,
                                                                           0.05)
    assert model["tau_i"] == 0.003
    assert summary["encoder"] == {"counts_per_rev": 4096.0, "speed_filter": 0.0}


def test_no_pull_law_is_used(tmp_path, capsys):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert run([DRIVE, "--torque", TORQUE, "--out", str(a)], capsys)[0] == 0
    assert run([DRIVE, "--torque", TORQUE, "--out", str(b), "--law", "no-pull"], capsys)[0] == 0
    t, u = read_torque(TORQUE)
    ref = read_drive_toml(DRIVE).simulate(t, u, law="no-pull")
    assert np.array_equal(read(b)["w_load"], ref.w_load)
    assert not np.array_equal(read(a)["w_load"], read(b)["w_load"])


def test_force_overwrites(tmp_path, capsys):
    out = tmp_path / "r.csv"
    out.write_text("old\n")
    assert run([DRIVE, "--torque", TORQUE, "--out", str(out), "--force"], capsys)[0] == 0
    assert header(out) == "t,w_motor,w_load,phi_d"


# --- --experiment --------------------------------------------------------------------


def test_paper_step_down_experiment(tmp_path, capsys):
    out = tmp_path / "exp.csv"
    code, stdout, _ = run([DRIVE, *PAPER_EXPERIMENT, "--out", str(out), "--json"], capsys)
    assert code == 0
    assert header(out) == "t,torque,w_motor,w_load"
    cols = read(out)
    t = cols["t"]
    assert t.size == 80001 and t[-1] == pytest.approx(80.0)
    np.testing.assert_allclose(np.diff(t), 1e-3, rtol=1e-9)
    assert np.all(cols["torque"][t < 40.0 - 1e-9] == 0.157)
    assert np.all(cols["torque"][t >= 40.0 - 1e-9] == 0.0)
    # noiseless: the simulation from rest, exactly
    ref = read_drive_toml(DRIVE).simulate(t, cols["torque"])
    assert np.array_equal(cols["w_motor"], ref.w_motor)
    assert np.array_equal(cols["w_load"], ref.w_load)
    # steady state before the step-down: w = a / (f_M + f_L) = 15.7 rad/s
    # (after 40 s, about 5.5 time constants J/f, it is within 0.5 % of it)
    assert cols["w_load"][39999] == pytest.approx(15.7, rel=5e-3)
    summary = json.loads(stdout)
    assert summary["n_samples"] == 80001 and summary["noise"] is None
    assert summary["experiment"]["kind"] == "step-down"
    assert summary["experiment"]["hold"] == 40.0
    # the step-down makes the shaft leave the positive flank and meet the negative one
    after = [(e["kind"], e["flank"]) for e in summary["events"] if e["time"] > 40.0]
    assert after[:2] == [("contact_lost", "positive"), ("contact_made", "negative")]


def test_noisy_experiment_is_deterministic_given_the_seed(tmp_path, capsys):
    args = [DRIVE, *PAPER_EXPERIMENT, "--duration", "50", "--snr-motor", "17.4",
            "--snr-load", "6.43"]
    a, b, c = (tmp_path / f"{x}.csv" for x in "abc")
    code, stdout, _ = run([*args, "--seed", "3", "--out", str(a), "--json"], capsys)
    assert code == 0
    assert run([*args, "--seed", "3", "--out", str(b)], capsys)[0] == 0
    assert run([*args, "--seed", "4", "--out", str(c)], capsys)[0] == 0
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()
    cols = read(a)
    assert cols["t"].size == 50001
    clean = read_drive_toml(DRIVE).simulate(cols["t"], cols["torque"])
    assert abs(signals.measure_snr_db(clean.w_motor, cols["w_motor"]) - 17.4) < 0.1
    assert abs(signals.measure_snr_db(clean.w_load, cols["w_load"]) - 6.43) < 0.1
    noise = json.loads(stdout)["noise"]
    assert noise["seed"] == 3 and noise["snr_motor_db"] == 17.4
    assert abs(noise["measured_snr_load_db"] - 6.43) < 0.1


def test_noise_on_one_channel_only_and_fresh_seed_is_reported(tmp_path, capsys):
    out = tmp_path / "e.csv"
    code, stdout, err = run(
        [DRIVE, *PAPER_EXPERIMENT, "--duration", "45", "--snr-load", "30", "--out", str(out),
         "--json"], capsys)
    assert code == 0 and "no --seed given; using --seed" in err
    noise = json.loads(stdout)["noise"]
    seed = noise["seed"]
    # the motor's keys are there, null: every document has the same keys
    assert noise["snr_motor_db"] is None and noise["measured_snr_motor_db"] is None
    assert noise["snr_load_db"] == 30.0
    cols = read(out)
    clean = read_drive_toml(DRIVE).simulate(cols["t"], cols["torque"])
    assert np.array_equal(cols["w_motor"], clean.w_motor)
    assert not np.array_equal(cols["w_load"], clean.w_load)
    again = tmp_path / "again.csv"
    assert run([DRIVE, *PAPER_EXPERIMENT, "--duration", "45", "--snr-load", "30", "--seed",
                str(seed), "--out", str(again)], capsys)[0] == 0
    assert again.read_bytes() == out.read_bytes()
    # a seed where nothing is random is said to do nothing (a QA pass)
    code, _, err = run([DRIVE, *PAPER_EXPERIMENT, "--duration", "45", "--seed", "3",
                        "--out", str(tmp_path / "clean.csv")], capsys)
    assert code == 0 and "note: --seed has no effect: nothing random is drawn" in err


@pytest.mark.parametrize(
    ("options", "n", "check"),
    [
        (["step", "--amplitude", "0.2", "--step-time", "0.5"], 1001,
         lambda u, t: np.array_equal(u, np.where(t >= 0.5 - 1e-9, 0.2, 0.0))),
        (["sine", "--amplitude", "0.3", "--frequency", "6.28", "--duration", "2",
          "--ts", "0.002"], 1001,
         lambda u, t: np.allclose(u, 0.3 * np.sin(6.28 * t), atol=1e-15)),
        (["prbs", "--amplitude", "0.25", "--bit-time", "0.05", "--duration", "1", "--seed",
          "2"], 1001,
         lambda u, t: set(np.unique(u)) == {-0.25, 0.25}),
        (["step-down", "--amplitude", "0.3", "--hold", "0.5", "--level-after", "-0.1"], 1001,
         lambda u, t: set(np.unique(u)) == {0.3, -0.1}),
    ],
    ids=["step", "sine", "prbs", "step-down-to-level"],
)
def test_other_experiments(tmp_path, capsys, options, n, check):
    out = tmp_path / "e.csv"
    code, _, err = run([DRIVE, "--experiment", *options, "--out", str(out)], capsys)
    assert code == 0, err
    cols = read(out)
    assert header(out) == "t,torque,w_motor,w_load"
    assert cols["t"].size == n and check(cols["torque"], cols["t"])


def test_experiment_file_is_readable_as_a_torque_file(tmp_path, capsys):
    exp, resp = tmp_path / "e.csv", tmp_path / "r.csv"
    args = [DRIVE, *PAPER_EXPERIMENT, "--duration", "41", "--ts", "0.01", "--out", str(exp)]
    assert run(args, capsys)[0] == 0
    assert run([DRIVE, "--torque", str(exp), "--out", str(resp)], capsys)[0] == 0
    assert np.array_equal(read(exp)["w_load"], read(resp)["w_load"])


def test_near_grazing_is_a_one_line_note(tmp_path, capsys, monkeypatch):
    original = bk.TwoMassDrive.simulate

    def grazing(self, t, torque, **kwargs):
        r = original(self, t, torque, **kwargs)
        warnings.warn("grazing", bk.SensitivityWarning, stacklevel=1)
        return dataclasses.replace(r, graze_array=np.array([[0.25, 0.0, -1e-9]]))

    monkeypatch.setattr(bk.TwoMassDrive, "simulate", grazing)
    out = tmp_path / "r.csv"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a leaked warning would fail the test
        code, stdout, err = run([DRIVE, "--torque", TORQUE, "--out", str(out), "--json"], capsys)
    assert code == 0
    notes = [line for line in err.splitlines() if "near-grazing" in line]
    assert len(notes) == 1 and "t = 0.25 s" in notes[0]
    assert "SensitivityWarning" not in err and "Traceback" not in err
    assert json.loads(stdout)["near_grazing"] == 1


# --- bad input -----------------------------------------------------------------------

GOOD_TOML = EXAMPLES.joinpath("paper_drive.toml").read_text()
GOOD_CSV = "t,torque\n0,0.1\n0.001,0.1\n0.002,0.1\n0.003,0\n"


def drive_with(text: str):
    return {"drive.toml": text}


def torque_with(text: str):
    return {"torque.csv": text}


# name -> (files to write, argv (with {d}=tmp dir), culprit expected in the error line)
BAD = {
    "missing TOML key": (
        drive_with(GOOD_TOML.replace("k_sh = 78.0", "")),
        ["{d}/drive.toml", "--torque", TORQUE], "missing key(s) k_sh"),
    "extra TOML key": (
        drive_with(GOOD_TOML + "gear_ratio = 3\n"),
        ["{d}/drive.toml", "--torque", TORQUE], "unknown key(s) gear_ratio"),
    "non-positive inertia": (
        drive_with(GOOD_TOML.replace("J_L = 6.8e-2", "J_L = 0.0")),
        ["{d}/drive.toml", "--torque", TORQUE], "J_L must be > 0"),
    "non-positive stiffness": (
        drive_with(GOOD_TOML.replace("k_sh = 78.0", "k_sh = -78.0")),
        ["{d}/drive.toml", "--torque", TORQUE], "k_sh must be > 0"),
    "negative backlash": (
        drive_with(GOOD_TOML.replace("theta = 3.49e-2", "theta = -3.49e-2")),
        ["{d}/drive.toml", "--torque", TORQUE], "theta must be >= 0"),
    "missing theta": (
        drive_with(GOOD_TOML.replace("theta = 3.49e-2", "")),
        ["{d}/drive.toml", "--torque", TORQUE], "missing key(s) theta"),
    "TOML does not parse": (
        drive_with(GOOD_TOML.replace("J_M = 4.88e-3", "J_M = 4.88e-3 kg")),
        ["{d}/drive.toml", "--torque", TORQUE], "not valid TOML"),
    "drive file missing": (
        {}, ["{d}/nope.toml", "--torque", TORQUE], "nope.toml"),
    "NaN in torque": (
        torque_with(GOOD_CSV.replace("0.001,0.1", "0.001,nan")),
        [DRIVE, "--torque", "{d}/torque.csv"], "line 3: 'torque' is missing"),
    "inf in torque": (
        torque_with(GOOD_CSV.replace("0.002,0.1", "0.002,inf")),
        [DRIVE, "--torque", "{d}/torque.csv"], "line 4, column 'torque'"),
    "inf in t": (
        torque_with(GOOD_CSV.replace("0.003,0", "inf,0")),
        [DRIVE, "--torque", "{d}/torque.csv"], "line 5, column 't'"),
    "non-monotonic t": (
        torque_with("t,torque\n0,1\n0.002,1\n0.001,1\n"),
        [DRIVE, "--torque", "{d}/torque.csv"], "the time 't' = 0.001 does not increase"),
    "non-uniform t": (
        torque_with("t,torque\n0,1\n0.001,1\n0.003,1\n"),
        [DRIVE, "--torque", "{d}/torque.csv"], "a non-uniform step in the time 't'"),
    "too few samples": (
        torque_with("t,torque\n0,1\n"),
        [DRIVE, "--torque", "{d}/torque.csv"], "too few samples"),
    "CSV does not parse": (
        torque_with("t,torque\n0,1\n0.001,1;2\n"),
        [DRIVE, "--torque", "{d}/torque.csv"], "'1;2' is not a number"),
    "CSV ragged": (
        torque_with("t,torque\n0,1\n0.001\n"),
        [DRIVE, "--torque", "{d}/torque.csv"], "line 3 has 1 field(s)"),
    "missing column": (
        torque_with("t,u\n0,1\n0.001,1\n"),
        [DRIVE, "--torque", "{d}/torque.csv"], "no column 'torque'"),
    "output exists": (
        {"out.csv": "precious\n"}, [DRIVE, "--torque", TORQUE], "pass --force"),
    "both sources": (
        {}, [DRIVE, "--torque", TORQUE, *PAPER_EXPERIMENT], "both were given"),
    "neither source": (
        {}, [DRIVE], "neither was given"),
    "experiment without amplitude": (
        {}, [DRIVE, "--experiment", "step-down", "--hold", "1"], "needs --amplitude"),
    "experiment without hold": (
        {}, [DRIVE, "--experiment", "step-down", "--amplitude", "1"], "needs --hold"),
    "option of another experiment": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--frequency", "3"], "--frequency does not apply"),
    "experiment option with --torque": (
        {}, [DRIVE, "--torque", TORQUE, "--snr-load", "20"], "--snr-load only applies"),
    "hold longer than record": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--duration", "30"], "--hold (40.0 s) must be shorter"),
    "step after the record": (
        {}, [DRIVE, "--experiment", "step", "--amplitude", "1", "--step-time", "2",
             "--duration", "1"], "--step-time (2.0 s) must be shorter"),
    "record too long": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--duration", "1e9"], "--duration / --ts:"),
    "negative ts": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--ts=-1e-3"], "--ts must be > 0"),
    "nan amplitude": (
        {}, [DRIVE, "--experiment", "step-down", "--amplitude", "nan", "--hold", "1"],
        "--amplitude must be finite"),
    "sine above Nyquist": (
        {}, [DRIVE, "--experiment", "sine", "--amplitude", "1", "--frequency", "5000",
             "--duration", "1"], "Nyquist"),
    "sine without duration": (
        {}, [DRIVE, "--experiment", "sine", "--amplitude", "1", "--frequency", "5"],
        "needs --duration"),
    "prbs bit shorter than sample": (
        {}, [DRIVE, "--experiment", "prbs", "--amplitude", "1", "--bit-time", "1e-4",
             "--duration", "1", "--seed", "0"], "--bit-time"),
    "negative seed": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--snr-load", "20", "--seed", "-1"], "--seed must be"),
    "infinite SNR": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--snr-load", "inf", "--seed", "1"],
        "--snr-load must be finite"),
    "noise on a zero signal": (
        {}, [DRIVE, "--experiment", "step", "--amplitude", "0", "--duration", "1",
             "--snr-motor", "20", "--seed", "1"], "--snr-motor: cannot add noise to w_motor"),
    "output directory missing": (
        {}, [DRIVE, "--torque", TORQUE, "--out", "{d}/no/such/dir/out.csv"], "does not exist"),
    # argparse's own checks (SystemExit) keep the same contract
    "unknown law": ({}, [DRIVE, "--torque", TORQUE, "--law", "magic"], "--law"),
    "amplitude not a number": (
        {}, [DRIVE, "--experiment", "step", "--amplitude", "abc"], "--amplitude"),
    "no output option": ({}, [DRIVE, "--torque", TORQUE, "--out"], "--out"),
    "encoder under one count": (
        {}, [DRIVE, "--torque", TORQUE, "--encoder", "0.5"], "--encoder: counts_per_rev"),
    "speed filter without encoder": (
        {}, [DRIVE, "--torque", TORQUE, "--speed-filter", "1e-3"], "--speed-filter only"),
    "negative speed filter": (
        {}, [DRIVE, "--torque", TORQUE, "--encoder", "1000", "--speed-filter", "-1"],
        "--speed-filter: tau_w must be >= 0"),
    "encoder with noise": (
        {}, [DRIVE, *PAPER_EXPERIMENT, "--encoder", "1000", "--snr-motor", "30"],
        "give one or the other"),
    "breakaway below Coulomb": (
        drive_with(GOOD_TOML + "fc_M = 0.02\nfs_M = 0.01\n"),
        ["{d}/drive.toml", "--torque", TORQUE], "fs_M must be >= fc_M"),
    "negative Coulomb friction": (
        drive_with(GOOD_TOML + "fc_L = -0.02\n"),
        ["{d}/drive.toml", "--torque", TORQUE], "fc_L must be >= 0"),
    "non-finite current loop": (
        drive_with(GOOD_TOML + "[actuator]\ntau_i = inf\n"),
        ["{d}/drive.toml", "--torque", TORQUE], "tau_i must be finite"),
}


@pytest.mark.parametrize("case", list(BAD), ids=list(BAD))
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, case):
    files, argv, culprit = BAD[case]
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    argv = [a.replace("{d}", str(tmp_path)) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out.csv")]
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    code, stdout, err = run(argv, capsys)
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("backlashkit: error: ")
    assert culprit in lines[0]
    assert "Traceback" not in err and stdout == ""
    # nothing written or overwritten
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_encoder_records(tmp_path, capsys):
    # --encoder N: the speeds an encoder of N counts/rev delivers (differences of counts
    # over the sample time), with the counts; the format identify reads plus two columns.
    out = tmp_path / "enc.csv"
    argv = [DRIVE, "--experiment", "step-down", "--amplitude", "0.157", "--hold", "2",
            "--encoder", "4096", "--speed-filter", "2e-3", "--out", str(out), "--json"]
    code, stdout, _ = run(argv, capsys)
    assert code == 0
    assert header(out) == "t,torque,w_motor,w_load,count_motor,count_load"
    cols = read(out)
    drive = read_drive_toml(DRIVE)
    resp = drive.simulate(cols["t"], cols["torque"], positions=True)
    expect = bk.measure_encoders(resp, bk.Encoder(4096, tau_w=2e-3))
    for name in ("w_motor", "w_load", "count_motor", "count_load"):
        assert np.array_equal(cols[name], expect[name]), name
    assert np.array_equal(cols["count_motor"], np.floor(resp.phi_motor / (2 * np.pi / 4096)))
    assert json.loads(stdout)["columns"] == list(expect)


def test_drive_file_friction_and_actuator(tmp_path, capsys):
    path = tmp_path / "drive.toml"
    path.write_text(GOOD_TOML + "fc_M = 0.01\nfc_L = 0.02\nfs_L = 0.03\n"
                    "[actuator]\ntau_i = 1e-3\n")
    out = tmp_path / "r.csv"
    code, _, _ = run([str(path), "--torque", TORQUE, "--out", str(out)], capsys)
    assert code == 0
    cols = read(out)
    t, u = read_torque(TORQUE)
    drive = read_drive_toml(path)
    assert (drive.fc_M, drive.fc_L, drive.fs_M, drive.fs_L) == (0.01, 0.02, None, 0.03)
    ref = drive.simulate(t, u, actuator=bk.CurrentLoop(1e-3))
    assert np.array_equal(cols["w_motor"], ref.w_motor)


def test_output_equal_to_input_is_refused_even_with_force(tmp_path, capsys):
    torque = tmp_path / "t.csv"
    torque.write_text(GOOD_CSV)
    code, _, err = run([DRIVE, "--torque", str(torque), "--out", str(torque), "--force"], capsys)
    assert code == 2 and "also an input file" in err and torque.read_text() == GOOD_CSV


# --- the installed entry point -------------------------------------------------------


def test_python_dash_m_entry_point(tmp_path):
    out = tmp_path / "r.csv"
    cmd = [sys.executable, "-m", "backlashkit", "simulate", DRIVE, "--torque", TORQUE,
           "--out", str(out), "--json"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["n_samples"] == read_torque(TORQUE)[0].size
    assert header(out) == "t,w_motor,w_load,phi_d"
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 2 and again.stdout == ""
    assert again.stderr.count("\n") == 1 and "--force" in again.stderr
    assert "Traceback" not in again.stderr


def test_torque_files_are_read_as_identify_reads_experiments(tmp_path, capsys):
    """A European export (';', decimal commas, other names) with --columns, and .npz:
    the same response as the plain CSV; reader options without --torque are refused."""
    t, u = read_torque(TORQUE)
    ref = read_drive_toml(DRIVE).simulate(t, u)
    eu = tmp_path / "eu.csv"
    eu.write_text("Zeit;Moment\n" + "".join(f"{a:.17g};{b:.17g}\n".replace(".", ",")
                                           for a, b in zip(t, u, strict=True)))
    npz = tmp_path / "torque.npz"
    np.savez(npz, t=t, torque=u)
    for source, extra in ((eu, ["--columns", "t=Zeit,torque=Moment"]), (npz, [])):
        out = tmp_path / f"{source.stem}.out.csv"
        code, _, err = run([DRIVE, "--torque", str(source), *extra, "--out", str(out)], capsys)
        assert code == 0, err
        np.testing.assert_allclose(read(out)["w_motor"], ref.w_motor, rtol=1e-12, atol=1e-12)
    code, _, err = run([DRIVE, *PAPER_EXPERIMENT, "--decimal", ",", "--out",
                        str(tmp_path / "x.csv")], capsys)
    assert code == 2 and "--decimal only applies with --torque" in err


def test_plot_formats_are_the_same_for_simulate_and_control(tmp_path, capsys):
    """Both --plot options write .jpg as well, and refuse .gif before computing."""
    out, jpg = tmp_path / "o.csv", tmp_path / "f.JPG"
    step = ["simulate", DRIVE, "--experiment", "step", "--amplitude", "0.1", "--duration",
            "0.5", "--out", str(out)]
    assert main([*step, "--plot", str(jpg)]) == 0
    assert jpg.read_bytes()[:2] == b"\xff\xd8"  # the JPEG start-of-image marker
    for argv in ([*step, "--force"], ["control", str(EXAMPLES / "tao1995.toml")]):
        capsys.readouterr()
        assert main([*argv, "--plot", str(tmp_path / "f.gif")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1
        assert "f.gif: the file name must end in .png, .svg, .pdf or .jpg" in err
    assert not (tmp_path / "f.gif").exists()


def test_the_plot_shows_the_speeds_as_written(tmp_path, monkeypatch):
    """With noise (or an encoder) the CSV holds speeds that differ from the simulated
    ones: the plot draws both, the simulated ones labelled noise-free (a QA pass found
    only the clean curves beside a noisy file); without, the simulated speeds alone."""
    import matplotlib.figure

    saved = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, *args, **kw: saved.append(fig))
    step = ["simulate", DRIVE, "--experiment", "step", "--amplitude", "0.1", "--duration",
            "0.5", "--plot", str(tmp_path / "p.png")]
    assert main([*step, "--out", str(tmp_path / "clean.csv")]) == 0
    assert main([*step, "--out", str(tmp_path / "noisy.csv"), "--snr-motor", "30",
                 "--snr-load", "30", "--seed", "1", "--force"]) == 0
    assert main([*step, "--out", str(tmp_path / "enc.csv"), "--encoder", "1000",
                 "--force"]) == 0
    labels = [[ln.get_label() for ln in fig.axes[0].get_lines()] for fig in saved]
    assert labels[0] == ["motor", "load"]
    noisy = np.loadtxt(tmp_path / "noisy.csv", delimiter=",", skiprows=1)
    for lines in labels[1:]:
        assert lines == ["motor (noise-free)", "motor as measured", "load (noise-free)",
                         "load as measured"]
    np.testing.assert_array_equal(saved[1].axes[0].get_lines()[1].get_ydata(), noisy[:, 2])
