"""HTML identification report (``backlashkit.identify.report``)."""

from __future__ import annotations

import argparse
import math
from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli.report import add_report_option, maybe_write_report
from backlashkit.errors import InputError
from backlashkit.identify import Record, RegressionIdentifier, TwoStepIdentifier
from backlashkit.identify.plots import (
    autocorrelation,
    fit_percent,
    plot_commutation,
    plot_cost,
    plot_profile,
    plot_residual_acf,
    plot_speed_fit,
)
from backlashkit.identify.report import write_identification_report
from backlashkit.identify.two_step import cost_curve

P = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
PRIOR = bk.TwoMassDrive(**P)
TRUE = PRIOR.with_theta(3.49e-2)
A = 0.942


@pytest.fixture(scope="module")
def record() -> Record:
    """A step-down from the steady state at t_s = 1 s, 2 s after it, 30 dB noise."""
    t = signals.time_grid(3.0, 1e-3)
    u = signals.step_down(t, A, t_s=1.0)
    r = TRUE.simulate(t, u, initial_state=TRUE.steady_state(A))
    sm, sl = np.random.SeedSequence(7).spawn(2)
    return Record(t, u, signals.add_noise(r.w_motor, 30, rng=sm),
                  signals.add_noise(r.w_load, 30, rng=sl), name="exp<1>.csv")


@pytest.fixture(scope="module")
def fitted(record) -> TwoStepIdentifier:
    return TwoStepIdentifier(PRIOR, n_grid=11, workers=2).fit(record)


class _Checker(HTMLParser):
    """Balanced tags, and every src/href collected."""

    VOID = {"meta", "img", "br", "hr", "link", "input"}

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.links: list[str] = []
        self.doctype = False
        self.text: list[str] = []

    def handle_decl(self, decl):
        self.doctype = decl.lower() == "doctype html"

    def handle_starttag(self, tag, attrs):
        if tag not in self.VOID:
            self.stack.append(tag)
        self.links += [v for k, v in attrs if k in ("src", "href")]

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, (tag, self.stack[-5:])
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def check_page(index: Path) -> str:
    page = index.read_text(encoding="utf-8")
    checker = _Checker()
    checker.feed(page)
    checker.close()
    assert checker.doctype and not checker.stack
    assert checker.links
    for link in checker.links:
        assert "://" not in link and not link.startswith(("/", "//", "data:")), link
        assert (index.parent / link).is_file(), link
    assert "<script" not in page and "stylesheet" not in page
    return page


