"""The fleet's wear report: one HTML page a plant engineer reads at a glance.

Sections, in order: the drives to look at (flagged by :mod:`backlashkit.fleet.wear`),
the fleet's wear rates with their intervals, the distribution of the latest backlash,
``theta`` over time per drive with its 95 % intervals and trend line, every drive's
trend, and the refused tests with their reasons. Figures are matplotlib ``Figure``
objects (no pyplot state), PNG shown and SVG linked (:mod:`backlashkit.htmlpage`).
"""

from __future__ import annotations

import datetime as dt
import html
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..htmlpage import figure, page, save_figure, table
from .wear import GROWTH_THRESHOLD, MIN_TREND_TESTS, DriveTrend, wear_trends

__all__ = ["check_report_dir", "plot_drives", "plot_rates", "plot_theta_distribution",
           "write_wear_report"]

#: Panels per figure of ``theta`` over time (4 columns): a page of 24 stays legible.
PANELS_PER_FIGURE = 24
_COLS = 4
_FLAG, _OK = "#b3261e", "#1f77b4"
#: Written into every wear report: a folder holding one may be written over.
MARKER = "<!-- backlashkit fleet wear report -->"


def check_report_dir(out_dir: str | Path, *, force: bool = False) -> Path:
    """Refuse, before any fit, a report folder that cannot take the wear report.

    A missing folder (in an existing one), an empty one, or one holding an earlier wear
    report (written over: the report of a completed rerun replaces the last one) is
    fine; anything else needs ``force``.

    Parameters
    ----------
    out_dir : str or pathlib.Path
        The folder.
    force : bool, optional
        Write into a folder holding other files (default False).

    Returns
    -------
    pathlib.Path
        The folder.

    Raises
    ------
    InputError
        If ``out_dir`` is a file, its parent does not exist, or it holds files that are
        not a wear report and ``force`` is False.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--report {out} exists and is not a directory")
    if not out.exists() and not out.parent.is_dir():
        raise InputError(f"--report {out}: directory {out.parent} does not exist (create it, "
                         "or write elsewhere)")
    index = out / "index.html"
    ours = index.is_file() and MARKER in index.read_text(encoding="utf-8", errors="replace")
    if out.exists() and any(out.iterdir()) and not ours and not force:
        raise InputError(f"--report {out} holds other files than a wear report; give "
                         "another folder or pass --force to write into it")
    return out


def _figure(width: float, height: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout="constrained")


def plot_rates(trends: Sequence[DriveTrend], *, ax=None):
    """Each drive's wear rate with its 95 % interval, sorted, flagged drives in red.

    Parameters
    ----------
    trends : sequence of DriveTrend
        From :func:`backlashkit.fleet.wear_trends`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default a new figure's).

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding ``ax``.
    """
    shown = sorted((t for t in trends if not math.isnan(t.slope)), key=lambda t: t.slope)
    if ax is None:
        ax = _figure(8.0, 1.2 + 0.18 * max(len(shown), 4)).subplots()
    y = np.arange(len(shown))
    for flagged, colour, label in ((False, _OK, "trend"), (True, _FLAG, "flagged drive")):
        idx = [i for i, t in enumerate(shown) if t.flagged == flagged]
        if not idx:
            continue
        s = np.array([shown[i].slope for i in idx]) * 1e3
        lo = np.array([shown[i].ci95_low for i in idx]) * 1e3
        hi = np.array([shown[i].ci95_high for i in idx]) * 1e3
        err = np.vstack([s - lo, hi - s])
        # too few tests give no interval: the legend then promises none
        said = ("Theil-Sen, Sen's 95 % interval" if np.isfinite(err).any() else
                f"Theil-Sen; no interval below {MIN_TREND_TESTS} tests")
        ax.errorbar(s, y[idx], xerr=np.nan_to_num(err), fmt="o", ms=4, color=colour,
                    capsize=2, label=f"{label} ({said})")
    ax.axvline(0.0, color="0.5", lw=0.8)
    ax.set_yticks(y, [t.drive for t in shown], fontsize=7 if len(shown) > 30 else 9)
    ax.set_xlabel("growth of the backlash half-width theta (mrad per year)")
    ax.set_title("Wear rate per drive")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=8)
    return ax.figure


def plot_theta_distribution(trends: Sequence[DriveTrend], *, ax=None):
    """Histogram of each drive's backlash at its last test (on its trend line).

    Parameters
    ----------
    trends : sequence of DriveTrend
        From :func:`backlashkit.fleet.wear_trends`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default a new figure's).

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding ``ax``.
    """
    if ax is None:
        ax = _figure(7.0, 3.2).subplots()
    first = np.array([t.theta_first for t in trends]) * 1e3
    last = np.array([t.theta_last for t in trends]) * 1e3
    bins = np.histogram_bin_edges(np.concatenate([first, last]), bins="auto")
    ax.hist(first, bins=bins, color="0.7", label="at the first test")
    ax.hist(last, bins=bins, histtype="step", lw=2, color=_FLAG, label="at the last test")
    ax.set_xlabel("backlash half-width theta (mrad)")
    ax.set_ylabel("drives")
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # drives come whole
    ax.set_title(f"The fleet's backlash ({len(trends)} drives, trend line values)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=8)
    return ax.figure


def _panel(ax, trend: DriveTrend | None, rows: list[Mapping[str, Any]]) -> None:
    import matplotlib.dates as mdates

    days = [dt.date.fromisoformat(str(r["date"])) for r in rows]
    theta = np.array([r["theta"] for r in rows]) * 1e3
    err = np.vstack([theta - np.array([r["ci95_low"] for r in rows]) * 1e3,
                     np.array([r["ci95_high"] for r in rows]) * 1e3 - theta])
    flagged = trend is not None and trend.flagged
    ax.errorbar(days, theta, yerr=np.clip(err, 0.0, None), fmt="o", ms=3, capsize=2,
                color=_FLAG if flagged else _OK, label="estimate, 95 % interval")
    if trend is not None and not math.isnan(trend.slope):
        ax.plot([trend.first, trend.last], [trend.theta_first * 1e3, trend.theta_last * 1e3],
                "k-", lw=1, label="Theil-Sen trend")
        rate = f"{trend.slope * 1e3:+.2f} mrad/yr"
    else:
        rate = "no trend"
    drive = rows[0]["drive"]
    ax.set_title(f"{drive}: {rate}", fontsize=9, color=_FLAG if flagged else "black")
    locator = mdates.AutoDateLocator(maxticks=5)
    ax.xaxis.set_major_locator(locator)
    ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    ax.tick_params(labelsize=7)


def plot_drives(trends: Sequence[DriveTrend], rows: Sequence[Mapping[str, Any]]):
    """``theta`` over time per drive, with 95 % intervals and the trend line.

    Parameters
    ----------
    trends : sequence of DriveTrend
        The drives to draw, in order (at most :data:`PANELS_PER_FIGURE` per figure).
    rows : sequence of mapping
        The results rows (refused ones are left out).

    Returns
    -------
    list of matplotlib.figure.Figure
        One figure per :data:`PANELS_PER_FIGURE` drives.
    """
    ok: dict[str, list[Mapping[str, Any]]] = {}
    for r in rows:
        if r["status"] == "ok" and r["theta"] is not None:
            ok.setdefault(str(r["drive"]), []).append(r)
    figs = []
    for k in range(0, len(trends), PANELS_PER_FIGURE):
        chunk = trends[k:k + PANELS_PER_FIGURE]
        cols = min(_COLS, len(chunk))  # fewer drives fill the width, no blank panels
        n_rows = math.ceil(len(chunk) / cols)
        fig = _figure(10.0, 0.6 + 2.0 * n_rows)
        axes = np.atleast_1d(fig.subplots(n_rows, cols, squeeze=False)).ravel()
        for ax, trend in zip(axes, chunk, strict=False):
            _panel(ax, trend, sorted(ok[trend.drive], key=lambda r: str(r["date"])))
        for ax in axes[len(chunk):]:
            ax.set_visible(False)
        for ax in axes[::cols]:
            ax.set_ylabel("theta (mrad)", fontsize=8)
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncols=2, frameon=False,
                   fontsize=8)
        fig.suptitle(f"Backlash half-width over time, drives {k + 1}-{k + len(chunk)} "
                     "(red: flagged)")
        figs.append(fig)
    return figs


def _fmt(x: float, scale: float = 1e3, spec: str = ".2f") -> str:
    return "-" if x is None or math.isnan(x) else format(x * scale, spec)


def _why(t: DriveTrend, growth_threshold: float) -> str:
    out = []
    if t.significant:
        out.append("trend significant")
    if t.grew:
        out.append(f"grew more than {growth_threshold * 1e3:g} mrad")
    return ", ".join(out)


def _trend_rows(trends: Sequence[DriveTrend], growth_threshold: float) -> list[list[Any]]:
    return [[t.drive, t.n_tests, f"{t.first} to {t.last}", _fmt(t.slope),
             _interval(t), _fmt(t.theta_first), _fmt(t.theta_last), _fmt(t.growth),
             (_why(t, growth_threshold), "miss") if t.flagged else "none"] for t in trends]


def _interval(t: DriveTrend) -> str:
    """Sen's interval in mrad/yr, or why there is none."""
    if math.isnan(t.ci95_low) or math.isnan(t.ci95_high):
        return f"needs {MIN_TREND_TESTS} tests"
    return f"[{_fmt(t.ci95_low)}, {_fmt(t.ci95_high)}]"


