"""Shared test set-up."""

from __future__ import annotations

from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread():
    """One BLAS thread per test process: ``pytest -n auto`` already runs one process per
    core, and more threads than cores make the joint fits several times slower (the
    same reason as :mod:`backlashkit.parallel`)."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


@pytest.fixture(scope="session")
def short_csv(tmp_path_factory):
    """The short experiment as a CSV file: paper A's drive, 0.942 N m from rest for 2 s,
    then 0; 4 s at Ts = 1 ms, 30 dB on both speeds (``backlashkit simulate``)."""
    from backlashkit.cli import main

    path = tmp_path_factory.mktemp("short") / "exp.csv"
    assert main(["simulate", str(EXAMPLES / "paper_drive.toml"), "--experiment", "step-down",
                 "--amplitude", "0.942", "--hold", "2", "--snr-motor", "30", "--snr-load",
                 "30", "--seed", "1", "--out", str(path)]) == 0
    return path
