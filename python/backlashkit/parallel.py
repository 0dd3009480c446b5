"""One way to run a batch of independent tasks: serially, on a local process pool, on any
:class:`concurrent.futures.Executor`, or on a Dask cluster.

Every batch of fits (the fleet, the reproductions, the studies in ``benchmarks/``) goes
through :func:`map_tasks` (results in task order) or :func:`iter_tasks` (results as
they finish, for consumers that record them as they come and resume after an
interruption). Where the work runs is chosen by the caller:

* nothing (``executor=None, jobs=None`` or ``jobs=1``): serially in this process;
* ``jobs=N``: a pool of ``N`` fresh interpreters (:func:`process_pool`);
* ``executor=``: any :class:`concurrent.futures.Executor` the caller made (and shuts
  down), or a ``dask.distributed.Client`` (Dask is the optional extra
  ``backlashkit[dask]``, imported only when a client is given; :func:`dask_client`
  starts a local cluster or connects to a scheduler).

**Determinism.** With ``seed`` given, task ``i`` receives the ``i``-th child of
``numpy.random.SeedSequence(seed).spawn(len(tasks))``: its random stream depends on its
place in the batch only, never on the executor, the number of workers or the order in
which tasks finish, so the results are bit-identical whatever runs them.

**One BLAS thread per worker.** Every worker's NumPy would otherwise start one OpenBLAS
thread per core, so ``jobs`` workers on ``jobs`` cores run ``jobs`` squared busy
threads. The Gauss-Newton products ``J^T J`` of the joint fit (320 010 x 7 on paper A's
records) gain nothing from a second thread (3.3 ms either way in one process,
``benchmarks/bench_identify.py``), but two workers with two threads each made
``backlashkit reproduce ravanbod2002 --runs 10 --jobs 2`` take 68 s instead of 31 s on a
2-core machine (README, "Speed"). The pool's workers are limited when they start; a
task that runs in another process than the caller's (a Dask worker, a user's process
pool) limits its process on first use. Tasks run in the caller's process (serially, on
a thread pool) leave the caller's BLAS alone.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from multiprocessing import get_context
from typing import IO, Any

import numpy as np

from .errors import InputError

__all__ = ["ProgressBar", "dask_client", "iter_tasks", "map_tasks", "process_pool",
           "reporter", "root_seed", "task_seeds"]

#: Seconds to wait for a Dask scheduler before calling it unreachable: a scheduler on
#: the network answers in well under a second; the default of distributed (30 s) makes
#: a typo in the address look like a hang.
CONNECT_TIMEOUT = 10.0

#: Width and height assumed of a terminal that reports no size (a pseudo-terminal of
#: size 0x0), the common default.
FALLBACK_COLUMNS, FALLBACK_ROWS = 80, 24

#: Dask's setting of the environment of its workers that :func:`dask_client` unsets.
_TRIM_KEY = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"
#: Whether Dask's workers sample their stacks (its statistical profiler).
_PROFILE_KEY = "distributed.worker.profile.enabled"

_BLAS_LIMITED = False  # this process has been limited to one BLAS thread (a worker)


def _one_blas_thread() -> None:
    global _BLAS_LIMITED
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")  # for the life of the worker
    _BLAS_LIMITED = True


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


class ProgressBar:
    """A progress bar on stderr: tasks done out of the total, and the time left.

    Pass it as the ``progress=`` of :func:`map_tasks` (or call it as
    ``bar(done, total)``). It draws with ``tqdm`` only when its stream is a terminal and
    ``quiet`` is False, so a log file, a pipe or a test sees nothing, and it never
    writes to stdout, where ``--json`` goes. Use it as a context manager, or call
    :meth:`close`, to end the bar's line.

    Parameters
    ----------
    desc : str
        What is counted, shown before the bar (e.g. ``"ravanbod2002"``).
    unit : str, optional
        Name of one task (default ``"fit"``).
    quiet : bool, optional
        Draw nothing (the command line's ``--quiet``).
    stream : file object, optional
        Where to draw (default ``sys.stderr``, looked up at construction).
    labels : sequence of str, optional
        What each task is (``labels[k]`` for the ``k``-th): shown after the bar while it
        runs, for a few long steps of different kinds (a fit's stages).
    """

    def __init__(self, desc: str, *, unit: str = "fit", quiet: bool = False,
                 stream: IO[str] | None = None, labels: Sequence[str] = ()) -> None:
        self.desc, self.unit, self.labels = desc, unit, tuple(labels)
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.shown = not quiet and callable(isatty) and bool(isatty())
        self._bar: Any = None

    def __repr__(self) -> str:
        return f"ProgressBar({self.desc!r}, unit={self.unit!r}, shown={self.shown})"

    def __call__(self, done: int, total: int) -> None:
        """Show ``done`` of ``total`` tasks (the first call starts the clock).

        Parameters
        ----------
        done : int
            Tasks finished so far (tasks already done before the run count too).
        total : int
            All tasks.
        """
        if not self.shown:
            return
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, desc=self.desc, unit=self.unit,
                             file=self.stream, **self._width())
        else:
            if total != self._bar.total:  # the work grew (e.g. a second search)
                self._bar.total = total
            self._bar.update(done - self._bar.n)
        if self.labels:  # the task now running; none once all are done
            self._bar.set_postfix_str(self.labels[done] if done < min(total, len(
                self.labels)) else "")

    def _width(self) -> dict[str, Any]:
        """Follow the terminal's width, or take :data:`FALLBACK_COLUMNS` where the
        terminal reports none (a pseudo-terminal of size 0x0 drew no bar at all)."""
        try:
            size = os.get_terminal_size(self.stream.fileno())
        except (AttributeError, OSError, ValueError):
            size = os.terminal_size((0, 0))
        # tqdm hides a bar below the terminal's last row: a size of 0 rows hid every bar
        return {"dynamic_ncols": True} if size.columns > 0 and size.lines > 0 else {
            "ncols": FALLBACK_COLUMNS, "nrows": FALLBACK_ROWS}

    def close(self) -> None:
        """End the bar's line (nothing when it was never drawn)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def root_seed(seed: int | np.random.SeedSequence | np.random.Generator
              ) -> np.random.SeedSequence:
    """The root of a batch's random streams: ``seed`` as a SeedSequence.

    Parameters
    ----------
    seed : int, numpy.random.SeedSequence or numpy.random.Generator
        An int >= 0, a SeedSequence (returned as it is), or a generator, whose own
        SeedSequence is the root (spawning from it advances its count of children, so
        two batches from one generator differ, as two draws from it do).

    Returns
    -------
    numpy.random.SeedSequence
        The root.

    Raises
    ------
    InputError
        If ``seed`` is none of these.
    """
    if isinstance(seed, np.random.Generator):
        seed = getattr(seed.bit_generator, "seed_seq", None)
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, a numpy.random.SeedSequence or a "
                         f"numpy.random.Generator, got {seed!r}")
    return np.random.SeedSequence(int(seed))


