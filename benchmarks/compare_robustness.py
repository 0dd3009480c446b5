"""Compare two ``benchmarks/robustness_joint.py --dump`` files trial by trial.

Used to show what a change of the search does to the robustness study: how many
estimates moved, by how much in the old fit's standard errors, and the coverage and
errors of both. Run the same study (same ``--trials`` and ``--seed``) on both trees::

    python benchmarks/robustness_joint.py --trials 20 --seed 5 --dump new.json
    python benchmarks/compare_robustness.py old.json new.json

The new run may take only some of the old one's ``--scenarios``: the old file's same
trials are then compared.

Prints the trials whose estimate moved by more than :data:`SHOWN` of its old standard
error, the largest change, and per file the coverage of the 95 % intervals and the
trials beyond 5 % of ``theta``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

#: Changes (in the old fit's standard errors) below this are counted, not listed.
SHOWN = 0.05
#: The error asked of an estimate (robustness.md's bar), as a share of theta.
ERR_BAR = 0.05


def summary(rows: list[dict]) -> str:
    """Coverage of the 95 % intervals and the trials beyond :data:`ERR_BAR`."""
    cover = sum(r["ci95"][0] <= r["theta"] <= r["ci95"][1] for r in rows)
    beyond = sum(abs(r["estimate"] / r["theta"] - 1) > ERR_BAR for r in rows)
    return f"covers {cover}/{len(rows)}, {beyond} beyond {ERR_BAR:.0%}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("old")
    p.add_argument("new")
    args = p.parse_args(argv)
    old, new = (json.loads(Path(f).read_text()) for f in (args.old, args.new))
    by_key = {(r["scenario"], r["trial"]): r for r in old}
    keys = [(r["scenario"], r["trial"]) for r in new]
    if not set(keys) <= set(by_key):
        print("the new file holds trials the old one does not: run the same --trials and "
              "--seed (the new run may take fewer --scenarios)")
        return 2
    if len(keys) < len(old):
        print(f"compared on the new file's {len(keys)} of the old file's {len(old)} trials")
        old = [by_key[k] for k in keys]
    moved = []
    for a, b in zip(old, new, strict=True):
        change = abs(b["estimate"] - a["estimate"]) / a["std"]
        if change > 0:
            moved.append((change, a, b))
    moved.sort(key=lambda m: -m[0])
    for change, a, b in moved:
        if change > SHOWN:
            # dumps since -2 log L was kept say which of the two fits is the better
            rise = (f", -2 log L {b['m2ll'] - a['m2ll']:+.3g} from the old fit's"
                    if "m2ll" in a and "m2ll" in b else "")
            print(f"scenario {a['scenario']:>2} ({a['drive']}, {a['theta_deg']:g} deg, "
                  f"{a['snr_db']:g} dB) trial {a['trial']:>2}: "
                  f"{100 * (a['estimate'] / a['theta'] - 1):+.2f} % -> "
                  f"{100 * (b['estimate'] / b['theta'] - 1):+.2f} %, {change:.3g} old std"
                  + rise)
    largest = moved[0][0] if moved else 0.0
    print(f"{len(moved)} of {len(old)} estimates changed, "
          f"{sum(m[0] > SHOWN for m in moved)} by more than {SHOWN:g} old std; "
          f"largest change {largest:.3g} old std")
    print(f"old: {summary(old)}; new: {summary(new)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
