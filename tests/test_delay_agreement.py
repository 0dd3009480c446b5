"""Chen's sweep, the Kronecker-sum pencil and the spectral method agree on random
stable systems (n <= 6, q <= 3), seeded.

Run with ``-s`` to print the number of cases and the largest disagreements.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from backlashkit.delay import DelaySystem, delay_margin, rightmost_root, spectral_margin

#: Number of random systems; seed of the whole batch.
N_CASES = 60
SEED = 20260522
#: Agreement required between the two methods (relative, on h_max and every window edge).
AGREE = 1e-9
#: Relative distance from h_max at which the spectral rightmost root must change sign.
SIGN_STEP = 1e-4


def random_system(rng: np.random.Generator) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """A random system, stable at h = 0, with delayed terms strong enough to give a finite
    margin in most draws; the neutral terms are small (difference operator stable)."""
    n = int(rng.integers(1, 7))
    q = int(rng.integers(1, 4))
    a = [rng.normal(size=(n, n)) * rng.uniform(0.3, 2.0) for _ in range(q)]
    a0 = rng.normal(size=(n, n))
    shift = max(np.linalg.eigvals(a0 + sum(a)).real) + rng.uniform(0.05, 1.0)
    b = [rng.normal(size=(n, n)) * 0.1 / (n * q) for _ in range(q)]
    return a0 - shift * np.eye(n), a, b


def cases():
    children = np.random.SeedSequence(SEED).spawn(N_CASES)
    out = []
    for i, child in enumerate(children):
        a0, a, b = random_system(np.random.default_rng(child))
        out.append((i, a0, a, b if i % 4 == 3 else None))  # every fourth one neutral
    return out


CASES = cases()
_SUMMARY: dict[str, float] = {"finite": 0, "inf": 0, "worst": 0.0, "worst_raw": 0.0}


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"case{c[0]}")
def test_methods_agree(case):
    _, a0, a, b = case
    r1 = delay_margin(a0, a, b, method="sweep", verify=False)
    r2 = delay_margin(a0, a, b, method="kronecker", verify=False)
    raw1 = delay_margin(a0, a, b, method="sweep", verify=False, polish=False)
    raw2 = delay_margin(a0, a, b, method="kronecker", verify=False, polish=False)
    assert r1.stable_at_zero and r2.stable_at_zero
    if math.isinf(r2.h_max):
        _SUMMARY["inf"] += 1
        assert math.isinf(r1.h_max) and r1.delay_independent and r2.delay_independent
        return
    _SUMMARY["finite"] += 1
    rel = abs(r1.h_max - r2.h_max) / r2.h_max
    rel_raw = abs(raw1.h_max - raw2.h_max) / raw2.h_max
    _SUMMARY["worst"] = max(_SUMMARY["worst"], rel)
    _SUMMARY["worst_raw"] = max(_SUMMARY["worst_raw"], rel_raw)
    assert rel <= AGREE and rel_raw <= AGREE
    assert r1.omega == pytest.approx(r2.omega, rel=AGREE)
    span = (0.0, 5 * r2.h_max)
    w1, w2 = r1.stability_windows(span), r2.stability_windows(span)
    assert len(w1) == len(w2)
    for (p, q_), (u, v) in zip(w1, w2, strict=True):
        assert p == pytest.approx(u, rel=AGREE, abs=1e-12)
        assert q_ == pytest.approx(v, rel=AGREE, abs=1e-12)


def _finite(case):
    """The sweep's answer, the system and a fine collocation degree for it (one that
    resolves the crossing root); skips a system stable for every delay."""
    _, a0, a, b = case
    r = delay_margin(a0, a, b, verify=False)
    if math.isinf(r.h_max):
        pytest.skip("stable for every delay")
    s = DelaySystem(a0, a, b)
    return r, s, 40 + int(2 * r.omega * s.q * r.h_max)


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"case{c[0]}")
def test_spectral_root_changes_sign_at_h_max(case):
    """Independent of both methods: the rightmost root by Chebyshev collocation is left
    of the axis just below h_max and right of it just above."""
    r, s, nodes = _finite(case)
    below = rightmost_root(s, r.h_max * (1 - SIGN_STEP), n_nodes=nodes).real
    above = rightmost_root(s, r.h_max * (1 + SIGN_STEP), n_nodes=nodes).real
    assert below < 0 < above


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"case{c[0]}")
def test_default_collocation_is_fine_enough_for_the_check(case):
    """The default check solves at ``default_nodes`` (at least ``MIN_NODES``, 12): at
    the two delays it checks, its rightmost root has the sign and three digits of the
    one from the fine collocation above."""
    from backlashkit.delay.margin import VERIFY_STEP

    r, s, nodes = _finite(case)
    for h in (r.h_max * (1 - VERIFY_STEP), r.h_max * (1 + VERIFY_STEP)):
        coarse, fine = rightmost_root(s, h).real, rightmost_root(s, h, n_nodes=nodes).real
        assert (coarse < 0) == (fine < 0)
        assert coarse == pytest.approx(fine, rel=1e-3)


@pytest.mark.parametrize("case", CASES[:12], ids=lambda c: f"case{c[0]}")
def test_spectral_scan_finds_the_same_margin(case):
    """The spectral scan with bisection in h (no knowledge of omega) finds h_max."""
    r, s, nodes = _finite(case)
    h = spectral_margin(s, 1.5 * r.h_max, n_scan=30, n_nodes=nodes, xtol=1e-11)
    assert h == pytest.approx(r.h_max, rel=1e-8)


def test_summary():
    """Most of the seeded systems have a finite margin, so that the agreement tests test
    something; prints the agreement figures of the cases this process ran (with ``-s``;
    under pytest-xdist, a worker runs only some of them, so the count is made here)."""
    finite = sum(not math.isinf(delay_margin(a0, a, b, verify=False).h_max)
                 for _, a0, a, b in CASES)
    ran = int(_SUMMARY["finite"] + _SUMMARY["inf"])
    print(f"\ndelay agreement: {N_CASES} random systems (seed {SEED}), {finite} with finite "
          f"h_max; of the {ran} compared in this process, the largest relative difference "
          f"sweep vs kronecker: {_SUMMARY['worst']:.2e} polished, "
          f"{_SUMMARY['worst_raw']:.2e} unpolished")
    assert finite >= N_CASES // 2
