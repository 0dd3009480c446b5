"""Progress bars on stderr (:class:`backlashkit.parallel.ProgressBar`): drawn on a
terminal, silent elsewhere and with ``--quiet``, never on stdout."""

from __future__ import annotations

import io
import json

import pytest

from backlashkit.cli import main
from backlashkit.parallel import ProgressBar, map_tasks


class _Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def _square(x: int) -> int:
    return x * x


def test_a_terminal_sees_done_of_total_and_the_time_left():
    term = _Terminal()
    with ProgressBar("squares", unit="fit", stream=term) as bar:
        assert bar.shown
        assert map_tasks(_square, [1, 2, 3, 4], progress=bar) == [1, 4, 9, 16]
    drawn = term.getvalue()
    assert "squares" in drawn and "4/4" in drawn and "fit" in drawn
    assert "<" in drawn  # tqdm's "elapsed<remaining"


def test_labels_name_the_task_running():
    """A fit's stages differ in kind and length: the bar names the one running (the QA
    pass saw only "6/7 stage" for 32 of 35 s), and none once all are done."""
    term = _Terminal()
    with ProgressBar("identify", unit="stage", stream=term,
                     labels=("starts", "first window", "continuation")) as bar:
        bar(1, 3)
        assert term.getvalue().endswith("first window]")
        bar(2, 3)
        assert term.getvalue().endswith("continuation]")
        bar(3, 3)
    assert term.getvalue().rstrip().endswith("stage/s]")


@pytest.mark.parametrize("stream, quiet", [(io.StringIO(), False), (_Terminal(), True)],
                         ids=["not a terminal", "quiet"])
def test_silent_off_a_terminal_and_when_quiet(stream, quiet):
    with ProgressBar("squares", quiet=quiet, stream=stream) as bar:
        assert not bar.shown
        map_tasks(_square, [1, 2], progress=bar)
    assert stream.getvalue() == ""
    assert "shown=False" in repr(bar)


def test_reproduce_json_is_stdout_and_json_out_a_file(tmp_path, capsys):
    """``--json`` prints the document alone on stdout (no bar: stderr is no terminal
    here); ``--json-out`` writes it, announced on stderr, and refuses to overwrite."""
    assert main(["reproduce", "tao1995", "--json", "--quiet"]) == 0
    out, err = capsys.readouterr()
    doc = json.loads(out)
    assert set(doc["variants"]) == {"exact", "smooth-filter", "none", "gain-only"}
    assert "MET" in err and "controller/s" not in err
    target = tmp_path / "t.json"
    assert main(["reproduce", "tao1995", "--json-out", str(target)]) == 0
    out, err = capsys.readouterr()
    assert json.loads(target.read_text()) == doc and "MET" in out
    assert f"backlashkit: wrote {target}" in err
    assert main(["reproduce", "tao1995", "--json-out", str(target)]) == 2
    err = capsys.readouterr().err
    assert f"--json-out {target} already exists; pass --force" in err
    assert main(["reproduce", "tao1995", "--json-out", "/dev/null"]) == 0  # no user's file
    capsys.readouterr()
    # a directory is refused before the study runs (the QA pass: after it)
    assert main(["reproduce", "tao1995", "--json-out", str(tmp_path)]) == 2
    out, err = capsys.readouterr()
    assert f"--json-out {tmp_path} is a directory; give a file name in it" in err
    assert "MET" not in out + err


def _interval_inputs():
    """What a fit hands its interval object, with refits that return 0.9, 1.1, 1.0."""
    import numpy as np

    from backlashkit.identify.intervals import IntervalInputs

    draws = iter([0.9, 1.1, 1.0])
    return IntervalInputs(theta=1.0, std=0.6, z=np.zeros(1), cov_z=np.eye(1), cost=0.0,
                          residual=None, fd_step=1e-6, resample=lambda rng: None,
                          refit=lambda records: next(draws))