def test_two_step_report(tmp_path, record, fitted):
    out = tmp_path / "report"
    index = write_identification_report(out, [record], fitted, prior=PRIOR)
    assert index == out / "index.html"
    page = check_page(index)
    for stem in ("fit", "commutation", "cost", "residual_acf"):
        assert (out / f"{stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert b"<svg" in (out / f"{stem}.svg").read_bytes()[:2000]
    assert f"{fitted.theta_:.5g}" in page
    assert f"{fitted.theta_ini_:.5g}" in page
    assert f"{math.degrees(fitted.theta_):.4g}" in page
    assert f"{fitted.t_c_[0]:.4f}" in page and f"{fitted.t_b_[0]:.4f}" in page
    assert f"{fitted.bounds_[0]:.5g}" in page and f"{fitted.bounds_[1]:.5g}" in page
    assert "exp&lt;1&gt;.csv" in page  # names are escaped
    assert "n/a" not in page and "gives no standard error" in page  # none for this method
    assert "<td></td>" not in page
    # the fit in the table is the NRMSE fit of the model with the estimate
    assert "fit w_M (%)" in page

    # refusal without force, then overwrite with it
    with pytest.raises(InputError) as exc:
        write_identification_report(out, [record], fitted, prior=PRIOR)
    msg = str(exc.value)
    assert "\n" not in msg and "index.html" in msg and "force" in msg
    write_identification_report(out, [record], fitted, prior=PRIOR, force=True)


def test_regression_report_and_intervals(tmp_path, record):
    est = RegressionIdentifier(PRIOR, n_grid=11, workers=2).fit(record)
    est.std_ = 1.5e-3
    est.ci95_ = (est.theta_ - 2.9e-3, est.theta_ + 2.9e-3)
    page = check_page(write_identification_report(tmp_path / "r", record, est, prior=PRIOR))
    assert not (tmp_path / "r" / "commutation.png").exists()  # no t_c / t_b: no zoom
    assert f"{est.theta_:.5g}" in page and "0.0015" in page
    assert f"{est.ci95_[0]:.5g}, {est.ci95_[1]:.5g}" in page


def test_duck_typed_result_and_errors(tmp_path, record):
    result = SimpleNamespace(theta_=0.03, std_=None, ci95_=None)
    page = check_page(write_identification_report(tmp_path / "d", record, result, prior=PRIOR))
    assert "0.03" in page and "n/a" not in page and "gives no standard error" in page
    with pytest.raises(InputError, match="theta_"):
        write_identification_report(tmp_path / "e", record, SimpleNamespace(), prior=PRIOR)
    with pytest.raises(InputError, match="prior"):
        write_identification_report(tmp_path / "e", record, result, prior="drive.toml")
    afile = tmp_path / "afile"
    afile.write_text("x")
    with pytest.raises(InputError, match="not a directory"):
        write_identification_report(afile, record, result, prior=PRIOR)


def test_missing_commutation_instants_skip_the_zoom(tmp_path, record):
    """A joint fit whose model has no contact change after the step-down (t_c_ None):
    the report is written without the commutation zoom."""
    result = SimpleNamespace(theta_=0.03, std_=None, ci95_=None, t_c_=[None], t_b_=[None])
    check_page(write_identification_report(tmp_path / "n", record, result, prior=PRIOR))
    assert not (tmp_path / "n" / "commutation.png").exists()


def test_profile_section_and_interval_name(tmp_path, record):
    profile = np.array([[0.0285, 3.9], [0.03, 0.0], [0.0322, 3.7]])
    result = SimpleNamespace(theta_=0.03, std_=1e-3, ci95_=(0.0285, 0.0322),
                             interval_="profile", profile_=profile, t_c_=[None], t_b_=[None])
    page = check_page(write_identification_report(tmp_path / "p", record, result, prior=PRIOR))
    assert "95 % interval of theta (profile likelihood)" in page and "0.0322" in page
    assert "Profile likelihood of theta" in page and (tmp_path / "p" / "profile.png").is_file()
    result.profile_ = None  # other intervals: no section
    page = check_page(write_identification_report(tmp_path / "q", record, result, prior=PRIOR))
    assert "Profile likelihood" not in page and not (tmp_path / "q" / "profile.png").exists()


def test_cost_curve_matches_identifier(record, fitted):
    c = cost_curve(PRIOR, record, [fitted.theta_], workers=1)
    assert c[0] == pytest.approx(fitted.cost_, rel=1e-9)


def test_numbers():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)
    assert math.isnan(fit_percent(np.ones(3), np.zeros(3)))
    rng = np.random.default_rng(0)
    r = autocorrelation(rng.standard_normal(4000), 20)
    assert r[0] == 1.0 and np.all(np.abs(r[1:]) < 4 / math.sqrt(4000))
    with pytest.raises(InputError, match="max_lag"):
        autocorrelation(y, 4)


def test_plot_helpers_take_ax_and_return_figure(record, fitted):
    from matplotlib.figure import Figure

    fig = Figure()
    axes = fig.subplots(5)
    t = record.t[:100]
    assert plot_speed_fit(t, record.w_motor[:100], record.w_motor[:100], ax=axes[0]) is fig
    assert plot_commutation(record, fitted.t_c_[0], fitted.t_b_[0], ax=axes[1]) is fig
    assert plot_cost([0.0, 0.01, 0.02], [3.0, 1.0, 2.0], theta=0.01, theta_ini=0.011,
                     bounds=(0.009, 0.013), ax=axes[2]) is fig
    assert plot_residual_acf(record.w_motor - record.w_motor.mean(), ts=record.ts,
                             ax=axes[3]) is fig
    assert plot_profile([[0.01, 1.0], [0.02, 0.0], [0.03, 4.0]], ci95=(0.012, 0.029),
                        ax=axes[4]) is fig
    assert isinstance(plot_cost([0.0, 0.01], [1.0, 2.0]), Figure)
    # an estimate whose interval reaches 0: the Fisher parabola in theta from 0, not in
    # log theta (flat at 0 about an estimate of 1e-14 rad)
    near = plot_profile([[0.0, 0.5], [1e-14, 0.0], [2e-5, 3.9]], ci95=(0.0, 2e-5),
                        theta=1e-14, std=1e-5).axes[0]
    x, y = near.lines[0].get_data()
    assert x[0] == 0.0 and np.interp(1.96e-5 * 180 / np.pi, x, y) == pytest.approx(3.84,
                                                                                 rel=0.01)
    # a QA pass: the load's residual was titled the motor-speed residual's, and a
    # malformed profile or measured speeds failed in NumPy's or matplotlib's words
    title = plot_residual_acf(record.w_load - record.w_load.mean(), ts=record.ts,
                              label="w_L - w_L,sim").axes[0].get_title()
    assert title.startswith("Autocorrelation of the residual w_L - w_L,sim"), title
    with pytest.raises(InputError, match=r"profile must be rows \(theta in rad, cost "
                                         r"rise\), shape \(k, 2\), got shape \(3,\)"):
        plot_profile([1.0, 2.0, 3.0])
    drive = bk.TwoMassDrive(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=5e-3, f_L=5e-3,
                            f_sh=1.575e-2, theta=0.0349)
    t = signals.time_grid(0.2, 1e-3)
    r = drive.simulate(t, signals.step_down(t, 0.942, t_s=0.1))
    with pytest.raises(InputError, match=r"measured must hold 2 speed arrays, one per "
                                         r"inertia, each of 201 samples .* got one array "
                                         r"of shape \(201,\)"):
        r.plot(measured=r.w_motor)


