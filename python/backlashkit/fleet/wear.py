"""Wear of each drive: the trend of its backlash over time, with a 95 % interval.

**Why Theil-Sen.** The slope of each drive is the Theil-Sen estimator (the median of
the slopes between every pair of tests), its 95 % interval Sen's (1968), from the ranks
of those pairwise slopes (:func:`scipy.stats.theilslopes`). Weighted least squares with
the fits' standard errors would be the efficient choice if those errors were exact and
every fit landed in the right basin; neither is guaranteed: where the shaft rattles the
joint fit's interval is too narrow (95 % coverage measured at 89.8 % over 324 trials,
README, "Away from paper A's drive"), and a fit can settle in a wrong minimum
(``JointIdentifier.ambiguous_``). Theil-Sen needs neither: its interval comes from the
scatter of the estimates themselves, and up to 29 % of the tests can be wild without
moving the slope (its breakdown point). It assumes the scatter of a drive's tests
independent and alike, which holds for one drive tested the same way every week.
``benchmarks/fleet_trend_coverage.py`` measures how often the interval covers the true
rate on generated fleets.

Rates are in rad per year (the half-width ``theta``'s growth; a year of 365.25 days).
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from .generate import DAYS_PER_YEAR

__all__ = ["DriveTrend", "GROWTH_THRESHOLD", "MIN_TREND_TESTS", "TREND_COLUMNS", "wear_trends"]

#: Default growth of the half-width, rad, between a drive's first and last test (on its
#: trend line) beyond which the drive is flagged: 3.5e-3 rad, a tenth of paper A's
#: 3.49e-2 rad half-width.
GROWTH_THRESHOLD = 3.5e-3
#: Fewest tests for a trend interval. Sen's interval takes the pairwise slopes of
#: ranks ``(N -+ 1.96 sd(S)) / 2`` (``N = n (n - 1) / 2``, ``sd(S)`` Kendall's); below 5
#: tests these ranks fall at or beyond the extreme slopes (n = 4: 0.1 of 6; n = 3: below
#: 0), and SciPy then returns the extremes, an interval far from 95 %.
MIN_TREND_TESTS = 5
#: Confidence of the trend interval.
CONFIDENCE = 0.95


@dataclass(frozen=True)
class DriveTrend:
    """The wear trend of one drive.

    Attributes
    ----------
    drive : str
        Drive id.
    n_tests : int
        Identified tests (status ``ok``) the trend rests on.
    first, last : datetime.date
        Dates of the first and last of them.
    slope : float
        Theil-Sen growth rate of ``theta`` in rad per year (NaN with fewer than 2 tests).
    ci95_low, ci95_high : float
        Sen's 95 % interval of the slope in rad per year (NaN with fewer than
        :data:`MIN_TREND_TESTS` tests).
    theta_first, theta_last : float
        ``theta`` in rad on the trend line at ``first`` and ``last``.
    growth : float
        ``theta_last - theta_first`` in rad.
    significant : bool
        The interval lies above the rate threshold (the backlash grows for sure).
    grew : bool
        ``growth`` exceeds the growth threshold.
    """

    drive: str
    n_tests: int
    first: dt.date
    last: dt.date
    slope: float
    ci95_low: float
    ci95_high: float
    theta_first: float
    theta_last: float
    growth: float
    significant: bool
    grew: bool

    def __repr__(self) -> str:
        # floats as floats (the fields hold NumPy's), the dates as ISO dates
        return (f"DriveTrend({self.drive!r}, {self.n_tests} tests {self.first} to "
                f"{self.last}, slope {float(self.slope):.4g} rad/yr [95 %: "
                f"{float(self.ci95_low):.4g}, {float(self.ci95_high):.4g}], growth "
                f"{float(self.growth):.4g} rad, flagged={self.flagged})")

    @property
    def flagged(self) -> bool:
        """Whether the drive needs a look: a significant trend or too much growth.

        Returns
        -------
        bool
            True if ``significant`` or ``grew``.
        """
        return self.significant or self.grew


def _trend(drive: str, dates: list[dt.date], theta: list[float], growth_threshold: float,
           rate_threshold: float) -> DriveTrend:
    from scipy.stats import theilslopes

    order = np.argsort(np.array([d.toordinal() for d in dates]))
    days = np.array([dates[i].toordinal() for i in order], float)
    y = np.array([theta[i] for i in order])
    x = (days - days[0]) / DAYS_PER_YEAR
    nan = math.nan
    if len(y) >= 2 and x[-1] > 0:
        slope, intercept, low, high = (float(a) for a in
                                       theilslopes(y, x, alpha=CONFIDENCE))
    else:
        slope, intercept, low, high = nan, (float(y[0]) if len(y) else nan), nan, nan
    if len(y) < MIN_TREND_TESTS:
        low = high = nan
    first = intercept
    last = intercept + slope * x[-1] if len(y) >= 2 else first
    growth = last - first
    return DriveTrend(drive, len(y), dates[order[0]], dates[order[-1]], slope, low, high,
                      first, last, growth, bool(low > rate_threshold),
                      bool(growth > growth_threshold))


#: The columns of a results row that :func:`wear_trends` reads.
TREND_COLUMNS = ("drive", "date", "status", "theta")


def _day(k: int, day: Any) -> dt.date:
    """A row's date: a ``datetime.date`` or an ISO 8601 string."""
    if isinstance(day, dt.date):
        return day.date() if isinstance(day, dt.datetime) else day
    try:
        return dt.date.fromisoformat(str(day))
    except ValueError:
        raise InputError(f"results row {k}: date {day!r} is not an ISO 8601 date (write "
                         "e.g. 2026-01-05)") from None


def wear_trends(
    results: Iterable[Mapping[str, Any]],
    *,
    growth_threshold: float = GROWTH_THRESHOLD,
    rate_threshold: float = 0.0,
) -> list[DriveTrend]:
    """The wear trend of every drive from the fleet's results.

    Parameters
    ----------
    results : iterable of mapping
        Rows of :func:`backlashkit.fleet.identify_fleet` or
        :func:`backlashkit.fleet.read_results` (``drive``, ``date``, ``status``,
        ``theta``); refused tests are left out.
    growth_threshold : float, optional
        Growth of ``theta`` in rad over a drive's tests beyond which it is flagged
        (default :data:`GROWTH_THRESHOLD`).
    rate_threshold : float, optional
        Rate in rad per year that the trend's 95 % interval must lie above to be
        significant (default 0: any growth).

    Returns
    -------
    list of DriveTrend
        One per drive with at least one identified test, in order of first appearance.

    Raises
    ------
    InputError
        If a threshold is not a finite number (``growth_threshold`` >= 0), or a row
        misses a column of :data:`TREND_COLUMNS`, has a date that is no ISO date or an
        identified ``theta`` that is not finite.
    """
    v.nonnegative("growth_threshold", growth_threshold)
    v.finite_scalar("rate_threshold", rate_threshold)
    by_drive: dict[str, tuple[list[dt.date], list[float]]] = {}
    for k, row in enumerate(results):
        missing = [c for c in TREND_COLUMNS if c not in row]
        if missing:
            raise InputError(f"results row {k}: missing {', '.join(missing)}; a row of "
                             "identify_fleet or read_results has them")
        if row["status"] != "ok" or row["theta"] is None:
            continue
        dates, thetas = by_drive.setdefault(str(row["drive"]), ([], []))
        dates.append(_day(k, row["date"]))
        thetas.append(v.finite_scalar(f"results row {k}: theta", row["theta"]))
    return [_trend(d, dates, thetas, growth_threshold, rate_threshold)
            for d, (dates, thetas) in by_drive.items()]