def task_seeds(seed: int | np.random.SeedSequence | np.random.Generator | None,
               n: int) -> list[np.random.SeedSequence | None]:
    """The random stream of each of ``n`` tasks: ``SeedSequence(seed).spawn(n)``.

    Parameters
    ----------
    seed : int, numpy.random.SeedSequence, numpy.random.Generator or None
        Root seed (:func:`root_seed`); None: the tasks take no seed.
    n : int
        Number of tasks.

    Returns
    -------
    list of numpy.random.SeedSequence or None
        Child ``i`` for task ``i`` (``n`` Nones without a seed).

    Raises
    ------
    InputError
        If ``seed`` is neither None nor a seed :func:`root_seed` takes.
    """
    if seed is None:
        return [None] * n
    return root_seed(seed).spawn(n)


def _call(fn: Callable, task: Any, seed: np.random.SeedSequence | None,
          caller_pid: int) -> Any:
    """Run one task where it landed (module level: pickled to workers)."""
    if os.getpid() != caller_pid and not _BLAS_LIMITED:
        _one_blas_thread()
    return fn(task) if seed is None else fn(task, seed)


def _check_jobs(jobs: Any) -> int | None:
    if jobs is None:
        return None
    if isinstance(jobs, bool) or not isinstance(jobs, (int, np.integer)) or jobs < 1:
        raise InputError(f"jobs must be a positive integer (worker processes), got {jobs!r}")
    return int(jobs)


