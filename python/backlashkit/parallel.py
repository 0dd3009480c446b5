"""Process pools for the studies (``reproduce``, the benchmarks): one BLAS thread each.

Every worker's NumPy would otherwise start one OpenBLAS thread per core, so ``jobs``
workers on ``jobs`` cores run ``jobs`` squared busy threads. The Gauss-Newton products
``J^T J`` of the joint fit (320 010 x 7 on paper A's records) gain nothing from a
second thread (3.3 ms either way in one process, ``benchmarks/bench_identify.py``),
but two workers with two threads each made ``backlashkit reproduce ravanbod2002
--runs 10 --jobs 2`` take 68 s instead of 31 s on a 2-core machine (README, "Speed").
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context


def _one_blas_thread() -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")  # for the life of the worker


def process_pool(jobs: int) -> ProcessPoolExecutor:
    """A pool of ``jobs`` fresh interpreters, each limited to one BLAS thread.

    Parameters
    ----------
    jobs : int
        Worker processes (>= 1).

    Returns
    -------
    concurrent.futures.ProcessPoolExecutor
        The pool ("spawn" start method: no fork of a process that has started threads).
    """
    return ProcessPoolExecutor(jobs, mp_context=get_context("spawn"),
                               initializer=_one_blas_thread)
