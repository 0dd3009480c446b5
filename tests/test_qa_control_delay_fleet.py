"""Bad input found by a QA pass over paper B's control, the delay margins and the
fleet: each is refused in one line that names the parameter and what to do, before any
memory is taken or any file is written, never in NumPy's, Python's or the kernel's
words, and never answered silently wrong."""

from __future__ import annotations

import datetime as dt
import shutil

import numpy as np
import pytest

import backlashkit as bk
from backlashkit.cli import main
from backlashkit.control.discrete import simulate_discrete_loop
from backlashkit.delay import read_delay_system
from backlashkit.errors import InputError
from backlashkit.fleet import generate_fleet, read_manifest, wear_trends, write_wear_report

G = ([1.0], [1.0, -0.5, -1.5])
GAP = bk.Backlash(m=0.7, c_r=1.3, c_l=-0.5)
REF = bk.SumOfSines([10.0], [1.3])
A0, A1 = np.diag([-2.0, -0.9]), np.array([[-1.0, 0.0], [-1.0, -1.0]])


@pytest.mark.parametrize("kwargs, said", [
    ({"duration": 1.0, "step": 1e-9}, r"duration / step gives 1e\+09 integration steps "
                                       r"\(step 1e-09 s, given\), more than 20,000,000"),
    ({"duration": 4e5, "ts": 0.1}, r"duration / step gives 4e\+08 integration steps \(step "
                                    r"0.001 s, the default, min\(ts, 1 ms\)\)"),
    ({"duration": 1e6}, r"duration / ts gives 1e\+08 output samples, more than 5,000,000"),
    ({"duration": 1.0, "ts": 0.3}, r"duration must be a whole number of ts = 0.3 s \(the run "
                                    r"would stop at 0.9 s\), got 1.0: give duration = 0.9"),
])
def test_a_closed_loop_too_long_or_off_its_grid_is_refused_before_it_runs(kwargs, said):
    """A step of 1e-9 s took all of the machine's memory until the kernel killed the
    process; a duration that is no whole number of ts stopped short without a word."""
    with pytest.raises(InputError, match=said):
        bk.simulate_closed_loop(G, GAP, reference=REF, **kwargs)


def test_the_discrete_loops_length_and_divergence_are_said():
    ctrl = bk.DiscreteAdaptiveController(G, ts=0.5)
    with pytest.raises(InputError, match=r"duration must be >= the controller's ts = 0.5 s"):
        simulate_discrete_loop(G, GAP, ctrl, reference=REF, duration=0.2)
    with pytest.raises(InputError, match=r"duration / ts gives 2e\+09 output samples"):
        simulate_discrete_loop(G, GAP, ctrl, reference=REF, duration=1e9)
    # it flooded stderr with NumPy's overflow warnings and answered y of 1e180; then,
    # over 60 s, a finite error of 2.7e56 without a word (a second QA pass)
    for duration in (200.0, 60.0):
        with pytest.raises(InputError, match=r"the simulation diverged \(the plant output "
                                             r"reached \S+, over 1e\+06 times the reference's "
                                             r"largest value\) at t = \d+(\.\d+)? s; the "
                                             r"controller's sample time ts = 0.5 s may be too "
                                             r"long"):
            simulate_discrete_loop(G, GAP, ctrl, reference=REF, duration=duration)


@pytest.mark.parametrize("backend", ["rust", "numpy"])
def test_a_continuous_loop_that_runs_away_with_finite_values_is_refused(backend):
    """An adaptation gain of 1e4 grows the output past 1e7 (the reference's largest
    value is 10) while every value stays finite: it was answered without a word."""
    with pytest.raises(InputError, match=r"the simulation diverged \(the plant output "
                                         r"reached \S+, over 1e\+06 times the reference's "
                                         r"largest value\) at t = \d+(\.\d+)? s; check .* "
                                         r"gamma among them\), or give a smaller step"):
        bk.simulate_closed_loop(G, GAP, reference=REF, duration=60.0, backend=backend,
                                adaptation=bk.AdaptiveLaw(gamma=1e4))
    # a disturbance that grows the output 2.5e5 times the reference is no runaway
    bk.simulate_closed_loop(G, GAP, reference=REF, duration=60.0, backend=backend,
                            input_disturbance=lambda t: 1e4 * t)


def test_a_smooth_filter_faster_than_the_step_is_refused_before_the_run():
    """alpha = 5000 with the default 1 ms step diverged and was blamed on the units.
    The filter is a first-order lag integrated by classical Runge-Kutta, stable up to
    alpha * step = 2.785 (``control.problem.RK4_REAL_STABILITY``): 2 700 runs, 2 900
    diverged and is now refused before the run."""
    bk.simulate_closed_loop(G, GAP, reference=REF, duration=1.0,
                            inverse=bk.SmoothFilterInverse(2700.0))
    with pytest.raises(InputError, match=r"SmoothFilterInverse\(alpha=2900.0\) with the "
                                         r"integration step 0.001 s: alpha \* step = 2.9 is "
                                         r"beyond the integration's stability .* give step "
                                         r"<= 0.00096 s"):
        bk.simulate_closed_loop(G, GAP, reference=REF, duration=1.0,
                                inverse=bk.SmoothFilterInverse(2900.0))


