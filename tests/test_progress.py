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
