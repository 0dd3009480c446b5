"""Backlash across a fleet: identify every drive's weekly tests, track wear over time.

* :func:`generate_fleet` writes demo and test data: drives of paper A's model wearing at
  drive-specific rates, a step-down test per week, priors and a manifest.
* :func:`read_manifest` reads and checks ``MANIFEST.csv`` (one row per test).
* :func:`identify_fleet` identifies every test with the default method on any executor
  (:mod:`backlashkit.parallel`: serial, a local process pool, a Dask cluster), writing
  one row per test as it finishes and completing an interrupted run.
* :func:`wear_trends` gives each drive's wear rate (Theil-Sen, rad per year, 95 %
  interval) and flags; :func:`write_wear_report` the HTML page.

The command line is ``backlashkit fleet MANIFEST.csv --out RESULTS.csv``.
"""

from __future__ import annotations

from .generate import FleetTruth, generate_fleet
from .identify import identify_fleet, identify_test
from .manifest import MANIFEST_COLUMNS, FleetTest, Manifest, read_manifest
from .report import write_wear_report
from .results import RESULT_COLUMNS, ResultsFile, read_results
from .wear import DriveTrend, wear_trends

__all__ = [
    "DriveTrend",
    "FleetTest",
    "FleetTruth",
    "MANIFEST_COLUMNS",
    "Manifest",
    "RESULT_COLUMNS",
    "ResultsFile",
    "generate_fleet",
    "identify_fleet",
    "identify_test",
    "read_manifest",
    "read_results",
    "wear_trends",
    "write_wear_report",
]