def test_a_diverging_run_names_the_integration_step():
    """A plant pole at -5000 rad/s diverges at the default 1 ms step: the message used to
    blame the parameters' units alone."""
    fast = ([5000.0], np.poly([-1.0, -5000.0]))
    with pytest.raises(InputError, match=r"diverged .*or give a smaller step \(now 0.001 s\): "
                                         r"a fast part \(a plant pole"):
        bk.simulate_closed_loop(fast, GAP, reference=REF, duration=5.0)


@pytest.mark.parametrize("call, said", [
    (lambda: bk.simulate_closed_loop(G, GAP, reference=REF, duration=1.0, adaptation={}),
     "adaptation must be an AdaptiveLaw, got dict"),
    (lambda: bk.simulate_closed_loop(G, GAP, reference=REF, duration=1.0, inverse="exact"),
     r"inverse must be an InverseKind \(ExactInverse\(\), .*\), got str 'exact'; for a "
     r"name, inverse_from_name\('exact'\)"),
    (lambda: bk.DiscreteAdaptiveController(G, ts=1e-3, adaptation={}),
     "adaptation must be an AdaptiveLaw, got dict"),
    (lambda: bk.DiscreteAdaptiveController(G, ts=1e-3, design="x"),
     r"design must be an MRCDesign \(from design_mrc\), got str"),
    (lambda: bk.simulate_closed_loop(G, GAP, reference=REF, duration=1.0,
                                     output_noise=lambda t: np.zeros(3)),
     r"output_noise\(t\) must give one value per time of t \(shape \(1001,\)\) or one for "
     r"all, got shape \(3,\)"),
    (lambda: bk.AdaptiveLaw(gamma="5"), "gamma must be real numbers, got '5'"),
    (lambda: bk.AdaptiveLaw(gamma=True), "gamma must be real numbers, got True"),
    (lambda: bk.AdaptiveLaw(theta_b0=None), "theta_b0 must be real numbers, got None"),
    (lambda: bk.SumOfSines("10", "1.3"), "amplitude must be real numbers, got '10'"),
    (lambda: bk.design_mrc((["a"], [1.0, 2.0])), "plant numerator must be real numbers"),
    (lambda: bk.design_mrc(([[1.0], [2.0]], [1.0, 2.0])),
     r"plant numerator must be one list of coefficients .*got shape \(2, 1\)"),
    (lambda: simulate_discrete_loop(G, GAP, bk.DiscreteAdaptiveController(G, ts=1e-3),
                                    reference=REF, duration=0.1, use_r_dot="no"),
     "use_r_dot must be True or False, got 'no'"),
])
def test_control_arguments_of_the_wrong_kind_are_named(call, said):
    """They ended in AttributeError, NumPy's broadcasting error or "could not convert
    string to float", or were read as numbers ("5", True) or as true ("no")."""
    with pytest.raises(InputError, match=said):
        call()


def test_the_error_summaries_and_the_plot_check_their_arguments():
    loop = bk.simulate_closed_loop(G, GAP, reference=REF, duration=2.0)
    for fraction in (-1.0, 0.0, 2.0, np.nan, "0.5"):
        with pytest.raises(InputError, match="fraction must"):
            loop.rms_error_last(fraction)
        with pytest.raises(InputError, match="fraction must"):
            loop.max_abs_error_last(fraction)
    assert loop.rms_error_last(1.0) > 0
    with pytest.raises(InputError, match="ax must be matplotlib Axes, got int"):
        loop.plot(ax=5)  # it ended in "'int' object has no attribute 'plot'"


@pytest.mark.parametrize("a0, said", [
    (A0 + 1j, "A0 must be a real matrix of numbers, got an array of complex128"),
    ([["-2.0", 0.0], [0.0, -0.9]], "A0 must be a real matrix of numbers, got '-2.0'"),
    ([[True, 0.0], [0.0, -0.9]], "A0 must be a real matrix of numbers, got True"),
])
def test_a_delay_matrix_of_strings_bools_or_complex_numbers_is_refused(a0, said):
    """The imaginary part was dropped with NumPy's warning; "-2.0" and True were read as
    numbers."""
    with pytest.raises(InputError, match=said):
        bk.delay_margin(a0, [A1])


def test_the_delay_margins_options_and_ranges_are_checked():
    result = bk.delay_margin(A0, [A1])
    for h_range in ("0,10", (0,), 10):
        with pytest.raises(InputError, match=r"h_range must be two delays \(lo, hi\) in s"):
            result.stability_windows(h_range)
    # 1e9 s ran for minutes, the time linear in the range
    with pytest.raises(InputError, match=r"h_range up to 1e\+09 s holds about 6.9\de\+07 "
                                         r"delays .* more than 100,000: give a shorter range"):
        result.stability_windows((0.0, 1e9))
    for n_h in ("a", 0):
        with pytest.raises(InputError, match="n_h must be an integer >= 2"):
            result.plot(n_h=n_h)
    with pytest.raises(InputError, match="n_omega must be an integer from 10 to 1,000,000"):
        bk.delay_margin(A0, [A1], n_omega=10**9)  # a MemoryError
    with pytest.raises(InputError, match="polish must be True or False, got 'no'"):
        bk.delay_margin(A0, [A1], polish="no")


