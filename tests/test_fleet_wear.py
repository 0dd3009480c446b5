"""Wear trends (Theil-Sen with Sen's interval) and the wear report."""

from __future__ import annotations

import datetime as dt
import math
from html.parser import HTMLParser

import numpy as np
import pytest
from scipy.stats import kendalltau

from backlashkit.errors import InputError
from backlashkit.fleet import wear_trends, write_wear_report
from backlashkit.fleet.report import check_report_dir

START = dt.date(2026, 1, 5)


def _rows(drive, rate, n, *, sigma=2e-4, seed=0, theta0=0.035):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        day = START + dt.timedelta(days=7 * k)
        th = theta0 + rate * 7 * k / 365.25 + sigma * rng.standard_normal()
        out.append({"drive": drive, "date": day.isoformat(), "status": "ok", "theta": th,
                    "std": sigma, "ci95_low": th - 2 * sigma, "ci95_high": th + 2 * sigma,
                    "reason": ""})
    return out


def test_exact_line_gives_its_slope():
    (t,) = wear_trends(_rows("a", 0.01, 8, sigma=0.0))
    assert t.slope == pytest.approx(0.01, rel=1e-9)
    assert t.ci95_low == pytest.approx(0.01, rel=1e-9)
    assert t.growth == pytest.approx(0.01 * 49 / 365.25, rel=1e-9)
    assert t.significant


def test_interval_is_sens_and_a_wild_test_does_not_move_the_slope():
    rows = _rows("a", 0.02, 12, seed=3)
    clean = wear_trends(rows)[0]
    rows[5] = {**rows[5], "theta": 0.08}  # a fit in a wrong basin
    wild = wear_trends(rows)[0]
    assert abs(wild.slope - clean.slope) < 0.2 * (clean.ci95_high - clean.ci95_low)
    # Sen's interval independently: the pairwise slopes of ranks (N -+ z sd(S)) / 2
    x = np.array([7 * k / 365.25 for k in range(12)])
    y = np.array([r["theta"] for r in _rows("a", 0.02, 12, seed=3)])
    i, j = np.triu_indices(12, 1)
    slopes = np.sort((y[j] - y[i]) / (x[j] - x[i]))
    n_pairs = slopes.size
    sd = math.sqrt(12 * 11 * 29 / 18)
    lo = slopes[int(round((n_pairs - 1.959963984540054 * sd) / 2)) - 1]
    hi = slopes[int(round((n_pairs + 1.959963984540054 * sd) / 2))]
    assert clean.ci95_low == pytest.approx(lo, rel=1e-12)
    assert clean.ci95_high == pytest.approx(hi, rel=1e-12)
    assert kendalltau(x, y).statistic > 0


def test_flags_and_small_samples():
    rows = (_rows("fast", 0.05, 10, seed=1) + _rows("still", 0.0, 10, seed=2)
            + _rows("few", 0.05, 4, seed=3))
    rows.append({"drive": "still", "date": "2026-06-01", "status": "refused", "theta": None,
                 "reason": "file not found"})
    trends = {t.drive: t for t in wear_trends(rows)}
    assert trends["fast"].flagged and trends["fast"].significant
    assert not trends["still"].flagged and trends["still"].n_tests == 10
    assert math.isnan(trends["few"].ci95_low) and not trends["few"].significant
    big = {t.drive: t for t in wear_trends(rows, growth_threshold=1.0, rate_threshold=1.0)}
    assert not big["fast"].flagged


def test_the_rates_legend_promises_an_interval_only_where_one_is_drawn():
    """Drives of too few tests have a slope and no interval: the legend said
    "Sen's 95 % interval" beside markers without bars (a QA pass)."""
    from backlashkit.fleet.report import plot_rates

    few = wear_trends(_rows("few", 0.05, 4, seed=3) + _rows("some", 0.01, 3, seed=4))
    assert all(math.isnan(t.ci95_low) for t in few)
    labels = [t.get_text() for t in plot_rates(few).axes[0].get_legend().get_texts()]
    assert labels and all(label.endswith("(Theil-Sen; no interval below 5 tests)")
                          for label in labels), labels
    # two drives: two panels side by side, none left blank (a QA pass)
    from backlashkit.fleet.report import plot_drives

    rows = _rows("few", 0.05, 4, seed=3) + _rows("some", 0.01, 3, seed=4)
    (fig,) = plot_drives(few, rows)
    assert [ax.get_visible() for ax in fig.axes] == [True, True]
    many = wear_trends(_rows("many", 0.05, 10, seed=1))
    labels = [t.get_text() for t in plot_rates(many).axes[0].get_legend().get_texts()]
    assert labels == ["flagged drive (Theil-Sen, Sen's 95 % interval)"], labels


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.text = [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("img", "a") and (a.get("src") or a.get("href")):
            self.links.append(a.get("src") or a.get("href"))

    def handle_data(self, data):
        self.text.append(data)


def test_report_has_every_section_and_its_files(tmp_path):
    rows = (_rows("drive-001", 0.05, 10, seed=1) + _rows("drive-002", 0.0, 10, seed=2)
            + [{"drive": "drive-003", "date": "2026-01-05", "status": "refused",
                "theta": None, "reason": "file not found: x.csv"}])
    page = write_wear_report(rows, tmp_path / "rep")
    parser = _Links()
    parser.feed(page.read_text(encoding="utf-8"))
    text = " ".join(parser.text)
    for words in ("Drives to look at, fastest wear first", "Wear rates", "The fleet's backlash",
                  "Backlash over time", "Refused tests", "file not found: x.csv",
                  "1 drive(s) flagged"):
        assert words in text, words
    assert parser.links and all((tmp_path / "rep" / link).is_file() for link in parser.links)
    # a rerun writes over its own report; another folder's files need force
    check_report_dir(tmp_path / "rep")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "keep.txt").write_text("x")
    with pytest.raises(InputError, match="other files"):
        check_report_dir(tmp_path / "other")
    check_report_dir(tmp_path / "other", force=True)
