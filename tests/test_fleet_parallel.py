"""backlashkit.parallel: one executor abstraction, the same results on every executor."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from backlashkit.errors import InputError
from backlashkit.parallel import dask_client, iter_tasks, map_tasks, task_seeds


def _draw(task, seed):
    """A random task: its result depends on its stream only."""
    rng = np.random.default_rng(seed)
    return task, rng.standard_normal(3).tolist(), os.getpid()


def _blas_threads(_task):
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def _fail(task):
    if task == 2:
        raise InputError("task 2 refused")
    return task


TASKS = list(range(7))


@pytest.fixture(scope="module")
def reference():
    return [r[:2] for r in map_tasks(_draw, TASKS, seed=5)]


def test_streams_are_spawned_children():
    expected = np.random.SeedSequence(5).spawn(7)
    got = task_seeds(5, 7)
    assert [s.spawn_key for s in got] == [s.spawn_key for s in expected]
    assert task_seeds(None, 3) == [None] * 3
    direct = [np.random.default_rng(s).standard_normal(3).tolist() for s in expected]
    assert [r[1] for r in map_tasks(_draw, TASKS, seed=5)] == direct


def test_same_results_serial_threads_and_processes(reference):
    with ThreadPoolExecutor(3) as pool:
        threads = map_tasks(_draw, TASKS, executor=pool, seed=5)
    procs = map_tasks(_draw, TASKS, jobs=2, seed=5)
    assert [r[:2] for r in threads] == reference
    assert [r[:2] for r in procs] == reference
    assert {r[2] for r in procs} != {os.getpid()}  # they did run elsewhere


def test_same_results_on_dask(reference):
    pytest.importorskip("distributed")
    with dask_client(n_workers=2) as client:
        got = map_tasks(_draw, TASKS, executor=client, seed=5)
        blas = map_tasks(_blas_threads, [0, 1], executor=client)
    assert [r[:2] for r in got] == reference
    assert all(n == 1 for threads in blas for n in threads)  # one BLAS thread per worker


def test_pool_workers_run_one_blas_thread():
    assert all(n == 1 for threads in map_tasks(_blas_threads, [0, 1], jobs=2)
               for n in threads)


def test_skip_keeps_the_streams_of_the_others(reference):
    got = dict(iter_tasks(_draw, TASKS, seed=5, skip=[0, 3]))
    assert sorted(got) == [1, 2, 4, 5, 6]
    assert all(got[i][:2] == reference[i] for i in got)


def test_progress_and_order():
    calls = []
    assert map_tasks(abs, [-3, 2, -1], jobs=2,
                     progress=lambda d, n: calls.append((d, n))) == [3, 2, 1]
    assert calls == [(0, 3), (1, 3), (2, 3), (3, 3)]


def test_a_task_error_reaches_the_caller():
    with pytest.raises(InputError, match="task 2 refused"):
        map_tasks(_fail, TASKS, jobs=2)
    with pytest.raises(InputError, match="task 2 refused"):
        map_tasks(_fail, TASKS)


@pytest.mark.parametrize("kwargs, words", [
    ({"jobs": 0}, "jobs must be a positive integer"),
    ({"jobs": 1.5}, "jobs must be a positive integer"),
    ({"jobs": 2, "executor": ThreadPoolExecutor(1)}, "not both"),
    ({"executor": object()}, "executor must be a concurrent.futures.Executor"),
    ({"seed": -1}, "seed must be an integer >= 0"),
])
def test_bad_options(kwargs, words):
    with pytest.raises(InputError, match=words):
        map_tasks(abs, [1], **kwargs)


def test_dask_client_needs_one_of_address_and_workers():
    with pytest.raises(InputError, match="exactly one"), dask_client():
        pass
    with pytest.raises(InputError, match="exactly one"), \
            dask_client(address="tcp://127.0.0.1:9", n_workers=2):
        pass
