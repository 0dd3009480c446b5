"""Shared test set-up."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_limits


@pytest.fixture(scope="session", autouse=True)
def _one_blas_thread():
    """One BLAS thread per test process: ``pytest -n auto`` already runs one process per
    core, and more threads than cores make the joint fits several times slower (the
    same reason as :mod:`backlashkit._parallel`)."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield
