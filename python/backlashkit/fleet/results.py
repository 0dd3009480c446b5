"""The fleet's results file: one CSV row per test, appended as tests finish.

The first line is a comment naming the manifest's fingerprint
(:attr:`backlashkit.fleet.Manifest.sha256`) and its number of tests; then the header
(:data:`RESULT_COLUMNS`) and one row per finished test, written and flushed as one
piece, with the fingerprint of the test's manifest row
(:attr:`backlashkit.fleet.FleetTest.fingerprint`). A rerun keeps the rows whose test is
still in the manifest with the same files: an interrupted run, or a manifest grown by
new tests, is completed; one that dropped a test or changed its files is refused
without ``force``. Numbers are written with Python's ``repr`` (the shortest text that
reads back to the same float), so two runs that computed the same fits write the same
bytes. When every test of the manifest is in the file, it is rewritten in the
manifest's order (through a temporary file and an atomic rename): the finished file
does not depend on the executor, the number of workers, or on interruptions.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import InputError
from .manifest import Manifest

__all__ = ["RESULT_COLUMNS", "ResultsFile", "read_results"]

#: Columns of the results file. ``theta`` (the backlash half-width), ``std``,
#: ``ci95_low`` and ``ci95_high`` in rad; ``fit_percent`` the lowest NRMSE fit % over
#: the test's records and speeds; ``noise_model`` the noise model the fit chose;
#: ``notes`` the fit's warnings; ``status`` ``ok`` or ``refused`` with its ``reason``;
#: ``inputs`` the fingerprint of the test's manifest row.
RESULT_COLUMNS = ("drive", "date", "status", "theta", "std", "ci95_low", "ci95_high",
                  "fit_percent", "noise_model", "notes", "reason", "inputs")
#: The columns of results files written before ``inputs`` (read alike, their rows'
#: ``inputs`` empty: they complete only the manifest they were written for).
_COLUMNS_BEFORE_INPUTS = RESULT_COLUMNS[:-1]
_FLOATS = ("theta", "std", "ci95_low", "ci95_high", "fit_percent")
_MAGIC = "# backlashkit fleet results"


def _header(sha: str, n: int) -> str:
    return f"{_MAGIC}; manifest sha256 {sha}; {n} tests\n"


def _line(row: Mapping[str, Any]) -> str:
    buf = io.StringIO()
    cells = []
    for c in RESULT_COLUMNS:
        value = row.get(c)
        cells.append("" if value is None else repr(float(value)) if c in _FLOATS
                     else str(value))
    csv.writer(buf, lineterminator="\n").writerow(cells)
    return buf.getvalue()


def _parse(row: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {"inputs": "", **row}
    for c in _FLOATS:
        out[c] = float(row[c]) if row.get(c) else None
    return out


def read_results(path: str | Path) -> tuple[str, list[dict[str, Any]]]:
    """Read a fleet results file.

    Parameters
    ----------
    path : str or pathlib.Path
        The file written by :func:`backlashkit.fleet.identify_fleet`.

    Returns
    -------
    tuple of (str, list of dict)
        The manifest fingerprint it was written for, and its rows (column name to
        value: floats for the numbers, None where empty; strings otherwise) in file
        order. A last line cut short by an interruption is left out.

    Raises
    ------
    InputError
        If the file is a directory or not a fleet results file.
    FileNotFoundError
        If it does not exist.
    """
    if Path(path).is_dir():
        raise InputError(f"{path}: is a directory; give a fleet results file")
    text = Path(path).read_text(encoding="utf-8")
    first, _, rest = text.partition("\n")
    if not first.startswith(_MAGIC) or "sha256 " not in first:
        raise InputError(f"{path} is not a backlashkit fleet results file (its first line "
                         f"is not '{_MAGIC}; ...')")
    sha = first.split("sha256 ", 1)[1].split(";", 1)[0].strip()
    if not rest.endswith("\n"):  # killed while writing a row: that test is not done
        rest = rest[: rest.rfind("\n") + 1]
    reader = csv.DictReader(io.StringIO(rest))
    if tuple(reader.fieldnames or ()) not in (RESULT_COLUMNS, _COLUMNS_BEFORE_INPUTS):
        raise InputError(f"{path}: columns {reader.fieldnames} are not those of a fleet "
                         f"results file ({','.join(RESULT_COLUMNS)})")
    try:
        return sha, [_parse(r) for r in reader]
    except ValueError as exc:
        raise InputError(f"{path}, line {reader.line_num + 1}: {exc}") from None


class ResultsFile:
    """The results file of one manifest, opened to append rows.

    Parameters
    ----------
    path : str or pathlib.Path
        The file.
    manifest : Manifest
        The manifest it holds the results of.
    force : bool, optional
        Start the file afresh if it exists (default False: complete it where each of its
        rows is a test of ``manifest`` with the same files; refuse otherwise).

    Attributes
    ----------
    done : dict
        ``(drive, ISO date) -> row`` of the tests already in the file, but those it
        refused: a rerun tries them again (a missing record file restored since).

    Raises
    ------
    InputError
        If the file exists, ``force`` is False and it is not a results file, or holds a
        test that ``manifest`` does not have or gives other files; or its directory
        does not exist.
    """

    def __init__(self, path: str | Path, manifest: Manifest, *, force: bool = False) -> None:
        self.path = Path(path)
        self.sha256 = manifest.sha256
        self.n_tests = len(manifest.tests)
        self.inputs = {(t.drive, t.date.isoformat()): t.fingerprint for t in manifest.tests}
        if not self.path.parent.is_dir():
            raise InputError(f"--out {self.path}: directory {self.path.parent} does not exist")
        if self.path.is_dir():
            raise InputError(f"--out {self.path} is a directory; give a file name")
        self.done: dict[tuple[str, str], dict[str, Any]] = {}
        if self.path.exists() and not force:
            try:
                sha, rows = read_results(self.path)
            except InputError as exc:  # the run's output, not the user's file to read
                raise InputError(f"--out {exc}; give another --out or pass --force") from None
            self._check_tests(sha, rows)
            # a refused test is tried again: its file may have been restored since
            self.done = {(r["drive"], r["date"]): {**r, "inputs": self.inputs[
                (r["drive"], r["date"])]} for r in rows if r["status"] != "refused"}
            self._rewrite(list(self.done.values()))  # drops a row cut short
        else:
            self._rewrite([])

    def _check_tests(self, sha: str, rows: Sequence[Mapping[str, Any]]) -> None:
        """Refuse rows that are no test of the manifest with the same files (rows
        without a fingerprint: unless the file was written for this very manifest)."""
        if sha == self.sha256:
            return
        # a refused test has no result to lose: the manifest may drop it
        stale = [f"{r['drive']} on {r['date']}" for r in rows if r["status"] != "refused"
                 and self.inputs.get((r["drive"], r["date"])) != r["inputs"]]
        if not stale:
            return
        which = f"{stale[0]} and {len(stale) - 1} more are" if len(stale) > 1 \
            else f"{stale[0]} is"
        raise InputError(
            f"{self.path} holds results of another manifest (sha256 {sha[:12]}..., this "
            f"one {self.sha256[:12]}...): {which} not in this one or had other files; "
            "give another --out, or pass --force to start it afresh (a manifest that only "
            "adds tests completes the file)")

    def _rewrite(self, rows: Sequence[Mapping[str, Any]]) -> None:
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(_header(self.sha256, self.n_tests) + ",".join(RESULT_COLUMNS) + "\n")
            fh.write("".join(_line(r) for r in rows))
        os.replace(tmp, self.path)

    def append(self, row: Mapping[str, Any]) -> None:
        """Append one test's row and flush it to the file.

        Parameters
        ----------
        row : mapping
            Column name to value (:data:`RESULT_COLUMNS`; missing ones are empty).
        """
        row = {**row, "inputs": self.inputs[(row["drive"], row["date"])]}
        with open(self.path, "a", encoding="utf-8", newline="") as fh:
            fh.write(_line(row))
            fh.flush()
        self.done[(row["drive"], row["date"])] = row

    def finish(self, order: Sequence[tuple[str, str]]) -> list[dict[str, Any]]:
        """Rewrite the file in manifest order once every test is in it.

        Parameters
        ----------
        order : sequence of (str, str)
            ``(drive, ISO date)`` of the manifest's tests, in order.

        Returns
        -------
        list of dict
            The rows in that order (None for tests not done).
        """
        rows = [self.done.get(key) for key in order]
        if all(r is not None for r in rows):
            self._rewrite(rows)  # type: ignore[arg-type]
        return [None if r is None else _normalised(r) for r in rows]


def _normalised(row: Mapping[str, Any]) -> dict[str, Any]:
    """A row as it reads back from the file (floats exact, empty text for None)."""
    return {c: (None if row.get(c) is None else float(row[c])) if c in _FLOATS
            else ("" if row.get(c) is None else str(row[c])) for c in RESULT_COLUMNS}
