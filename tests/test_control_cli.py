"""``backlashkit control`` and the ``reproduce tao1995`` runner."""

import json
from pathlib import Path

import numpy as np
import pytest

from backlashkit.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "tao1995.toml"
COLUMNS = "t,r,y,y_m,e,u_d,v,u,mc_r_hat,m_hat,mc_l_hat"


def test_control_json_trace_plot(tmp_path, capsys):
    trace, plot = tmp_path / "tr.csv", tmp_path / "f.png"
    assert (
        main(["control", str(EXAMPLE), "--json", "--trace", str(trace), "--plot", str(plot)]) == 0
    )
    doc = json.loads(capsys.readouterr().out)
    # Paper B, Section IV: theta_1 = (-32.25, -5.5), theta_2 = (-78.375, -76.375), theta_3 = 1
    # (solved in floating point: a last-bit difference between machines is not an error)
    assert doc["controller"]["theta_1"] == pytest.approx([-32.25, -5.5], rel=1e-12)
    assert doc["controller"]["theta_2"] == pytest.approx([-78.375, -76.375], rel=1e-12)
    assert doc["controller"]["theta_3"] == pytest.approx(1.0, rel=1e-12)
    assert doc["rms_error_last"] <= 1e-3
    np.testing.assert_allclose(doc["theta_b_final"], [0.91, 0.7, -0.35], rtol=0.01)
    assert doc["inverse"] == "exact" and doc["inverse_parameters"] == {}
    assert trace.read_text().splitlines()[0] == COLUMNS
    data = np.loadtxt(trace, delimiter=",", skiprows=1)
    assert data.shape == (6001, 11)
    np.testing.assert_allclose(np.diff(data[:, 0]), 0.01, atol=1e-9)
    assert plot.stat().st_size > 1000
    # no overwrite without --force
    assert main(["control", str(EXAMPLE), "--trace", str(trace)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["control", str(EXAMPLE), "--inverse", "gain-only", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rms_error_last"] >= 0.5


def test_a_gain_of_zero_is_printed_without_its_sign(tmp_path, capsys):
    """A first-order plant whose pole is the reference model's solves theta_2 = -0.0,
    which the summary printed as ``[-0]`` (a QA pass)."""
    text = EXAMPLE.read_text()
    for old, new in (("den = [1.0, -0.5, -1.5]", "den = [1.0, 5.0]"),
                     ("den = [1.0, 5.0, 6.0]", "den = [1.0, 5.0]"),
                     ("den = [1.0, 4.0, 4.0]", "den = [1.0, 4.0]")):
        assert old in text
        text = text.replace(old, new)
    scenario = tmp_path / "first_order.toml"
    scenario.write_text(text)
    assert main(["control", str(scenario)]) == 0
    out = capsys.readouterr().out
    assert "theta_1 = [0], theta_2 = [0], theta_3 = 1" in out, out


@pytest.mark.parametrize(
    "edit, needle",
    [
        (("m = 0.7", "m = -0.7"), "[backlash] m must be > 0"),
        (("den = [1.0, 5.0, 6.0]", "den = [1.0, 5.0]"), "A2"),
        (("num = [1.0]", "num = [1.0, -3.0]"), "A1"),
        (("gamma = 5.0", 'gamma = "big"'), "[adaptation] gamma must be a number"),
        (("duration = 60.0", "duration = 0.0"), "[simulation] duration must be > 0"),
        (("frequency = [1.3]  # rad/s", "frequency = [1.3, 2.0]"), "same length"),
        (("c_l = -0.5", "c_l = 0.5"), "[backlash] c_l must be <= 0"),
        (("ts = 0.01", "tss = 0.01"), "unknown key"),
        (("gamma = 5.0", "gama = 5.0"), "[adaptation] has unknown key(s) gama (did you mean "
                                        "gamma?)"),
        (('kind = "exact"', 'kind = "magic"'), "[inverse] kind must be one of"),
        (("[plant]", "[plant\n"), "not valid TOML"),
        (("theta_b0 = [1.51, 0.2, -0.55]", "theta_b0 = [1.51, 0.2, -0.55, 1.0]"),
         "[adaptation] theta_b0 must be a list of exactly 3 numbers"),
        (("theta_b0 = [1.51, 0.2, -0.55]", "theta_b0 = [1.51, 0.2]"),
         "[adaptation] theta_b0 must be a list of exactly 3 numbers"),
        (("num = [1.0]", "num = [0.0]"), "must not be the zero polynomial, got [0.0]"),
    ],
)
def test_bad_scenarios_one_line_errors(tmp_path, capsys, edit, needle):
    text = EXAMPLE.read_text()
    assert edit[0] in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    assert main(["control", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("backlashkit: error:")
    assert needle in err


def test_reproduce_runner(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["reproduce", "tao1995", "--json-out", str(out), "--report",
                 str(tmp_path / "rep")]) == 0
    doc = json.loads(out.read_text())
    assert set(doc["variants"]) == {"exact", "smooth-filter", "none", "gain-only"}
    for v in doc["variants"].values():
        assert {"controller", "theta_b_final", "rms_error_last", "max_abs_error_last"} <= set(v)
    assert doc["variants"]["smooth-filter"]["rms_error_last"] <= 2e-2
    rep = tmp_path / "rep"
    assert {"fig5_exact_inverse.png", "fig5_exact_inverse.svg", "comparison.svg",
            "trace_exact.csv", "index.html"} <= {p.name for p in rep.iterdir()}
    page = (rep / "index.html").read_text(encoding="utf-8")
    assert 'src="fig6_smooth_inverse_alpha6.png"' in page and "MET" in page
    assert "MISSED" not in page  # the runner returned 0: every bar met
    capsys.readouterr()
    assert main(["reproduce", "tao1995", "--json-out", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err


def test_a_reference_file_is_refused_where_it_cannot_drive_the_run(tmp_path, capsys):
    """A reference file shorter than the run (held at its last value, the error then
    measured against a constant), one of three columns, or one separated by ';' (read
    as one column) is refused, naming the file (a QA pass found all three answered or
    refused in general words)."""
    text = EXAMPLE.read_text()
    start = text.index("[reference]")
    end = text.index("\n[", start + 1)
    scenario = text[:start] + '[reference]\nfile = "ref.csv"\n' + text[end:]
    bad = tmp_path / "bad.toml"
    bad.write_text(scenario)
    t = np.linspace(0.0, 10.0, 101)
    rows = "".join(f"{a:.17g},{b:.17g}\n" for a, b in zip(t, np.sin(t), strict=True))
    cases = (("t,r\n" + rows,
              "[reference] file: the reference table ends at t = 10 s, before the run's end "
              "at duration = 60 s"),
             ("t,r,x\n0,0,0\n60,1,0\n", "has 3 columns; give two, t and r"),
             ("t;r\n0;0\n60;1\n", "its first line holds ';': the columns are separated by "
                                  "',' here"))
    for body, needle in cases:
        (tmp_path / "ref.csv").write_text(body)
        assert main(["control", str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("backlashkit: error:"), err
        assert needle in err, err


def test_a_run_refused_by_the_library_names_the_scenario_and_its_keys(tmp_path, capsys):
    """What the library refuses at run time names the scenario file and the tables'
    keys to change (a QA pass: "give step <= ...", no file, no table)."""
    bad = tmp_path / "fast.toml"
    bad.write_text(EXAMPLE.read_text().replace("alpha = 6.0", "alpha = 5000.0", 1))
    assert main(["control", str(bad), "--inverse", "smooth-filter"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("backlashkit: error: fast.toml: SmoothFilterInverse(alpha=5000.0)"), err
    assert "give [simulation] step <= 0.000557 s or a smaller [inverse] alpha" in err, err
