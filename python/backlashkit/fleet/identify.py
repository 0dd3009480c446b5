"""Identify every test of a fleet's manifest, on any executor, resumably.

Each test is identified with the default method,
:class:`backlashkit.JointIdentifier` with its default options on all the test's
records, its prior read from the test's PRIOR.toml. The task sent to a worker is the
test's file names, never its data: every worker reads the records where they lie (on
a cluster, a file system the workers share at the same paths), so the scheduler moves a
few hundred bytes per test.

A test whose files cannot be used (missing, unreadable, refused by the estimator) is a
row with ``status = refused`` and the one-line reason; the other tests go on. One
simulation thread per fit (``workers=1``): the parallelism is across tests, and the
fits are then the same computation on every worker.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..parallel import iter_tasks
from .manifest import Manifest, read_manifest
from .results import ResultsFile

__all__ = ["identify_fleet", "identify_test"]


def _refused(drive: str, date: str, reason: str) -> dict[str, Any]:
    return {"drive": drive, "date": date, "status": "refused",
            "reason": " ".join(reason.split())}


def _fit(records: list[str], prior_path: str) -> dict[str, Any]:
    from .. import JointIdentifier, read_records
    from ..identify.noise import noise_label
    from ..io import read_drive_toml

    prior = read_drive_toml(prior_path, require_theta=False)
    recs = [r for path in records for r in read_records(path)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est = JointIdentifier(prior, workers=1).fit(recs)
    notes = list(dict.fromkeys(" ".join(str(w.message).split()) for w in caught))
    if getattr(est, "ambiguous_", False):
        notes.append("ambiguous: the likelihood has distinct minima of nearly equal cost")
    low, high = est.ci95_
    fits = getattr(est, "fit_percent_", None)
    return {"status": "ok", "theta": est.theta_, "std": est.std_, "ci95_low": low,
            "ci95_high": high,
            "fit_percent": None if fits is None else float(np.min(fits)),
            "noise_model": noise_label(est.noise_ar_), "notes": "; ".join(notes),
            "reason": ""}


def identify_test(task: tuple[str, str, list[str], str]) -> dict[str, Any]:
    """Identify one test; a refused test gives its reason instead of raising.

    Parameters
    ----------
    task : tuple of (str, str, list of str, str)
        Drive id, ISO date, absolute record paths, absolute prior path.

    Returns
    -------
    dict
        The results row (:data:`backlashkit.fleet.RESULT_COLUMNS`).
    """
    drive, date, records, prior = task
    for path in (*records, prior):
        if not Path(path).is_file():
            return _refused(drive, date, f"file not found: {path}")
    try:
        row = _fit(records, prior)
    except InputError as exc:
        # an option the message advises is the library's: a manifest sets none
        return _refused(drive, date, exc.worded(
            lambda option: f"{option} (a library option, which a manifest cannot set)"))
    except (ValueError, ArithmeticError) as exc:  # the model cannot follow these data
        return _refused(drive, date, f"cannot compute with this input: {exc}")
    except OSError as exc:
        return _refused(drive, date, f"cannot read {exc.filename or ''}: {exc.strerror or exc}")
    return {"drive": drive, "date": date, **row}


def identify_fleet(
    manifest: str | Path | Manifest,
    *,
    out: str | Path,
    executor: Any = None,
    jobs: int | None = None,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """Identify every test of a manifest; write the results as they come.

    Parameters
    ----------
    manifest : str, pathlib.Path or Manifest
        The ``MANIFEST.csv`` (:func:`backlashkit.fleet.read_manifest`).
    out : str or pathlib.Path
        The results CSV (:mod:`backlashkit.fleet.results`). If it exists and holds
        results of this manifest's tests, with the same files, those tests are skipped
        and the file is completed: an interrupted run loses only the fits in flight,
        and a manifest grown by new tests fits only those. Tests it refused are tried
        again.
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Where the fits run (:mod:`backlashkit.parallel`); default serially here.
    jobs : int, optional
        Local worker processes instead of ``executor``.
    force : bool, optional
        Start ``out`` afresh (default False).
    progress : callable, optional
        ``progress(done, total)`` once before the first fit (tests already in ``out``)
        and after every test.

    Returns
    -------
    list of dict
        One row per test in manifest order (:data:`backlashkit.fleet.RESULT_COLUMNS`;
        floats for the numbers, None where empty): the same, bit for bit, whatever the
        executor, the number of workers, or interruptions.

    Raises
    ------
    InputError
        If the manifest is malformed or repeats a (drive, date), ``out`` holds a test
        this manifest does not have or gives other files (without ``force``) or cannot
        be written, or ``executor`` / ``jobs`` are invalid; all before any fit.
    """
    man = manifest if isinstance(manifest, Manifest) else read_manifest(manifest)
    folder = man.path.parent
    results = ResultsFile(out, man, force=force)
    keys = [(t.drive, t.date.isoformat()) for t in man.tests]
    tasks = [(t.drive, t.date.isoformat(), *t.paths(folder)) for t in man.tests]
    skip = [i for i, key in enumerate(keys) if key in results.done]
    done = len(skip)
    if progress is not None:
        progress(done, len(tasks))
    for _, row in iter_tasks(identify_test, tasks, executor=executor, jobs=jobs, skip=skip):
        results.append(row)
        done += 1
        if progress is not None:
            progress(done, len(tasks))
    return results.finish(keys)