def _as_executor(executor: Any) -> Executor:
    """A concurrent.futures view of ``executor`` (a Dask client's is its ``get_executor``)."""
    if isinstance(executor, Executor):
        return executor
    get_executor = getattr(executor, "get_executor", None)
    if callable(get_executor):  # a dask.distributed.Client: its concurrent.futures face
        # pure=False: two equal tasks are two runs, not one result shared by key
        return get_executor(pure=False)
    raise InputError(
        "executor must be a concurrent.futures.Executor or a dask.distributed.Client, "
        f"got {type(executor).__name__}")


@contextmanager
def _runner(executor: Any, jobs: Any) -> Iterator[Executor | None]:
    """The executor to submit to (None: serial), shut down afterwards if made here."""
    n = _check_jobs(jobs)
    if executor is not None and n is not None:
        raise InputError(f"give executor or jobs, not both (got jobs={jobs!r} and an "
                         f"executor {type(executor).__name__})")
    if executor is not None:
        view = _as_executor(executor)
        try:
            yield view
        finally:
            if view is not executor:  # the Dask view: cancel what is left, keep the client
                view.shutdown(wait=False)
        return
    if n is None or n == 1:
        yield None
        return
    pool = process_pool(n)
    try:
        yield pool
    finally:  # an interruption must not wait for every queued task
        pool.shutdown(wait=True, cancel_futures=True)


def iter_tasks(
    fn: Callable[..., Any],
    tasks: Sequence[Any],
    *,
    executor: Any = None,
    jobs: int | None = None,
    seed: int | np.random.SeedSequence | None = None,
    skip: Iterable[int] = (),
) -> Iterator[tuple[int, Any]]:
    """Run ``fn`` on every task; yield ``(index, result)`` as each one finishes.

    Parameters
    ----------
    fn : callable
        ``fn(task)``, or ``fn(task, seed)`` when ``seed`` is given (``seed`` a
        :class:`numpy.random.SeedSequence`). Must be picklable (a module-level
        function) for process pools and Dask.
    tasks : sequence
        The tasks (picklable; keep them small: paths rather than data).
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Where to run (module docstring); the caller keeps it open and shuts it down.
    jobs : int, optional
        Worker processes of a local pool made for this batch (1 or None: serial in
        this process). Not with ``executor``.
    seed : int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Root seed: task ``i`` gets child ``i`` of ``SeedSequence(seed).spawn(len(tasks))``
        whether or not other tasks are skipped.
    skip : iterable of int, optional
        Indices of tasks not to run (already done by an earlier, interrupted run).

    Yields
    ------
    tuple of (int, object)
        The task's index in ``tasks`` and ``fn``'s result, in order of completion
        (task order when serial).

    Raises
    ------
    InputError
        If ``jobs``, ``seed`` or ``executor`` is invalid, or both ``executor`` and
        ``jobs`` are given.
    Exception
        Whatever ``fn`` raises, when its result is reached; the tasks not started are
        then cancelled.
    """
    seeds = task_seeds(seed, len(tasks))
    skipped = set(skip)
    todo = [i for i in range(len(tasks)) if i not in skipped]
    pid = os.getpid()
    with _runner(executor, jobs) as pool:
        if pool is None:
            for i in todo:
                yield i, _call(fn, tasks[i], seeds[i], pid)
            return
        futures = {pool.submit(_call, fn, tasks[i], seeds[i], pid): i for i in todo}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:  # an error or an interruption: drop what has not started
            for future in futures:
                future.cancel()


