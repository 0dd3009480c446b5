"""Drive TOML files and CSV writing (backlashkit.io)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from backlashkit import InputError, TwoMassDrive
from backlashkit.identify.readers import read_torque
from backlashkit.io import (
    DRIVE_KEYS,
    read_drive_toml,
    read_uncertainty_toml,
    write_csv,
)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2,
             theta=3.49e-2)


def toml_text(values: dict | None = None, *, drop=(), extra: str = "") -> str:
    values = dict(PAPER if values is None else values)
    lines = ["[drive]"]
    for key, value in values.items():
        if key not in drop:
            lines.append(f"{key} = {value}")
    return "\n".join(lines) + "\n" + extra


def write(tmp_path: Path, text: str, name: str = "drive.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# --- drive TOML ----------------------------------------------------------------------


def test_paper_example_file():
    drive = read_drive_toml(EXAMPLES / "paper_drive.toml")
    assert drive == TwoMassDrive(**PAPER)
    assert drive.theta == pytest.approx(np.deg2rad(2.0), rel=1e-3)  # half-width, 2 degrees


def test_integers_are_accepted(tmp_path):
    drive = read_drive_toml(write(tmp_path, toml_text({**PAPER, "k_sh": 78, "theta": 0})))
    assert drive.k_sh == 78.0 and isinstance(drive.k_sh, float) and drive.theta == 0.0


def test_a_theta_in_degrees_is_noted(tmp_path):
    """theta = 2 (paper A's 2 degrees, written as rad) is 115 degrees of half-width: read,
    with a note that names the likely mistake; paper A's own file reads without one."""
    import warnings

    path = write(tmp_path, toml_text({**PAPER, "theta": 2.0}))
    with pytest.warns(UserWarning, match=r"theta = 2 rad is a half-width of 115 deg: "
                                         r"theta is in rad \(degrees written as rad\? "
                                         r"2 deg is 0\.03491 rad\)"):
        assert read_drive_toml(path).theta == 2.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_drive_toml(EXAMPLES / "paper_drive.toml")


def test_theta_may_be_left_out_for_identification(tmp_path):
    path = write(tmp_path, toml_text(drop=("theta",)))
    assert read_drive_toml(path, require_theta=False).theta is None
    with pytest.raises(InputError, match=r"missing key\(s\) theta .*half-width"):
        read_drive_toml(path)
    # a given theta is still used
    assert read_drive_toml(write(tmp_path, toml_text(), "b.toml"), require_theta=False).theta == (
        3.49e-2
    )


def test_uncertainty_table_is_accepted_and_read(tmp_path):
    path = write(tmp_path, toml_text(extra="[uncertainty]\nJ_L = 0.1\nk_sh = 0.2\n"))
    assert read_drive_toml(path) == TwoMassDrive(**PAPER)
    assert read_uncertainty_toml(path) == {"J_L": 0.1, "k_sh": 0.2}
    assert read_uncertainty_toml(write(tmp_path, toml_text(), "b.toml")) == {}
    # the Coulomb torques too, whose values the [drive] table gives
    text = toml_text(extra="[uncertainty]\nfc_M = 0.5\n").replace(
        "[drive]", "[drive]\nfc_M = 0.01")
    path = write(tmp_path, text, "c.toml")
    assert read_drive_toml(path).fc_M == 0.01
    assert read_uncertainty_toml(path) == {"fc_M": 0.5}
    # and a current loop's time constant, whose value the [actuator] table gives
    path = write(tmp_path, toml_text(extra="[actuator]\ntau_i = 0.001\n[uncertainty]\n"
                                           "tau_i = 0.3\n"), "d.toml")
    assert read_uncertainty_toml(path) == {"tau_i": 0.3}


@pytest.mark.parametrize(
    ("extra", "culprit"),
    [
        ("[uncertainty]\nJ_X = 0.1\n", r"unknown key\(s\) J_X in \[uncertainty\]; allowed keys: "
         r"J_M, J_L, k_sh, f_M, f_L, f_sh, fc_M, fc_L, tau_i$"),
        ("[uncertainty]\ntheta = 0.1\n", r"\[uncertainty\] theta: the backlash is what identify "
         r"estimates"),
        ("[uncertainty]\nJ_L = -0.1\n", "J_L must be >= 0"),
        ("[uncertainty]\nJ_L = 'ten'\n", "J_L must be a number"),
    ],
)
def test_bad_uncertainty_table(tmp_path, extra, culprit):
    with pytest.raises(InputError, match=culprit):
        read_uncertainty_toml(write(tmp_path, toml_text(extra=extra)))


BAD_TOML = {
    "missing key": (toml_text(drop=("k_sh",)), r"missing key\(s\) k_sh in \[drive\]"),
    "missing keys": (toml_text(drop=("J_M", "f_L")), r"missing key\(s\) J_M, f_L"),
    "extra key": (toml_text(extra="").replace("[drive]", "[drive]\nJ_m = 1.0"),
                  r"unknown key\(s\) J_m in \[drive\] \(did you mean J_M\?\); allowed keys: "
                  r"J_M, J_L, k_sh"),
    "total gap key": (toml_text({**PAPER, "b": 0.07}), r"unknown key\(s\) b"),
    "unknown table": (toml_text(extra="[drvie]\nx = 1\n"), r"unknown top-level key\(s\) drvie"),
    "no drive table": ("[motor]\nJ = 1.0\n", "motor"),
    "empty file": ("", r"no \[drive\] table"),
    "drive not a table": ("drive = 3\n", "drive must be a table"),
    "zero J_M": (toml_text({**PAPER, "J_M": 0.0}), r"J_M must be > 0, got 0\.0"),
    "negative J_L": (toml_text({**PAPER, "J_L": -1.0}), r"J_L must be > 0, got -1\.0"),
    "zero k_sh": (toml_text({**PAPER, "k_sh": 0}), "k_sh must be > 0"),
    "negative k_sh": (toml_text({**PAPER, "k_sh": -78}), "k_sh must be > 0"),
    "negative theta": (toml_text({**PAPER, "theta": -0.01}), r"theta must be >= 0, got -0\.01"),
    "negative f_sh": (toml_text({**PAPER, "f_sh": -1e-3}), "f_sh must be >= 0"),
    "string value": (toml_text({**PAPER, "J_M": '"4.88e-3"'}), r"J_M must be a number.*str"),
    "bool value": (toml_text({**PAPER, "f_M": "true"}), r"f_M must be a number.*bool"),
    "array value": (toml_text({**PAPER, "theta": "[0.1, 0.2]"}), "theta must be a number"),
    "nan value": (toml_text({**PAPER, "J_L": "nan"}), "J_L must be finite"),
    "inf value": (toml_text({**PAPER, "k_sh": "inf"}), "k_sh must be finite"),
    "does not parse": (toml_text().replace("k_sh = 78.0", "k_sh 78.0"),
                       r"not valid TOML: .*line 4"),
    "duplicate key": (toml_text() + "J_M = 1.0\n", r"not valid TOML: .*line 9"),
}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (toml_text().replace("k_sh", "k_hs"),
         "unknown key(s) k_hs in [drive] (did you mean k_sh?); allowed keys: J_M,"),
        (toml_text().replace("J_L", "JL").replace("f_sh", "f_hs"),
         "unknown key(s) JL, f_hs in [drive] (did you mean J_L or f_sh?); allowed keys"),
        (toml_text(extra="[drvie]\nx = 1\n"),
         "unknown top-level key(s) drvie (did you mean [drive]?); allowed tables"),
        (toml_text(extra="[uncertainty]\nJ_LL = 0.1\n"),
         "unknown key(s) J_LL in [uncertainty] (did you mean J_L?); allowed keys"),
        (toml_text().replace("[drive]", "theta_x = 1\n[drive]"),  # too far from any table
         "unknown top-level key(s) theta_x; allowed tables"),
        (toml_text(extra="[actuator]\ntau = 1e-3\n"),
         "[actuator] takes exactly the key(s) tau_i (tau_i: current-loop time constant in s); "
         "got tau (did you mean tau_i?)"),
    ],
    ids=["swap", "two", "table", "uncertainty", "no guess", "actuator"],
)
def test_a_typo_gets_did_you_mean(tmp_path, text, message):
    """A misspelt key is named with the allowed key it most looks like (difflib), by
    every reader of the file, and by the command line on one line."""
    from backlashkit.cli import main
    from backlashkit.io import read_actuator_toml

    path = write(tmp_path, text)
    reader = (read_actuator_toml if "[actuator]" in message else
              read_uncertainty_toml if "[uncertainty]" in message else read_drive_toml)
    with pytest.raises(InputError) as info:
        reader(path)
    assert str(info.value).startswith(f"{path}: {message}")
    if reader is read_drive_toml:
        argv = ["simulate", str(path), "--experiment", "step-down", "--amplitude", "0.1",
                "--hold", "1", "--out", str(tmp_path / "x.csv")]
        assert main(argv) == 2
        assert not (tmp_path / "x.csv").exists()


