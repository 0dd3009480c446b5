"""Compare two ``backlashkit reproduce ravanbod2002 --json`` documents number by number.

Every value must be identical except the timings (keys containing ``seconds``) and the
worker count (``jobs``), which do not change the estimates. Used to show that a change
leaves the reproduction's estimates as they were, to the last digit::

    backlashkit reproduce ravanbod2002 --runs 10 --seed 2002 --jobs 2 --json-out new.json
    python benchmarks/compare_reproduce.py old.json new.json

Prints ``IDENTICAL (timings excluded)`` and exits 0, or the first 50 differences and
exits 1. With ``--in-std``, a change that is allowed to move the estimates is measured
instead: per ``Err_p`` and method, the largest change of a run's estimate in standard
deviations of the old runs, and the change of the mean in standard errors of the mean
(``std / sqrt(runs)``); it exits 1 when a mean moves by more than one standard error::

    python benchmarks/compare_reproduce.py --in-std old.json new.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys

#: Keys whose values may differ between identical reproductions.
SKIP = ("seconds", "jobs")


def differences(a, b, path: str = "") -> list[str]:
    """Paths at which the JSON values ``a`` and ``b`` differ (timings skipped)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if any(s in k for s in SKIP):
                continue
            if k not in a or k not in b:
                out.append(f"{path}/{k}: only in {'new' if k not in a else 'old'}")
            else:
                out += differences(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: lengths {len(a)} and {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} and {b!r}"]


def in_std(old, new) -> bool:
    """Print how far each method's estimates moved; True if every mean stayed within
    one standard error of the mean."""
    ok = True
    print(f"{'Err_p':>5} {'method':<10} {'max run change (std)':>21} {'mean change (SE)':>17}")
    for ra, rb in zip(old["rows"], new["rows"], strict=True):
        for m in ("two_step", "regression", "joint"):
            a, b = ra["methods"][m], rb["methods"][m]
            pairs = [(x, y) for x, y in zip(a["estimates"], b["estimates"], strict=True)
                     if x is not None and y is not None]
            std = a["std"]
            se = std / math.sqrt(len(a["estimates"]))
            run = max((abs(y - x) for x, y in pairs), default=math.nan) / std
            mean = (b["mean"] - a["mean"]) / se
            ok &= abs(mean) <= 1.0
            print(f"{ra['err_p']:5.0%} {m:<10} {run:21.3g} {mean:17.3g}")
        print(f"{'':5} {'joint':<10} coverage {ra['methods']['joint']['coverage95']:.0%} -> "
              f"{rb['methods']['joint']['coverage95']:.0%}, paper A's model kept in "
              f"{rb['methods']['joint'].get('paper_model', math.nan):.0%}")
    print("every mean within one standard error" if ok else "a mean moved by more than "
          "one standard error")
    return ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", metavar="OLD.json")
    parser.add_argument("new", metavar="NEW.json")
    parser.add_argument("--in-std", action="store_true",
                        help="measure how far the estimates moved instead of asking for "
                        "identical documents")
    args = parser.parse_args()
    old, new = (json.load(open(p, encoding="utf-8")) for p in (args.old, args.new))
    if args.in_std:
        return 0 if in_std(old, new) else 1
    found = differences(old, new)
    print("\n".join(found[:50]) if found else "IDENTICAL (timings excluded)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