def write_wear_report(
    results: Sequence[Mapping[str, Any]],
    out_dir: str | Path,
    *,
    growth_threshold: float = GROWTH_THRESHOLD,
    rate_threshold: float = 0.0,
    title: str = "Backlash across the fleet",
) -> Path:
    """Write the wear report (``index.html`` and its figures) into ``out_dir``.

    Parameters
    ----------
    results : sequence of mapping
        Rows of :func:`backlashkit.fleet.identify_fleet` or
        :func:`backlashkit.fleet.read_results`.
    out_dir : str or pathlib.Path
        Folder for the page and figures (made if missing; its parent must exist).
    growth_threshold : float, optional
        Growth in rad beyond which a drive is flagged
        (:func:`backlashkit.fleet.wear_trends`).
    rate_threshold : float, optional
        Rate in rad per year a significant trend lies above (default 0).
    title : str, optional
        Page title.

    Returns
    -------
    pathlib.Path
        The ``index.html`` written.

    Raises
    ------
    InputError
        If ``out_dir`` is a file or its parent does not exist, or a row or threshold is
        refused by :func:`backlashkit.fleet.wear_trends`.
    """
    rows = [r for r in results if r is not None]
    trends = wear_trends(rows, growth_threshold=growth_threshold,
                         rate_threshold=rate_threshold)  # refused before any file changes
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"out_dir {out} exists and is not a directory")
    if not out.exists() and not out.parent.is_dir():
        raise InputError(f"out_dir {out}: directory {out.parent} does not exist (create it, "
                         "or write elsewhere)")
    out.mkdir(exist_ok=True)
    for old in (*out.glob("drives_*.png"), *out.glob("drives_*.svg")):
        old.unlink()  # an earlier report's panels: the fleet may have shrunk
    flagged = sorted((t for t in trends if t.flagged), key=lambda t: -np.nan_to_num(t.slope))
    refused = [r for r in rows if r["status"] != "ok"]
    header = ("drive", "tests", "dates", "rate (mrad/yr)", "95 % interval", "first (mrad)",
              "last (mrad)", "growth (mrad)", "flag")
    sections = [
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{len(rows)} tests of {len({r['drive'] for r in rows})} drives: "
        f"{len(rows) - len(refused)} identified, {len(refused)} refused. "
        f"<b>{len(flagged)} drive(s) flagged</b>: the 95 % interval of the wear rate above "
        f"{rate_threshold * 1e3:g} mrad per year, or a growth of the half-width beyond "
        f"{growth_threshold * 1e3:g} mrad. Rates are Theil-Sen slopes with Sen's 95 % "
        "interval (needs at least 5 tests).</p>",
        "<h2>Drives to look at, fastest wear first</h2>",
        table(header, _trend_rows(flagged, growth_threshold)) if flagged
        else "<p>None.</p>",
    ]
    if trends:
        sections += ["<h2>Wear rates</h2>",
                     figure(save_figure(plot_rates(trends), out, "rates"),
                            "Wear rate of every drive with its 95 % interval"),
                     "<h2>The fleet's backlash</h2>",
                     figure(save_figure(plot_theta_distribution(trends), out, "distribution"),
                            "Distribution of the half-width at the first and last test")]
        order = flagged + [t for t in trends if not t.flagged]
        sections.append("<h2>Backlash over time, flagged drives first</h2>")
        for k, fig in enumerate(plot_drives(order, rows)):
            sections.append(figure(save_figure(fig, out, f"drives_{k + 1}"),
                                   "Half-width estimates with 95 % intervals and trend"))
        sections += ["<h2>Every drive</h2>", table(header, _trend_rows(trends,
                                                                        growth_threshold))]
    sections.append("<h2>Refused tests</h2>")
    sections.append(table(("drive", "date", "reason"),
                          [[r["drive"], r["date"], r["reason"]] for r in refused])
                    if refused else "<p>None.</p>")
    target = out / "index.html"
    target.write_text(page(title, [MARKER, *sections]), encoding="utf-8")
    return target