def test_did_you_mean_in_the_cli_message(tmp_path, capsys):
    from backlashkit.cli import main

    path = write(tmp_path, toml_text().replace("k_sh", "k_hs"), "my drive.toml")
    assert main(["simulate", str(path), "--experiment", "step-down", "--amplitude", "0.1",
                 "--hold", "1", "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}: unknown key(s) k_hs in [drive] (did you mean " \
        "k_sh?)" in err


@pytest.mark.parametrize("case", list(BAD_TOML), ids=list(BAD_TOML))
def test_bad_drive_file(tmp_path, case):
    text, culprit = BAD_TOML[case]
    path = write(tmp_path, text)
    with pytest.raises(InputError, match=culprit) as info:
        read_drive_toml(path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and "\n" not in msg


def test_non_utf8_toml(tmp_path):
    path = tmp_path / "drive.toml"
    path.write_bytes(b"[drive]\nJ_M = 1.0 # \xff\n")
    with pytest.raises(InputError, match="not a UTF-8 text file"):
        read_drive_toml(path)


def test_missing_toml_file_is_a_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_drive_toml(tmp_path / "nope.toml")


def test_drive_keys_match_the_model():
    from backlashkit.io import FRICTION_KEYS

    assert set(DRIVE_KEYS) | set(FRICTION_KEYS) == set(TwoMassDrive.__dataclass_fields__)


# --- CSV reading ---------------------------------------------------------------------


def read_back(path: Path) -> dict[str, np.ndarray]:
    """The columns of a written CSV file, parsed with Python's float (exact)."""
    with open(path) as fh:
        names = fh.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return {name: data[:, k] for k, name in enumerate(names)}


# --- CSV writing ---------------------------------------------------------------------


def test_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(1000) * 1e-3
    cols = {
        "t": t,
        "torque": rng.normal(size=1000),
        "w": rng.normal(size=1000) * 10.0 ** rng.integers(-300, 300, 1000),
    }
    cols["w"][:3] = [0.1, 1 / 3, 5e-324]
    path = tmp_path / "out.csv"
    write_csv(path, cols)
    back = read_back(path)
    for key, values in cols.items():
        assert np.array_equal(back[key], values), key
    assert path.read_text().splitlines()[0] == "t,torque,w"


@given(arrays(np.float64, st.integers(2, 30), elements=st.floats(allow_nan=False,
                                                                  allow_infinity=False)))
@settings(max_examples=40, deadline=None)
def test_round_trip_property(tmp_path_factory, values):
    path = tmp_path_factory.mktemp("rt") / "x.csv"
    write_csv(path, {"x": values, "y": -values})
    back = read_back(path)
    assert np.array_equal(back["x"], values) and np.array_equal(back["y"], -values)


def test_write_refuses_to_overwrite_unless_forced(tmp_path):
    path = tmp_path / "out.csv"
    path.write_text("keep me\n")
    with pytest.raises(InputError, match=r"already exists; pass --force"):
        write_csv(path, {"a": [1.0]})
    assert path.read_text() == "keep me\n"
    write_csv(path, {"a": [1.0, 2.5]}, force=True)
    assert path.read_text() == "a\n1.0\n2.5\n"


@pytest.mark.parametrize(
    ("columns", "culprit"),
    [
        ({}, "at least one column"),
        ({"a": [1.0], "b": [1.0, 2.0]}, "same length"),
        ({"a,b": [1.0]}, "column names"),
        ({"": [1.0]}, "column names"),
        ({"a": [[1.0]]}, "1-D"),
        ({"a": ["x"]}, "real numbers"),
    ],
)
def test_write_rejects_bad_columns(tmp_path, columns, culprit):
    with pytest.raises(InputError, match=culprit):
        write_csv(tmp_path / "o.csv", columns)
    assert not (tmp_path / "o.csv").exists()


def test_write_into_missing_directory(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        write_csv(tmp_path / "nope" / "o.csv", {"a": [1.0]})


def test_nan_is_written_and_read_back_as_an_error(tmp_path):
    path = tmp_path / "o.csv"
    write_csv(path, {"t": [0.0, 1.0, 2.0], "torque": [1.0, math.nan, 1.0]})
    with pytest.raises(InputError, match="line 3: 'torque' is missing"):
        read_torque(path)
