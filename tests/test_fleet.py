"""Fleet identification (issue 23): the same table on every executor, resumable after a
kill, bad input as a refused row or one line before any fit.

The fleet is :func:`backlashkit.fleet.generate_fleet`'s: 3 drives of paper A's model x 2
weekly tests, each test paper A's two step-down records (0.157 and 0.942 N m) held 2 s,
paper A's SNRs (Section 5). About 4 s per fit on 2 shared cores.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from backlashkit.cli import main
from backlashkit.errors import InputError
from backlashkit.fleet import (
    RESULT_COLUMNS,
    generate_fleet,
    identify_fleet,
    read_manifest,
    read_results,
)

N_DRIVES, N_WEEKS, HOLD = 3, 2, 2.0


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet") / "data"
    return generate_fleet(N_DRIVES, N_WEEKS, seed=23, out=root, hold=HOLD)


@pytest.fixture(scope="module")
def serial(fleet, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "RESULTS.csv"
    rows = identify_fleet(fleet.manifest, out=out)
    return out, rows


def test_serial_table_is_complete_and_close_to_truth(fleet, serial):
    out, rows = serial
    assert [(r["drive"], r["date"]) for r in rows] == [
        (d, day.isoformat()) for d in fleet.drives for day in fleet.dates]
    assert all(r["status"] == "ok" for r in rows), [r["reason"] for r in rows]
    for k, r in enumerate(rows):
        d, w = divmod(k, N_WEEKS)
        years = (fleet.dates[w] - fleet.dates[0]).days / 365.25
        truth = fleet.theta0[d] + fleet.rate[d] * years
        # the estimate is within 5 of its own standard errors of the truth, which lies
        # within 10 % of it (the std is 0.4 % of theta on these records)
        assert abs(r["theta"] - truth) < 5 * r["std"] + 1e-12, (r, truth)
        assert r["ci95_low"] < r["theta"] < r["ci95_high"]
    sha, back = read_results(out)
    assert sha == read_manifest(fleet.manifest).sha256
    assert back == rows


def test_bit_identical_with_two_processes(fleet, serial, tmp_path):
    out = tmp_path / "RESULTS.csv"
    rows = identify_fleet(fleet.manifest, out=out, jobs=2)
    assert rows == serial[1]
    assert out.read_bytes() == serial[0].read_bytes()


def test_bit_identical_on_a_dask_local_cluster(fleet, serial, tmp_path):
    distributed = pytest.importorskip("distributed")  # the test extra installs it
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        out = tmp_path / "RESULTS.csv"
        rows = identify_fleet(fleet.manifest, out=out, executor=client)
    assert rows == serial[1]
    assert out.read_bytes() == serial[0].read_bytes()


def _data_rows(path: Path) -> int:
    if not path.exists():
        return 0
    lines = path.read_text(encoding="utf-8").splitlines()
    return max(len(lines) - 2, 0)  # the comment and the header


def test_killed_run_completes_without_refitting(fleet, serial, tmp_path):
    out = tmp_path / "RESULTS.csv"
    proc = subprocess.Popen(
        [sys.executable, "-m", "backlashkit", "fleet", str(fleet.manifest), "--out", str(out),
         "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while _data_rows(out) < 1 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    kept = _data_rows(out)
    assert 1 <= kept < N_DRIVES * N_WEEKS, proc.stderr.read()
    calls = []
    rows = identify_fleet(fleet.manifest, out=out, progress=lambda d, n: calls.append(d))
    assert calls[0] == kept  # the rows already there are skipped ...
    assert len(calls) - 1 == N_DRIVES * N_WEEKS - kept  # ... and only the others fitted
    assert rows == serial[1]
    assert out.read_bytes() == serial[0].read_bytes()


def test_a_row_cut_short_is_fitted_again(fleet, serial, tmp_path):
    out = tmp_path / "RESULTS.csv"
    text = serial[0].read_text(encoding="utf-8")
    whole = text.splitlines(keepends=True)
    out.write_text("".join(whole[:-1]) + whole[-1][:20], encoding="utf-8")  # killed mid-row
    calls = []
    rows = identify_fleet(fleet.manifest, out=out, progress=lambda d, n: calls.append(d))
    assert calls == [N_DRIVES * N_WEEKS - 1, N_DRIVES * N_WEEKS]
    assert rows == serial[1]
    assert out.read_text(encoding="utf-8") == text


# -- bad input ----------------------------------------------------------------------------

def _manifest(tmp_path: Path, rows: list[str]) -> Path:
    path = tmp_path / "MANIFEST.csv"
    path.write_text("drive,date,records,prior\n" + "".join(r + "\n" for r in rows),
                    encoding="utf-8")
    return path


def _one_line_error(capsys, argv: list[str], *words: str) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("backlashkit: error: "), err
    for w in words:
        assert w in err, err


def test_missing_and_unreadable_records_are_refused_rows(fleet, tmp_path):
    data = fleet.manifest.parent
    bad = tmp_path / "bad.csv"
    bad.write_text("t,torque,w_motor\n0,0,0\n0.001,0,0\n", encoding="utf-8")
    prior = data / "drive-001" / "PRIOR.toml"
    path = _manifest(tmp_path, [f"d1,2026-01-05,nowhere.csv,{prior}",
                                f"d2,2026-01-05,{bad},{prior}",
                                f"d3,2026-01-05,{bad},no-prior.toml"])
    rows = identify_fleet(path, out=tmp_path / "R.csv")
    assert [r["status"] for r in rows] == ["refused"] * 3
    assert "file not found" in rows[0]["reason"] and "nowhere.csv" in rows[0]["reason"]
    assert "w_load" in rows[1]["reason"]  # read_records names the missing column
    assert "no-prior.toml" in rows[2]["reason"]
    assert all("\n" not in r["reason"] and r["theta"] is None for r in rows)
    # a rerun tries the refused tests again: a record restored since is read (a QA
    # pass found it refused for good)
    bad.write_text("t,torque,w_motor,w_load\n0,0,0,0\n0.001,0,0,0\n", encoding="utf-8")
    again = identify_fleet(path, out=tmp_path / "R.csv")
    assert again[0] == rows[0] and again[2]["reason"] == rows[2]["reason"]
    assert "w_load" not in again[1]["reason"]


def test_a_refused_rows_advice_says_the_manifest_cannot_set_it(fleet, serial, tmp_path):
    """A reader's or fit's advice names a library option (resample='linear' for a
    missing sample), which no manifest column sets: the row says so. The rows' noise
    model is a word, as identify's JSON gives it, not a Python repr."""
    data = fleet.manifest.parent
    prior = data / "drive-001" / "PRIOR.toml"
    rec = data / read_manifest(fleet.manifest).tests[0].records[0]
    cols = np.loadtxt(rec, delimiter=",", skiprows=1)
    cols[100, 2] = np.nan
    gap = tmp_path / "gap.csv"
    np.savetxt(gap, cols, delimiter=",", header="t,torque,w_motor,w_load", comments="")
    path = _manifest(tmp_path, [f"d1,2026-01-05,{gap},{prior}"])
    (row,) = identify_fleet(path, out=tmp_path / "R.csv")
    assert row["status"] == "refused"
    assert ("pass resample='linear' (a library option, which a manifest cannot set)"
            in row["reason"])
    assert {r["noise_model"] for r in serial[1]} <= {"white", "ar(1)", "ar(2)"}


def test_duplicated_drive_and_date_is_one_line_before_any_fit(tmp_path, capsys):
    path = _manifest(tmp_path, ["d1,2026-01-05,a.csv,p.toml", "d1,2026-01-12,a.csv,p.toml",
                                "d1,2026-01-05,b.csv,p.toml"])
    out = tmp_path / "R.csv"
    _one_line_error(capsys, ["fleet", str(path), "--out", str(out)], "line 4", "line 2",
                    "d1")
    assert not out.exists()


@pytest.mark.parametrize("rows, words", [
    (["d1,5 Jan 2026,a.csv,p.toml"], ["line 2", "ISO 8601"]),
    (["d1,2026-01-05,,p.toml"], ["line 2", "records"]),
    (["d1,2026-01-05,a.csv||b.csv,p.toml"], ["empty file name"]),
    ([], ["no test"]),
])
def test_malformed_manifest_is_one_line(tmp_path, capsys, rows, words):
    path = _manifest(tmp_path, rows)
    _one_line_error(capsys, ["fleet", str(path), "--out", str(tmp_path / "R.csv")], *words)


def test_missing_column_is_one_line(tmp_path, capsys):
    path = tmp_path / "M.csv"
    path.write_text("drive,day,records,prior\nd1,2026-01-05,a.csv,p.toml\n", encoding="utf-8")
    _one_line_error(capsys, ["fleet", str(path), "--out", str(tmp_path / "R.csv")],
                    "missing column(s) date")
    path.write_text("drive;date;records;prior\nd1;2026-01-05;a.csv;p.toml\n", encoding="utf-8")
    _one_line_error(capsys, ["fleet", str(path), "--out", str(tmp_path / "R.csv")],
                    "a manifest has drive,date,records,prior, separated by commas (this one "
                    "uses ';')")