def test_a_delay_system_file_that_is_a_folder_or_holds_other_tables(tmp_path):
    with pytest.raises(InputError, match="is a directory; give a TOML file"):
        read_delay_system(tmp_path)
    path = tmp_path / "sys.toml"
    path.write_text("[delay_system]\nA0 = [[-1.0]]\nA = [[[-0.5]]]\n[other]\nx = 1\n")
    with pytest.raises(InputError, match=r"unknown top-level key\(s\) or table\(s\) other"):
        read_delay_system(path)


def test_a_scenario_that_is_a_folder_is_named_so(tmp_path, capsys):
    assert main(["control", str(tmp_path)]) == 2
    assert "is a directory; give a TOML file" in capsys.readouterr().err


def test_the_control_command_does_not_write_its_trace_over_its_scenario(tmp_path, capsys):
    scenario = tmp_path / "in.toml"
    shutil.copy("examples/tao1995.toml", scenario)
    before = scenario.read_bytes()
    assert main(["control", str(scenario), "--trace", str(scenario), "--force"]) == 2
    assert "--trace " + str(scenario) + " is the scenario file; choose another name" in (
        capsys.readouterr().err)
    assert scenario.read_bytes() == before


@pytest.mark.parametrize("kwargs, said", [
    ({"snr1": (1.0,)}, r"snr1 must be two SNRs in dB, \(w_M, w_L\), each within \+-300"),
    ({"hold": 1e6}, r"hold must be at most 10000 s \(each record is 2 hold at 0.001 s"),
    ({"seed": None}, "seed must be an integer >= 0, a numpy.random.SeedSequence or"),
    ({"start": "2026-01-05x"}, r"start must be a date, datetime.date\(2026, 1, 5\) or "
                               r"'2026-01-05', got '2026-01-05x'"),
])
def test_a_fleet_is_refused_before_any_file_is_written(tmp_path, kwargs, said):
    """A bad snr1 or hold was refused after drive-001's PRIOR.toml was written (and the
    retry then refused for it), in IndexError's or time_grid's words."""
    out = tmp_path / "fleet"
    with pytest.raises(InputError, match=said):
        generate_fleet(1, 1, out=out, **{"seed": 1, **kwargs})
    assert not out.exists()


def test_a_fleet_starts_on_an_iso_date(tmp_path):
    truth = generate_fleet(1, 2, seed=1, out=tmp_path / "f", start="2026-02-02", hold=3.0)
    assert truth.dates == [dt.date(2026, 2, 2), dt.date(2026, 2, 9)]


def test_fleet_files_and_rows_are_checked(tmp_path):
    with pytest.raises(InputError, match="is a directory; give the manifest's CSV file"):
        read_manifest(tmp_path)
    manifest = tmp_path / "MANIFEST.csv"
    manifest.write_text("drive,date,records,prior\nd1,2026-01-05,a.csv,p.toml,extra\n")
    with pytest.raises(InputError, match=r"line 2: more fields than the header has columns"):
        read_manifest(manifest)
    ok = {"drive": "d1", "date": "2026-01-05", "status": "ok", "theta": 0.03}
    for rows, said in (([{"drive": "d1"}], "results row 0: missing date, status, theta"),
                       ([{**ok, "date": "5 Jan"}], "results row 0: date '5 Jan' is not an ISO"),
                       ([{**ok, "theta": np.nan}], "results row 0: theta must be finite")):
        with pytest.raises(InputError, match=said):
            wear_trends(rows)
    with pytest.raises(InputError, match="growth_threshold must be >= 0, got -1"):
        wear_trends([ok], growth_threshold=-1)
    with pytest.raises(InputError, match="directory .*nodir does not exist"):
        write_wear_report([ok], tmp_path / "nodir" / "report")


def test_results_of_control_and_the_fleet_print_short(tmp_path):
    """MRCDesign printed every polynomial (about 400 characters), FleetTruth every
    drive's parameters (about 800 with np.float64(...)), DriveTrend np.float64(...)."""
    design = bk.design_mrc(G)
    assert repr(design) == ("MRCDesign(n=2, n*=2, theta_1 and theta_2 [-32.25, -5.5, "
                            "-78.375, -76.375], theta_3=1)")
    truth = generate_fleet(2, 3, seed=1, out=tmp_path / "f", hold=3.0)
    assert repr(truth).startswith("FleetTruth(2 drives, 3 weekly tests from 2026-01-05")
    rows = [{"drive": "a", "date": f"2026-01-0{k + 1}", "status": "ok", "theta": 0.03 + k * 1e-3}
            for k in range(5)]
    trend = repr(wear_trends(rows)[0])
    assert trend.startswith("DriveTrend('a', 5 tests 2026-01-01 to 2026-01-05, slope ")
    assert "np.float64" not in trend and len(trend) < 160
