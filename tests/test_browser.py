"""Every HTML page the toolkit writes, opened in a real headless browser.

Chromium (Debian's ``chromium`` package, which ``.ci/run`` installs) loads each page as
a reader's browser does. For each page the test asserts that every ``<img>`` loaded
(``naturalWidth > 0``), that no table cell is empty and that no "n/a n/a" is shown, and
it keeps a screenshot of the whole page in ``$BACKLASHKIT_ARTEFACTS`` (default: the
test's ``tmp_path``). The pages are those of ``make demo`` (the drive plot and the
``reproduce tao1995`` report), the ``identify --report`` page of the two-step and the
joint method, a small ``reproduce ravanbod2002`` report and the fleet's wear report.

Where no Chromium can be found, the tests skip and say so.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.io import write_csv

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: Names the Chromium binary goes by (Debian: chromium), or $BACKLASHKIT_CHROMIUM.
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: Width of the screenshots in CSS pixels: the pages' 1000 px column and its margins.
WIDTH = 1100
#: Tallest screenshot in px (a longer page is cut there; the checks still see all of it).
MAX_HEIGHT = 12000
#: Seconds one browser call may take (a cold start on a busy 2-core machine is ~3 s).
TIMEOUT = 120

#: Appended to a copy of each page: once every image has loaded or failed (the load
#: event), writes what the checks need into the DOM, which ``--dump-dom`` then prints.
PROBE = """<script>
window.addEventListener('load', function () {
  var imgs = Array.from(document.images).map(function (i) {
    return {src: i.getAttribute('src'), ok: i.complete && i.naturalWidth > 0}; });
  var empty = Array.from(document.querySelectorAll('td,th'))
    .filter(function (c) { return c.textContent.trim() === ''; })
    .map(function (c) { return c.parentElement.textContent.trim().slice(0, 80); });
  var pre = document.createElement('pre'); pre.id = 'bk-probe';
  pre.textContent = JSON.stringify({imgs: imgs, empty: empty, text: document.body.innerText,
    height: document.documentElement.scrollHeight});
  document.body.appendChild(pre);
});
</script>"""


def _chromium() -> str | None:
    given = os.environ.get("BACKLASHKIT_CHROMIUM")
    if given:
        return shutil.which(given)
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


CHROMIUM = _chromium()
NO_CHROMIUM = ("no Chromium found (tried " + ", ".join(CHROMIUM_NAMES) + "): install it with "
               "`apt-get install -y chromium` (.ci/run does) or set BACKLASHKIT_CHROMIUM")


@pytest.fixture(autouse=True)
def _need_chromium():
    """Skip without a browser, and say so in the warnings summary too (a skip's reason
    alone shows only with ``pytest -rs``)."""
    if CHROMIUM is None:
        warnings.warn(NO_CHROMIUM, UserWarning, stacklevel=1)
        pytest.skip(NO_CHROMIUM)


def _browser(profile: Path, *args: str) -> subprocess.CompletedProcess:
    """One headless Chromium call with its own profile (tests run in parallel)."""
    assert CHROMIUM is not None
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
           "--hide-scrollbars", "--disable-dev-shm-usage", f"--user-data-dir={profile}",
           *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, check=False)


def inspect_page(index: Path, work: Path) -> dict:
    """What a browser shows of ``index``: its images (loaded or not), its empty table
    cells, its text and its height in px."""
    probe = index.with_name(f".probe-{os.getpid()}-{index.name}")  # same folder: same links
    probe.write_text(index.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"),
                     encoding="utf-8")
    try:
        run = _browser(work / "profile-dom", "--virtual-time-budget=10000", "--dump-dom",
                       probe.as_uri())
    finally:
        probe.unlink()
    found = re.search(r'<pre id="bk-probe">(.*?)</pre>', run.stdout, re.S)
    assert found, f"Chromium did not load {index} (exit {run.returncode}): {run.stderr[-800:]}"
    return json.loads(html.unescape(found.group(1)))


def screenshot(index: Path, png: Path, height: int, work: Path) -> None:
    """A screenshot of the whole page (up to :data:`MAX_HEIGHT` px) into ``png``."""
    run = _browser(work / "profile-shot", f"--window-size={WIDTH},{min(height, MAX_HEIGHT)}",
                   f"--screenshot={png}", index.as_uri())
    assert png.is_file() and png.stat().st_size > 0, run.stderr[-800:]


def problems(seen: dict) -> list[str]:
    """What a reader would stumble on: broken images, empty cells, "n/a n/a"."""
    out = [f"image {i['src']} did not load" for i in seen["imgs"] if not i["ok"]]
    out += [f"empty table cell in the row {row!r}" for row in seen["empty"]]
    out += [f"shows {m.group(0)!r}" for m in re.finditer(r"n/a\s+n/a", seen["text"])]
    return out


# --- the pages ------------------------------------------------------------------------


def _demo_drive_plot(out: Path) -> Path:
    """``make demo``'s first command: paper A's experiment simulated and plotted, shown
    on a page of its own."""
    assert main(["simulate", str(EXAMPLES / "paper_drive.toml"), "--experiment",
                 "step-down", "--amplitude", "0.157", "--hold", "40", "--out",
                 str(out / "paper_experiment.csv"), "--plot",
                 str(out / "paper_experiment.png")]) == 0
    index = out / "index.html"
    index.write_text('<!DOCTYPE html><html><body><img src="paper_experiment.png" '
                     'alt="drive plot"></body></html>', encoding="utf-8")
    return index


def _demo_tao1995(out: Path) -> Path:
    """``make demo``'s second command."""
    main(["reproduce", "tao1995", "--report", str(out / "tao1995")])
    return out / "tao1995" / "index.html"