def test_bootstrap_refits_report_their_progress(monkeypatch):
    """``ParametricBootstrap(progress=...)``: a callable hears every refit; True draws a
    bar on a terminal stderr and nothing elsewhere; the option is no part of the
    configuration's equality and is checked."""
    import backlashkit as bk
    from backlashkit.errors import InputError

    heard = []
    bk.ParametricBootstrap(3, progress=lambda done, total: heard.append((done, total))
                           )._interval(_interval_inputs())
    assert heard == [(0, 3), (1, 3), (2, 3), (3, 3)]
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    boot = bk.ParametricBootstrap(3, progress=True)._interval(_interval_inputs())
    assert boot.bootstrap_thetas.tolist() == [0.9, 1.1, 1.0]
    assert "bootstrap" in term.getvalue() and "3/3" in term.getvalue()
    assert "refit" in term.getvalue()
    pipe = io.StringIO()
    monkeypatch.setattr("sys.stderr", pipe)
    bk.ParametricBootstrap(3, progress=True)._interval(_interval_inputs())
    assert pipe.getvalue() == ""
    assert bk.ParametricBootstrap(3, progress=True) == bk.ParametricBootstrap(3)
    with pytest.raises(InputError, match="progress must be True, False or a callable"):
        bk.ParametricBootstrap(3, progress="yes")


@pytest.mark.parametrize("quiet", [False, True], ids=["terminal", "quiet"])
def test_identify_bootstrap_draws_its_bar_on_stderr(short_csv, monkeypatch, capsys, quiet):
    """``identify --bootstrap N`` on a terminal stderr: the refits' bar there, unless
    ``--quiet``; stdout holds the JSON document alone either way."""
    from pathlib import Path

    drive = str(Path(__file__).resolve().parents[1] / "examples" / "paper_drive.toml")
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    argv = ["identify", str(short_csv), "--drive", drive, "--bootstrap", "2", "--json"]
    assert main(argv + (["--quiet"] if quiet else [])) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["interval"] == "bootstrap"
    drawn = term.getvalue()
    assert ("bootstrap" in drawn and "2/2" in drawn) is not quiet, drawn


def test_joint_fit_reports_its_stages(short_csv, monkeypatch, capsys):
    """``JointIdentifier(progress=callable)`` hears every stage of the search, in order,
    up to the last; the CLI's joint fit draws an "identify" bar on a terminal stderr."""
    from pathlib import Path

    import backlashkit as bk
    from backlashkit.errors import InputError
    from backlashkit.identify.readers import read_records
    from backlashkit.io import read_drive_toml

    drive = Path(__file__).resolve().parents[1] / "examples" / "paper_drive.toml"
    heard = []
    fit = bk.JointIdentifier(read_drive_toml(drive, require_theta=False),
                             interval=bk.FisherInterval(),
                             progress=lambda done, total: heard.append((done, total)))
    fit.fit(read_records(short_csv))
    total = heard[-1][1]
    assert total in (7, 14) and heard[-1][0] == total
    assert [d for d, _ in heard] == list(range(1, total + 1))
    assert "progress" not in repr(bk.JointIdentifier(fit.prior))
    with pytest.raises(InputError, match="progress must be True, False or a callable"):
        bk.JointIdentifier(fit.prior, progress="yes").fit(read_records(short_csv))
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    assert main(["identify", str(short_csv), "--drive", str(drive), "--interval",
                 "fisher"]) == 0
    assert "identify" in term.getvalue() and "7/7" in term.getvalue()


def _read_pty(master, *, timeout=5.0):
    """All a pseudo-terminal holds: one read may return only the first frame."""
    import os
    import select

    out = b""
    while select.select([master], [], [], timeout)[0]:
        chunk = os.read(master, 65536)
        out += chunk
        if not chunk or b"3/3" in out:
            break
        timeout = 0.5
    return out.decode("utf-8", "replace")


def test_a_terminal_of_no_size_still_sees_the_bar():
    """A pseudo-terminal that reports 0 columns and 0 rows (some CI consoles and
    ``script``): tqdm hid the bar below the last of 0 rows, so a long run looked hung."""
    import os

    master, slave = os.openpty()
    try:
        with os.fdopen(slave, "w", closefd=False) as stream:
            assert tuple(os.get_terminal_size(slave)) == (0, 0)
            with ProgressBar("demo", stream=stream) as bar:
                bar(0, 3)
                bar(3, 3)
        assert "3/3" in _read_pty(master)
    finally:
        os.close(slave)
        os.close(master)