def map_tasks(
    fn: Callable[..., Any],
    tasks: Sequence[Any],
    *,
    executor: Any = None,
    jobs: int | None = None,
    seed: int | np.random.SeedSequence | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[Any]:
    """Run ``fn`` on every task and return the results in task order.

    Parameters
    ----------
    fn : callable
        ``fn(task)``, or ``fn(task, seed)`` when ``seed`` is given (see
        :func:`iter_tasks`).
    tasks : sequence
        The tasks.
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Where to run (module docstring).
    jobs : int, optional
        Worker processes of a local pool (1 or None: serial). Not with ``executor``.
    seed : int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Root seed of the tasks' random streams (:func:`task_seeds`).
    progress : callable, optional
        ``progress(done, total)`` once before the first task (``done`` 0: a
        :class:`ProgressBar` starts its clock) and after every finished task.

    Returns
    -------
    list
        ``fn``'s result per task, in the order of ``tasks``: bit-identical whatever the
        executor and the number of workers, when ``fn`` depends only on its task and
        seed.

    Raises
    ------
    InputError
        As :func:`iter_tasks`.
    Exception
        The first error raised by ``fn`` (in order of completion).
    """
    results: list[Any] = [None] * len(tasks)
    if progress is not None:
        progress(0, len(tasks))
    for done, (i, result) in enumerate(
            iter_tasks(fn, tasks, executor=executor, jobs=jobs, seed=seed), start=1):
        results[i] = result
        if progress is not None:
            progress(done, len(tasks))
    return results


@contextmanager
def dask_client(
    *,
    address: str | None = None,
    n_workers: int | None = None,
    timeout: float = CONNECT_TIMEOUT,
) -> Iterator[Any]:
    """A ``dask.distributed.Client``: connected to ``address``, or to a local cluster of
    ``n_workers`` single-threaded worker processes started (and stopped) here.

    Parameters
    ----------
    address : str, optional
        The scheduler, e.g. ``"tcp://host:8786"``.
    n_workers : int, optional
        Worker processes of a local cluster (one thread each). Give this or ``address``.
    timeout : float, optional
        Seconds to wait for the scheduler (default :data:`CONNECT_TIMEOUT`).

    Yields
    ------
    dask.distributed.Client
        The client, closed on exit (with the local cluster, if one was started).

    Raises
    ------
    InputError
        If Dask is not installed, both or neither of ``address`` and ``n_workers`` are
        given, ``n_workers`` is not a positive integer, or the scheduler does not answer
        within ``timeout``.
    """
    if (address is None) == (n_workers is None):
        raise InputError("give a scheduler address or n_workers for a local cluster "
                         f"(exactly one), got address={address!r}, n_workers={n_workers!r}")
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("Dask is not installed: pip install 'backlashkit[dask]'") from None
    if address is None:
        import dask

        n = _check_jobs(n_workers)
        # one thread per worker process: the fits hold the GIL; a worker per core.
        # Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers, which freezes glibc's
        # mmap threshold, so every large NumPy temporary of a fit is a fresh mmap with
        # its page faults; unset, as in the pool's workers (benchmarks/bench_fleet.py:
        # Dask's overhead against the pool went from +25 % to -1 %, docs/design/fleet.md).
        # The dashboard on any free port: on the default 8787 it collides with another
        # cluster on the machine (and None still binds the default)
        # The workers' statistical profiler takes the GIL every 10 ms to walk the stack
        # of a fit that holds it; off (benchmarks/bench_fleet.py, docs/design/fleet.md).
        with dask.config.set({_TRIM_KEY: None, _PROFILE_KEY: False}), \
                LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                             dashboard_address=":0") as cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:  # refused, unresolved, silent, bad
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(f"cannot reach the Dask scheduler {address} within {timeout:g} s "
                         f"({reason[:160]}); is it running? check the address") from None
    with client:
        yield client


@contextmanager
def reporter(progress: bool | Callable[[int, int], None], desc: str, *,
             unit: str = "fit", labels: Sequence[str] = ()
             ) -> Iterator[Callable[[int, int], None]]:
    """The ``progress(done, total)`` callable that a ``progress=`` option asks for.

    Parameters
    ----------
    progress : bool or callable
        True: a :class:`ProgressBar` made here (and closed on exit), drawn only on a
        terminal; a callable: the caller's own, left open; False: one that does nothing.
    desc, unit : str
        The bar's label and the name of one step, when it is made here.
    labels : sequence of str, optional
        What each step is (:class:`ProgressBar`'s ``labels``), when it is made here.

    Yields
    ------
    callable
        ``progress(done, total)``.
    """
    if callable(progress):
        yield progress
    elif progress:
        with ProgressBar(desc, unit=unit, labels=labels) as bar:
            yield bar
    else:
        yield lambda done, total: None