def test_results_of_another_manifest_are_refused(fleet, serial, tmp_path, capsys):
    out = tmp_path / "R.csv"
    out.write_bytes(serial[0].read_bytes())
    other = _manifest(tmp_path, ["d9,2026-01-05,x.csv,p.toml"])
    _one_line_error(capsys, ["fleet", str(other), "--out", str(out)], "another manifest",
                    "--force")
    assert out.read_bytes() == serial[0].read_bytes()  # untouched
    with pytest.raises(InputError, match="another manifest"):
        identify_fleet(other, out=out)
    rows = identify_fleet(other, out=out, force=True)  # the missing file: refused, no fit
    assert [r["status"] for r in rows] == ["refused"]
    assert read_results(out)[0] == read_manifest(other).sha256


def _first_weeks(fleet, path: Path) -> Path:
    """A manifest of the fleet's tests but its last week's, beside the fleet's."""
    lines = fleet.manifest.read_text(encoding="utf-8").splitlines(keepends=True)
    last = fleet.dates[-1].isoformat()
    path.write_text("".join(x for x in lines if f",{last}," not in x), encoding="utf-8")
    return path


def test_a_manifest_grown_by_a_week_completes_its_results(fleet, serial, tmp_path, capsys):
    """A fleet adds a week of tests to its manifest: the results of the earlier weeks
    are kept and only the new week is fitted (the whole manifest's fingerprint used to
    refuse the file, and --force fitted every week again)."""
    short = read_manifest(_first_weeks(fleet, fleet.manifest.with_name("FIRST.csv")))
    lines = serial[0].read_text(encoding="utf-8").splitlines(keepends=True)
    last = fleet.dates[-1].isoformat()
    out = tmp_path / "RESULTS.csv"  # the results of the shorter manifest, as it wrote them
    out.write_text(lines[0].replace(read_manifest(fleet.manifest).sha256, short.sha256)
                   + "".join(x for x in lines[1:] if f",{last}," not in x), encoding="utf-8")
    calls = []
    rows = identify_fleet(fleet.manifest, out=out, progress=lambda d, n: calls.append(d))
    assert calls == list(range(N_DRIVES * (N_WEEKS - 1), N_DRIVES * N_WEEKS + 1))
    assert rows == serial[1]
    assert out.read_bytes() == serial[0].read_bytes()
    # the other way, a manifest that dropped tests, would lose results: refused
    _one_line_error(capsys, ["fleet", str(short.path), "--out", str(out)],
                    "another manifest", f"drive-001 on {last} and {N_DRIVES - 1} more are "
                    "not in this one or had other files", "--force")
    assert out.read_bytes() == serial[0].read_bytes()


def test_a_manifest_may_drop_a_refused_test(fleet, serial, tmp_path):
    """A refused test has no result to lose: a manifest without it completes the file
    (its other rows are kept, nothing is fitted), where one that drops a fitted test is
    refused."""
    short = read_manifest(_first_weeks(fleet, fleet.manifest.with_name("FIRST2.csv")))
    last = fleet.dates[-1].isoformat()
    lines = serial[0].read_text(encoding="utf-8").splitlines(keepends=True)
    refused = [x.replace(f",{last},ok,", f",{last},refused,", 1) for x in lines[2:]]
    assert sum(f",{last},refused," in x for x in refused) == N_DRIVES
    out = tmp_path / "RESULTS.csv"
    out.write_text("".join(lines[:2] + refused), encoding="utf-8")
    calls = []
    kept = identify_fleet(short, out=out, progress=lambda d, n: calls.append(d))
    assert calls == [len(short.tests)]  # nothing fitted
    assert kept == [r for r in serial[1] if r["date"] != last]