def test_cli_hook(tmp_path, record, capsys):
    parser = add_report_option(argparse.ArgumentParser())
    result = SimpleNamespace(theta_=0.02)
    args = parser.parse_args([])
    assert args.report is None and args.force is False
    assert maybe_write_report(args, [record], result, PRIOR) is None
    args = parser.parse_args(["--report", str(tmp_path / "cli")])
    index = maybe_write_report(args, [record], result, PRIOR)
    assert index is not None and index.is_file()
    assert capsys.readouterr().err == f"backlashkit: wrote {index}\n"  # says where
    with pytest.raises(InputError, match="--force"):
        maybe_write_report(args, [record], result, PRIOR)
    args = parser.parse_args(["--report", str(tmp_path / "cli"), "--force"])
    assert maybe_write_report(args, [record], result, PRIOR) == index


def test_noise_model_note(tmp_path, record):
    """The joint estimator's page names its noise model and repeats its warning."""
    result = SimpleNamespace(theta_=0.03, std_=1e-3, ci95_=(0.028, 0.032), interval_="fisher",
                             t_c_=[None], t_b_=[None], noise_ar_=None,
                             residual_lag1_=np.array([[0.004, -0.002]]),
                             correlation_message=lambda: None)
    page = check_page(write_identification_report(tmp_path / "w", record, result, prior=PRIOR))
    assert "Noise model: white." in page and "largest lag-1 correlation is 0.004" in page
    result.noise_ar_ = np.zeros((1, 2, 3))
    result.correlation_message = lambda: "the residual of w_L in exp (record 1) has lag-1 x"
    page = check_page(write_identification_report(tmp_path / "a", record, result, prior=PRIOR))
    assert "Noise model: autoregressive of order 3." in page
    assert "<b>Note:</b> the residual of w_L in exp (record 1) has lag-1 x." in page


def test_notes_and_the_prior_as_read(tmp_path, record):
    """The page lists the command's notes on the answer, and the prior as the fit read
    it: its Coulomb torques where it gives them, and the relative stds (a QA pass found
    both missing)."""
    prior = bk.TwoMassDrive(**P, fc_M=0.013, fc_L=0.02)
    result = SimpleNamespace(theta_=0.03, prior_rel_std={"k_sh": 0.1, "fc_M": 0.01})
    notes = ["the data pull fc_M 9.2 standard deviations from the prior's values <sic>"]
    page = check_page(write_identification_report(tmp_path / "n", record, result,
                                                  prior=prior, notes=notes))
    assert ("<h2>Notes</h2><ul class=\"note\"><li>the data pull fc_M 9.2 standard "
            "deviations from the prior&#x27;s values &lt;sic&gt;</li></ul>") in page
    assert "fc_M = 0.013, fc_L = 0.02; relative stds k_sh 0.1, fc_M 0.01." in page
    page = check_page(write_identification_report(tmp_path / "e", record, result,
                                                  prior=PRIOR))
    assert "<h2>Notes</h2>" not in page and "fc_M =" not in page
