"""``backlashkit delay-margin``: JSON fields, words, and one-line errors (status 2)."""

from __future__ import annotations

import importlib
import json
import math
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "delay_system.toml"


@pytest.fixture
def run_cli(monkeypatch, capsys):
    """``backlashkit ...`` with the delay-margin subcommand registered (whether or not the
    top-level CLI lists it yet)."""
    main_mod = importlib.import_module("backlashkit.cli.main")
    if "delay_margin" not in main_mod.SUBCOMMAND_MODULES:
        monkeypatch.setattr(main_mod, "SUBCOMMAND_MODULES",
                            (*main_mod.SUBCOMMAND_MODULES, "delay_margin"))

    def run(*argv):
        status = main_mod.main(["delay-margin", *map(str, argv)])
        out, err = capsys.readouterr()
        return status, out, err

    return run


def write(tmp_path, text, name="sys.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_json_fields_of_the_example(run_cli):
    status, out, err = run_cli(EXAMPLE, "--json")
    assert status == 0 and err == ""
    d = json.loads(out)
    assert set(d) == {"h_max", "omega", "stable_at_zero", "delay_independent", "windows",
                      "difference_radius"}
    assert d["difference_radius"] == 0.0  # retarded
    assert math.floor(d["h_max"] * 1e4) / 1e4 == 6.1725
    assert d["omega"] == pytest.approx(math.sqrt(0.19), rel=1e-12)
    assert d["stable_at_zero"] is True and d["delay_independent"] is False
    assert d["windows"] == [[0.0, pytest.approx(d["h_max"])]]


def test_h_range_and_returning_windows(run_cli, tmp_path):
    """Olgac & Sipahi's (2002) example: stability is lost and comes back."""
    p = write(tmp_path, "[delay_system]\n"
                        "A0 = [[-1.0, 13.5, -1.0], [-3.0, -1.0, -2.0], [-2.0, -1.0, -4.0]]\n"
                        "A = [[[-5.9, 7.1, -70.3], [2.0, -1.0, 5.0], [2.0, 0.0, 6.0]]]\n")
    status, out, _ = run_cli(p, "--json", "--h-range", "0,1")
    d = json.loads(out)
    assert status == 0 and len(d["windows"]) == 2
    assert d["windows"][0][0] == 0.0 and d["windows"][0][1] == pytest.approx(d["h_max"])
    assert all(0 <= a < b <= 1 for a, b in d["windows"])


def test_delay_independent_gives_null(run_cli, tmp_path):
    p = write(tmp_path, "[delay_system]\nA0 = [[-2.0]]\nA = [[[-1.0]]]\n")
    status, out, _ = run_cli(p, "--json")
    d = json.loads(out)
    assert status == 0 and d["h_max"] is None and d["omega"] is None
    assert d["delay_independent"] is True and d["windows"] == [[0.0, 100.0]]


def test_unstable_at_zero_is_not_an_error(run_cli, tmp_path):
    p = write(tmp_path, "[delay_system]\nA0 = [[1.0]]\nA = [[[-0.5]]]\n")
    status, out, _ = run_cli(p, "--json")
    d = json.loads(out)
    assert status == 0 and d["h_max"] == 0.0 and d["stable_at_zero"] is False
    status, out, _ = run_cli(p)
    assert status == 0 and "unstable at h = 0" in out


def test_neutral_and_words(run_cli, tmp_path):
    p = write(tmp_path, "[delay_system]\nA0 = [[-1.0]]\nA = [[[-2.0]]]\nB = [[[0.5]]]\n")
    status, out, _ = run_cli(p, "--method", "kronecker")
    assert status == 0 and out.startswith("h_max = 0.785398163") and "confirmed" in out


def test_plot(run_cli, tmp_path):
    out = tmp_path / "m.png"
    status, _, err = run_cli(EXAMPLE, "--plot", out, "--h-range", "0,8")
    assert status == 0 and out.stat().st_size > 1000
    assert err == f"backlashkit: wrote {out}\n"  # as control and simulate say it
    status, _, err = run_cli(EXAMPLE, "--plot", out)
    assert status == 2 and "already exists; pass --force" in err


@pytest.mark.parametrize(
    "text, args, message",
    [
        ("[delay_system]\nA0 = [[1.0, 2.0]]\nA = [[[1.0]]]\n", (),
         "A0 must be a square matrix; got shape (1, 2)"),
        ("[delay_system]\nA0 = [[-1.0, 0.0], [0.0, -1.0]]\nA = [[[1.0]]]\n", (),
         "A[0] (delay 1 h) has shape (1, 1); it must match A0, which is 2x2"),
        ("[delay_system]\nA0 = [[-1.0]]\nA = [[[-0.5]]]\nB = [[[1.0]]]\n", (),
         "the neutral difference operator is not strongly stable"),
        ("[delay_system]\nA0 = [[-1.0]]\nA = [[[nan]]]\n", (), "A[0] (delay 1 h)[0, 0] is nan"),
        ("[delay_system]\nA0 = [[-1.0]]\n", (), "[delay_system] needs A"),
        ("[other]\n", (), "no [delay_system] table"),
        ("[delay_system]\nA0 = [[-1.0]]\nA = [[[-2.0]]]\n", ("--h-range", "3,1"),
         "--h-range must be finite with 0 <= lo < hi"),
        ("[delay_system]\nA0 = [[-1.0]]\nA = [[[-2.0]]]\n", ("--h-range", "1"),
         "--h-range must be two numbers LO,HI in s"),
        ("[delay_system]\nA0 = [[-1.0]]\nA = [[[-2.0]]]\n", ("--plot", "x.txt"),
         "--plot x.txt: the file name must end in .png"),
    ],
)
def test_one_line_errors_exit_2(run_cli, tmp_path, text, args, message):
    p = write(tmp_path, text)
    status, out, err = run_cli(p, *args)
    assert status == 2 and out == ""
    assert err.startswith("backlashkit: error: ") and err.count("\n") == 1
    assert message in err


def test_a_neutral_system_unstable_for_every_delay_says_why_in_json(run_cli, tmp_path):
    """h_max 0 with stable_at_zero true and no reason: the radius is the reason. At
    h = 0, -0.5 x' = 0.5 x is stable; B = 1.5 makes it unstable for every h > 0."""
    p = write(tmp_path, "[delay_system]\nA0 = [[1.0]]\nA = [[[-0.5]]]\nB = [[[1.5]]]\n")
    status, out, _ = run_cli(p, "--json")
    d = json.loads(out)
    assert status == 0 and d["h_max"] == 0.0 and d["stable_at_zero"] is True
    assert d["difference_radius"] == pytest.approx(1.5)


def test_the_neutral_refusal_names_the_file(run_cli, tmp_path):
    p = write(tmp_path, "[delay_system]\nA0 = [[-1.0]]\nA = [[[-0.5]]]\nB = [[[1.0]]]\n")
    status, _, err = run_cli(p)
    assert status == 2 and f"backlashkit: error: {p}: " in err  # it said "B: ..." alone


def test_missing_file(run_cli, tmp_path):
    status, _, err = run_cli(tmp_path / "nope.toml")
    assert status == 2 and "file not found" in err


def test_control_reports_the_linear_loop_delay_margin(capsys):
    """``backlashkit control SCENARIO.toml --json`` carries the delay margin of its linear
    model-reference loop, delay at the plant input (equal to PM/omega_c)."""
    from backlashkit.cli import main
    from backlashkit.control.scenario import load_scenario
    from backlashkit.delay.loops import mrc_delay_system, siso_delay_margin

    scenario = EXAMPLE.parent / "tao1995.toml"
    assert main(["control", str(scenario), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)["delay_margin"]
    design = load_scenario(scenario).run().design
    plant, ctrl, _ = mrc_delay_system(design)
    assert d["h_max"] == pytest.approx(siso_delay_margin(plant, ctrl, sign=+1.0)[0], rel=1e-9)
    assert d["stable_at_zero"] is True
