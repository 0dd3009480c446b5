"""The fleet's manifest: one row per test, read and checked before any fit.

``MANIFEST.csv`` has the columns ``drive`` (an id), ``date`` (ISO 8601, ``2026-01-05``),
``records`` (the test's record files, separated by ``|``) and ``prior`` (a PRIOR.toml:
the ``[drive]`` table of ``examples/paper_drive.toml`` without ``theta``); file names are
relative to the manifest's folder (or absolute). Other columns are ignored. A
malformed manifest, a missing column or value, a bad date, or a (drive, date) given twice
is an :class:`~backlashkit.errors.InputError` naming the line, raised before any fit;
whether the files exist is checked where they are read (a missing file refuses its
test only).

Every manifest has a fingerprint (:attr:`Manifest.sha256`): the SHA-256 of its rows as
read (drive, ISO date, record and prior names, in order), whatever the file's spacing or
line endings; and every test one of its own row (:attr:`FleetTest.fingerprint`). A
results file carries both, so that a result is never kept for a test whose files the
manifest has changed, while a manifest that grows by a week of tests completes the
results of its earlier weeks.
"""

from __future__ import annotations

import csv
import datetime as dt
import hashlib
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

__all__ = ["FleetTest", "MANIFEST_COLUMNS", "Manifest", "read_manifest"]

#: The manifest's required columns.
MANIFEST_COLUMNS = ("drive", "date", "records", "prior")
#: Hex digits of a test's fingerprint: 64 bits, so that two rows of one fleet share one
#: by chance with a probability of about n^2 / 2^65 (1e-13 for 2 000 tests).
FINGERPRINT_DIGITS = 16


@dataclass(frozen=True)
class FleetTest:
    """One test of the manifest.

    Attributes
    ----------
    drive : str
        Drive id.
    date : datetime.date
        Date of the test.
    records : tuple of str
        Record files as written in the manifest.
    prior : str
        Prior file as written in the manifest.
    line : int
        Line of the manifest (1-based, the header is line 1).
    """

    drive: str
    date: dt.date
    records: tuple[str, ...]
    prior: str
    line: int

    @property
    def fingerprint(self) -> str:
        """The first 16 hex digits of the SHA-256 of the test's row as read (drive, ISO
        date, record and prior names): what a results row was fitted from."""
        return hashlib.sha256(_row_text(self)).hexdigest()[:FINGERPRINT_DIGITS]

    def paths(self, folder: Path) -> tuple[list[str], str]:
        """The record and prior files as absolute paths.

        Parameters
        ----------
        folder : pathlib.Path
            The manifest's folder, which relative names are read from.

        Returns
        -------
        tuple of (list of str, str)
            Record paths and prior path.
        """
        base = folder.resolve()
        return [str(base / r) for r in self.records], str(base / self.prior)


@dataclass(frozen=True)
class Manifest:
    """A manifest read by :func:`read_manifest`.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    tests : list of FleetTest
        Its rows, in order.
    sha256 : str
        Fingerprint of the rows (module docstring).
    """

    path: Path
    tests: list[FleetTest]
    sha256: str


def _date(path: Path, line: int, text: str) -> dt.date:
    try:
        return dt.date.fromisoformat(text)
    except ValueError:
        try:  # a timestamp: the test's day
            return dt.datetime.fromisoformat(text).date()
        except ValueError:
            raise InputError(f"{path}, line {line}: date {text!r} is not an ISO 8601 date "
                             "(write e.g. 2026-01-05)") from None


def _row(path: Path, line: int, row: dict[str, str]) -> FleetTest:
    if None in row:  # csv.DictReader's key for the fields past the header's
        raise InputError(f"{path}, line {line}: more fields than the header has columns "
                         "(a comma inside a file name? separate records with |)")
    values = {k: (row.get(k) or "").strip() for k in MANIFEST_COLUMNS}
    empty = [k for k, val in values.items() if not val]
    if empty:
        raise InputError(f"{path}, line {line}: empty {', '.join(empty)}; every test needs "
                         f"a {', '.join(MANIFEST_COLUMNS)}")
    records = tuple(r.strip() for r in values["records"].split("|"))
    if any(not r for r in records):
        raise InputError(f"{path}, line {line}: records {values['records']!r} holds an empty "
                         "file name; separate the files with a single |")
    return FleetTest(values["drive"], _date(path, line, values["date"]), records,
                     values["prior"], line)


def read_manifest(path: str | Path) -> Manifest:
    """Read and check a fleet manifest (module docstring).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``MANIFEST.csv``.

    Returns
    -------
    Manifest
        Its tests and fingerprint.

    Raises
    ------
    InputError
        If the file is not a CSV with the columns of :data:`MANIFEST_COLUMNS`, a row
        misses a value or has a bad date, a (drive, date) appears twice, or there is no
        test; the message names the file and line.
    FileNotFoundError
        If the file does not exist.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory; give the manifest's CSV file")
    with open(path, encoding="utf-8-sig", newline="") as fh:
        try:
            reader = csv.DictReader(fh)
            header = [h.strip() for h in reader.fieldnames or ()]
            missing = [c for c in MANIFEST_COLUMNS if c not in header]
            if missing:
                raise InputError(f"{path}: missing column(s) {', '.join(missing)} in the "
                                 f"header line; a manifest has {','.join(MANIFEST_COLUMNS)}"
                                 + _other_separator(header))
            reader.fieldnames = header
            tests = [_row(path, reader.line_num, row) for row in reader
                     if any((v or "").strip() for v in row.values() if isinstance(v, str))]
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: not a readable CSV manifest ({exc})") from None
    if not tests:
        raise InputError(f"{path}: no test in the manifest (a header and no rows)")
    seen: dict[tuple[str, dt.date], int] = {}
    for test in tests:
        key = (test.drive, test.date)
        if key in seen:
            raise InputError(f"{path}, line {test.line}: drive {test.drive} on {test.date} "
                             f"is also on line {seen[key]}; give each (drive, date) once")
        seen[key] = test.line
    digest = hashlib.sha256()
    for test in tests:
        digest.update(_row_text(test) + b"\n")
    return Manifest(path, tests, digest.hexdigest())


def _other_separator(header: list[str]) -> str:
    """``, separated by commas (this one uses ';')`` where the header is one field that
    another separator splits into the columns; else nothing."""
    if len(header) != 1:
        return ""
    for sep in (";", "\t", "|"):
        if set(MANIFEST_COLUMNS) <= {h.strip() for h in header[0].split(sep)}:
            return f", separated by commas (this one uses {sep!r})"
    return ""


def _row_text(test: FleetTest) -> bytes:
    """A test's row as the fingerprints read it."""
    return "\x1f".join((test.drive, test.date.isoformat(), "|".join(test.records),
                        test.prior)).encode()
