"""Reproduction of paper B's example (Tao & Kokotović 1995, Section IV, Figs. 5-6).

``G(s) = 1/((s-1.5)(s+1))``, ``Lambda = (s+2)^2``, ``W_m = 1/((s+2)(s+3))``, true
backlash ``m = 0.7, c_r = 1.3, c_l = -0.5``, ``Gamma = 5 I``,
``theta_b(0) = (1.51, 0.2, -0.55)``, ``r = 10 sin(1.3 t)``, 60 s, four variants: the
exact adaptive inverse (Fig. 5), the filtered inverse with ``alpha = 6`` (Fig. 6), the
fixed controller alone and the adaptive gain only (the two comparisons of the text).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..control.adaptive import AdaptiveLaw
from ..control.closed_loop import ClosedLoopResponse, SumOfSines, simulate_closed_loop
from ..nonlinearities import (
    Backlash,
    ExactInverse,
    GainOnlyInverse,
    NoInverse,
    SmoothFilterInverse,
)

__all__ = ["LABELS", "PAPER", "checks", "run_tao1995", "summary", "write_report"]

#: The paper's numbers (Section IV).
PAPER: dict[str, Any] = {
    "plant": ([1.0], [1.0, -0.5, -1.5]),
    "reference_model": [1.0, 5.0, 6.0],
    "filter": [1.0, 4.0, 4.0],
    "backlash": (0.7, 1.3, -0.5),
    "theta_b_star": (0.91, 0.7, -0.35),
    "gamma": 5.0,
    "theta_b0": (1.51, 0.2, -0.55),
    "reference": ([10.0], [1.3]),
    "duration": 60.0,
    "controller": (-32.25, -5.5, -78.375, -76.375, 1.0),
}

VARIANTS = {
    "exact": ExactInverse(),
    "smooth-filter": SmoothFilterInverse(alpha=6.0),
    "none": NoInverse(),
    "gain-only": GainOnlyInverse(),
}

#: The name of each variant wherever a reader sees it (checks, legends, page).
LABELS = {
    "exact": "exact adaptive inverse",
    "smooth-filter": "smooth inverse (alpha = 6)",
    "none": "fixed controller, no inverse",
    "gain-only": "adaptive gain only",
}


def run_tao1995(
    *, ts: float = 0.01, step: float | None = None, backend: str = "rust",
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, ClosedLoopResponse]:
    """Run the four variants of paper B's example.

    Parameters
    ----------
    ts : float
        Trace sample time in s.
    step : float, optional
        Largest integration step in s (default ``min(ts, 1e-3)``).
    backend : {"rust", "numpy"}
        Kernel.
    progress : callable, optional
        ``progress(done, total)`` before the first variant and after every one (e.g. a
        :class:`~backlashkit.parallel.ProgressBar`).

    Returns
    -------
    dict of str to ClosedLoopResponse
        Keyed ``exact``, ``smooth-filter``, ``none``, ``gain-only``.
    """
    b = Backlash(*PAPER["backlash"])
    law = AdaptiveLaw(gamma=PAPER["gamma"], theta_b0=PAPER["theta_b0"], m0=0.02)
    ref = SumOfSines(*PAPER["reference"])
    runs: dict[str, ClosedLoopResponse] = {}
    if progress is not None:
        progress(0, len(VARIANTS))
    for name, inv in VARIANTS.items():
        runs[name] = simulate_closed_loop(
            PAPER["plant"],
            b,
            reference=ref,
            duration=PAPER["duration"],
            ts=ts,
            step=step,
            inverse=inv,
            adaptation=law,
            reference_model=PAPER["reference_model"],
            filter=PAPER["filter"],
            backend=backend,
        )
        if progress is not None:
            progress(len(runs), len(VARIANTS))
    return runs


def checks(runs: dict[str, ClosedLoopResponse]) -> list[tuple[str, str, bool]]:
    """The reproduction's bars: the paper's tracking and convergence, and the two
    comparisons of its text.

    Parameters
    ----------
    runs : dict of str to ClosedLoopResponse
        As returned by :func:`run_tao1995`.

    Returns
    -------
    list of tuple of (str, str, bool)
        ``(bar, measured value, met)``.
    """
    ex, sm = runs["exact"], runs["smooth-filter"]
    star = PAPER["theta_b_star"]
    rel = max(abs(a - b) / abs(b) for a, b in zip(ex.theta_b[-1], star, strict=True))
    last = "RMS tracking error over the last 20 s"
    return [
        (
            f"{LABELS['exact']}: {last} <= 1e-3",
            f"{ex.rms_error_last():.3e}",
            ex.rms_error_last() <= 1e-3,
        ),
        (f"{LABELS['exact']}: backlash estimates within 1 % of (0.91, 0.7, -0.35)",
         f"{100 * rel:.3f} %", rel <= 0.01),
        (
            f"{LABELS['smooth-filter']}: {last} <= 2e-2",
            f"{sm.rms_error_last():.3e}",
            sm.rms_error_last() <= 2e-2,
        ),
        (
            f"{LABELS['none']}: {last} >= 0.5",
            f"{runs['none'].rms_error_last():.3g}",
            runs["none"].rms_error_last() >= 0.5,
        ),
        (
            f"{LABELS['gain-only']}: {last} >= 0.5",
            f"{runs['gain-only'].rms_error_last():.3g}",
            runs["gain-only"].rms_error_last() >= 0.5,
        ),
    ]


def summary(runs: dict[str, ClosedLoopResponse]) -> dict[str, Any]:
    """The reproduction as a JSON-ready document.

    Parameters
    ----------
    runs : dict of str to ClosedLoopResponse
        As returned by :func:`run_tao1995`.

    Returns
    -------
    dict
        ``controller`` (the designed gains), ``variants`` (each run's summary),
        ``paper`` (its ``theta_b_star`` and controller) and ``checks`` (each bar of
        :func:`checks` with its measured value and whether it is met).
    """
    return {
        "controller": runs["exact"].summary()["controller"],
        "variants": {k: r.summary() for k, r in runs.items()},
        "paper": {
            "theta_b_star": list(PAPER["theta_b_star"]),
            "controller": list(PAPER["controller"]),
        },
        "checks": [{"bar": b, "value": v, "met": bool(m)} for b, v, m in checks(runs)],
    }


def write_report(directory: str | os.PathLike[str],
                 runs: dict[str, ClosedLoopResponse]) -> Path:
    """Write the reproduction's HTML report into ``directory``.

    ``index.html`` (the bars of :func:`checks` and Figs. 5-6), the figures (PNG, SVG)
    and one trace CSV per controller variant.

    Parameters
    ----------
    directory : str or os.PathLike
        Output directory, created if absent; its files of these names are overwritten.
    runs : dict of str to ClosedLoopResponse
        As returned by :func:`run_tao1995`.

    Returns
    -------
    pathlib.Path
        Path of ``index.html``.
    """
    from ..control.closed_loop import write_trace
    from ..htmlpage import (
        bars_table,
        figure,
        page,
        save_figure,
    )

    rep = Path(directory)
    rep.mkdir(parents=True, exist_ok=True)
    for name, stem, fig_no in (("exact", "fig5_exact_inverse", 5),
                               ("smooth-filter", "fig6_smooth_inverse_alpha6", 6)):
        fig = runs[name].plot()
        fig.axes[0].set_title(f"Paper B's Fig. {fig_no}: closed loop with the {LABELS[name]}")
        save_figure(fig, rep, stem)
    save_figure(_plot_comparison(runs), rep, "comparison")
    for name, r in runs.items():
        write_trace(rep / f"trace_{name}.csv", r)
    traces = ", ".join(f'<a href="trace_{n}.csv">{LABELS[n]}</a>' for n in runs)
    sections = [
        "<h1>Tao &amp; Kokotović (1995), Section IV: reproduced</h1>",
        '<p class="note">Plant G(s) = 1/((s-1.5)(s+1)) behind a backlash with slope m = 0.7 '
        "and break points c_r = 1.3, c_l = -0.5; reference r = 10 sin(1.3 t) for 60 s. "
        f"Four controllers: the {LABELS['exact']} (the paper's Fig. 5), the "
        f"{LABELS['smooth-filter']} (Fig. 6), the {LABELS['none']} and the "
        f"{LABELS['gain-only']} (the two comparisons of the paper's text). Closed-loop "
        f"traces as CSV: {traces}.</p>",
        "<h2>Checks against the paper</h2>",
        bars_table(checks(runs)),
        f"<h2>Fig. 5: {LABELS['exact']}</h2>",
        figure("fig5_exact_inverse", f"Closed loop with the {LABELS['exact']}"),
        f"<h2>Fig. 6: {LABELS['smooth-filter']}</h2>",
        figure("fig6_smooth_inverse_alpha6", f"Closed loop with the {LABELS['smooth-filter']}"),
        "<h2>The four controllers compared</h2>",
        figure("comparison", "Tracking error e = y - y_m and backlash input v (the control "
               "signal before the backlash) of each controller"),
    ]
    index = rep / "index.html"
    index.write_text(page("Tao & Kokotović (1995): reproduction", sections), encoding="utf-8")
    return index


def _plot_comparison(runs: dict[str, ClosedLoopResponse]) -> Any:
    """The tracking error and the backlash input of every variant, one colour each."""
    from matplotlib.figure import Figure

    from ..report import legend_outside

    fig = Figure(figsize=(9, 6), layout="constrained")
    axs = fig.subplots(2, 1, sharex=True)
    for name, r in runs.items():
        axs[0].plot(r.t, r.e, label=LABELS[name], lw=0.8)
        axs[1].plot(r.t, r.v, label=LABELS[name], lw=0.8)
    axs[0].set_ylabel("error e = y - y_m\n(symmetric log scale)")
    axs[0].set_yscale("symlog", linthresh=1e-4)
    axs[0].set_title("Tracking error and backlash input of the four controllers")
    legend_outside(axs[0])
    axs[1].set_ylabel("v, backlash input")
    axs[1].set_xlabel("t [s]")
    return fig