def test_a_test_whose_files_changed_is_not_kept(fleet, serial, tmp_path, capsys):
    """A results row is kept for a test only with the files it was fitted from."""
    text = fleet.manifest.read_text(encoding="utf-8")
    first = text.splitlines()[1]
    drive, date, records, prior = first.split(",")
    changed = fleet.manifest.with_name("CHANGED.csv")
    changed.write_text(text.replace(first, ",".join(
        (drive, date, "|".join(reversed(records.split("|"))), prior))), encoding="utf-8")
    out = tmp_path / "RESULTS.csv"
    out.write_bytes(serial[0].read_bytes())
    _one_line_error(capsys, ["fleet", str(changed), "--out", str(out)],
                    f"{drive} on {date} is not in this one or had other files")
    assert out.read_bytes() == serial[0].read_bytes()


def test_results_written_before_the_tests_fingerprints_complete_their_manifest(
        fleet, serial, tmp_path):
    """A file without the ``inputs`` column (an earlier version's) is completed for
    the manifest it was written for, and written again with the column."""
    lines = serial[0].read_text(encoding="utf-8").splitlines(keepends=True)
    out = tmp_path / "RESULTS.csv"
    out.write_text(lines[0] + "".join(x.rstrip("\n").rsplit(",", 1)[0] + "\n"
                                      for x in lines[1:]), encoding="utf-8")
    assert read_results(out)[1][0]["inputs"] == ""
    calls = []
    rows = identify_fleet(fleet.manifest, out=out, progress=lambda d, n: calls.append(d))
    assert calls == [N_DRIVES * N_WEEKS] and rows == serial[1]
    assert out.read_bytes() == serial[0].read_bytes()


def test_a_file_that_is_no_results_file_is_refused(fleet, tmp_path, capsys):
    """As ``--out`` the advice names the flags; read from Python, no flag (a QA pass
    found the command line's words in ``read_results``)."""
    out = tmp_path / "notes.csv"
    out.write_text("a,b\n1,2\n", encoding="utf-8")
    _one_line_error(capsys, ["fleet", str(fleet.manifest), "--out", str(out)],
                    "not a backlashkit fleet results file", "give another --out or pass --force")
    with pytest.raises(InputError, match=r"not a backlashkit fleet results file \(its first "
                                         r"line is not '# backlashkit fleet results; \.\.\.'\)$"):
        read_results(out)


def test_unreachable_scheduler_is_one_line(fleet, tmp_path, capsys):
    out = tmp_path / "R.csv"
    _one_line_error(capsys, ["fleet", str(fleet.manifest), "--out", str(out), "--scheduler",
                             "tcp://127.0.0.1:9"], "cannot reach the Dask scheduler",
                    "tcp://127.0.0.1:9")
    assert not out.exists()


def test_results_columns_are_the_contract():
    for c in ("drive", "date", "theta", "std", "ci95_low", "ci95_high", "status", "reason"):
        assert c in RESULT_COLUMNS


def test_progress_is_silent_when_stderr_is_no_terminal(fleet, serial, tmp_path):
    out = tmp_path / "R.csv"
    out.write_bytes(serial[0].read_bytes())  # complete: nothing to fit
    proc = subprocess.run(
        [sys.executable, "-m", "backlashkit", "fleet", str(fleet.manifest), "--out", str(out)],
        capture_output=True, text=True, env={**os.environ, "COLUMNS": "80"}, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    # what was in --out is said apart from what ran (a QA pass read "6 identified" after
    # a rerun that fitted only a new week)
    assert f"6 tests (6 kept from {out}, 0 run now): 6 identified, 0 refused" in proc.stdout


def test_truth_table_holds_plain_numbers(fleet):
    """TRUTH.csv: every value but the drive's name reads back as a float, equal to the
    truth returned (it once held ``np.float64(...)`` strings)."""
    import csv

    with open(fleet.manifest.parent / "TRUTH.csv", encoding="utf-8", newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and not r[0].startswith("#")]
    header, body = rows[0], rows[1:]
    assert [r[0] for r in body] == fleet.drives
    values = np.array([[float(x) for x in r[1:]] for r in body])
    np.testing.assert_array_equal(values[:, header.index("theta0") - 1], fleet.theta0)
    np.testing.assert_array_equal(values[:, header.index("rate_rad_per_year") - 1], fleet.rate)