def _record_csv(out: Path) -> Path:
    """A step-down of paper A's drive from the steady state at t_s = 2 s (the 2 s the
    joint method needs before it), 2 s after it, 30 dB on both speeds, as a CSV file."""
    prior = bk.TwoMassDrive(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2,
                            f_sh=1.575e-2, theta=3.49e-2)
    t = signals.time_grid(4.0, 1e-3)
    u = signals.step_down(t, 0.942, t_s=2.0)
    r = prior.simulate(t, u, initial_state=prior.steady_state(0.942))
    sm, sl = np.random.SeedSequence(7).spawn(2)
    path = out / "exp.csv"
    write_csv(path, {"t": t, "torque": u, "w_motor": signals.add_noise(r.w_motor, 30, rng=sm),
                     "w_load": signals.add_noise(r.w_load, 30, rng=sl)})
    return path


def _from_rest_csv(out: Path) -> Path:
    """``make demo``'s drive started from rest: 0.942 N m for 2 s, then 0; 4 s, 30 dB on
    both speeds (the record docs/cli.md identifies with the joint method)."""
    path = out / "exp.csv"
    assert main(["simulate", str(EXAMPLES / "paper_drive.toml"), "--experiment", "step-down",
                 "--amplitude", "0.942", "--hold", "2", "--snr-motor", "30", "--snr-load",
                 "30", "--seed", "1", "--out", str(path)]) == 0
    return path


def _identify(method: str, record):
    def build(out: Path) -> Path:
        assert main(["identify", str(record(out)), "--drive",
                     str(EXAMPLES / "paper_drive.toml"), "--method", method, "--report",
                     str(out / "report")]) == 0
        return out / "report" / "index.html"

    return build


def _ravanbod2002(out: Path) -> Path:
    """A small run of paper A's protocol: two runs at one prior error."""
    main(["reproduce", "ravanbod2002", "--runs", "2", "--err-p", "0.1", "--jobs", "1",
          "--report", str(out / "ravanbod2002")])
    return out / "ravanbod2002" / "index.html"


def _fleet_wear(out: Path) -> Path:
    """``fleet --report``'s wear page from a results table of three drives (one wearing
    fast, one steady, one with a refused test), 12 weekly tests each."""
    import datetime as dt

    from backlashkit.fleet import write_wear_report

    rng = np.random.default_rng(5)
    rows = []
    for drive, rate in (("drive-001", 0.05), ("drive-002", 0.0), ("drive-003", 0.01)):
        for k in range(12):
            theta = 0.035 + rate * 7 * k / 365.25 + 2e-4 * rng.standard_normal()
            day = (dt.date(2026, 1, 5) + dt.timedelta(days=7 * k)).isoformat()
            rows.append({"drive": drive, "date": day, "status": "ok", "theta": theta,
                         "std": 2e-4, "ci95_low": theta - 4e-4, "ci95_high": theta + 4e-4,
                         "reason": ""})
    rows[-1] = {"drive": "drive-003", "date": rows[-1]["date"], "status": "refused",
                "theta": None, "reason": "e.csv: file not found"}
    return write_wear_report(rows, out / "wear")


PAGES = {
    "demo_drive_plot": _demo_drive_plot,
    "demo_tao1995": _demo_tao1995,
    "identify_two_step": _identify("two-step", _record_csv),
    "identify_joint": _identify("joint", _from_rest_csv),
    "reproduce_ravanbod2002": _ravanbod2002,
    "fleet_wear_report": _fleet_wear,
}


@pytest.fixture
def artefacts(tmp_path) -> Path:
    out = Path(os.environ.get("BACKLASHKIT_ARTEFACTS") or tmp_path / "artefacts")
    out.mkdir(parents=True, exist_ok=True)
    return out


@pytest.mark.parametrize("name", list(PAGES))
def test_page_reads_in_a_browser(name, tmp_path, artefacts):
    index = PAGES[name](tmp_path)
    seen = inspect_page(index, tmp_path)
    screenshot(index, artefacts / f"{name}.png", seen["height"], tmp_path)
    assert seen["imgs"], f"{name}: no image on the page"
    assert not problems(seen), f"{name}: " + "; ".join(problems(seen))


def test_the_checks_see_a_broken_page(tmp_path):
    """The checks can fail: a missing image, an empty cell and "n/a n/a" are reported."""
    index = tmp_path / "index.html"
    index.write_text('<!DOCTYPE html><html><body><img src="missing.png" alt="x">'
                     "<table><tr><td>search interval</td><td>n/a</td><td>n/a</td>"
                     "<td></td></tr></table></body></html>", encoding="utf-8")
    found = problems(inspect_page(index, tmp_path))
    assert found == ["image missing.png did not load",
                     "empty table cell in the row 'search intervaln/an/a'",
                     "shows 'n/a\\tn/a'"]
