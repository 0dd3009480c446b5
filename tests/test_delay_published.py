"""Closed forms and published values of the delay margin (backlashkit.delay).

Each closed form is met to 1e-9 relative (the issue asks 1e-6) by both methods; each
published value to the digits published.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest

from backlashkit.delay import DelaySystem, delay_margin, spectral_margin

METHODS = ("sweep", "kronecker")
REL = 1e-9


def published(x: float, digits: int = 4) -> float:
    """``x`` as the papers print it: truncated (not rounded) to ``digits`` decimals."""
    return math.floor(x * 10**digits) / 10**digits


def hayes_margin(a: float, b: float) -> float:
    """``x' = a x + b x(t - h)`` (Hayes 1950): stable at h = 0 iff a + b < 0; crossings
    iff |b| > |a|, at omega = sqrt(b^2 - a^2), h = arccos(-a/b) / omega."""
    if abs(b) <= abs(a):
        return math.inf
    w = math.sqrt(b * b - a * a)
    return math.acos(-a / b) / w


def neutral_margin(a: float, b: float, c: float) -> float:
    """``x' - c x'(t-h) = a x + b x(t-h)``, |c| < 1: at s = j omega,
    omega^2 = (b^2 - a^2) / (1 - c^2), exp(-j omega h) = (j omega - a) / (b + j c omega)."""
    if abs(b) <= abs(a):
        return math.inf
    w = math.sqrt((b * b - a * a) / (1 - c * c))
    z = (1j * w - a) / (b + 1j * c * w)
    return ((-cmath.phase(z)) % (2 * math.pi)) / w


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("a", [0.1, 1.0, 7.5, 300.0])
def test_pure_delay_pi_over_2a(method, a):
    r = delay_margin(0.0, [-a], method=method)
    assert r.h_max == pytest.approx(math.pi / (2 * a), rel=REL)
    assert r.omega == pytest.approx(a, rel=REL)
    assert r.stable_at_zero and not r.delay_independent
    assert r.verification["passed"]


HAYES = [(-1.0, -2.0), (0.5, -2.0), (-0.3, -0.31), (0.9, -1.0), (-3.0, -2.0), (-1.0, -1.0),
         (-2.0, 1.0), (-1.0, 5.0)]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("a,b", HAYES)
def test_hayes_scalar(method, a, b):
    r = delay_margin(a, [b], method=method)
    if a + b >= 0:  # unstable at h = 0: an answer, not an error
        assert r.h_max == 0.0 and not r.stable_at_zero
        return
    expected = hayes_margin(a, b)
    if math.isinf(expected):
        assert r.h_max == math.inf and r.delay_independent
    else:
        assert r.h_max == pytest.approx(expected, rel=REL)


NEUTRAL = [(-1.0, -2.0, 0.5), (-1.0, -2.0, -0.5), (0.5, -2.0, 0.3), (-1.0, -3.0, 0.9),
           (-2.0, -1.0, 0.4), (-1.0, -2.0, -0.95)]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("a,b,c", NEUTRAL)
def test_neutral_scalar(method, a, b, c):
    r = delay_margin(a, [b], [c], method=method)
    expected = neutral_margin(a, b, c)
    assert r.stable_at_zero
    if math.isinf(expected):
        assert r.h_max == math.inf and r.delay_independent
    else:
        assert r.h_max == pytest.approx(expected, rel=REL)
        assert r.verification["passed"]


def test_neutral_with_unstable_difference_operator_has_no_margin():
    r = delay_margin(-3.0, [-0.5], [1.5])  # |c| > 1: unstable for every h > 0
    assert r.h_max == 0.0 and r.difference_radius == pytest.approx(1.5)
    assert r.stability_windows((0, 10)) == []


@pytest.mark.parametrize("method", METHODS)
def test_classic_two_state_6_1725(method):
    """A0 = diag(-2, -0.9), A1 = [[-1, 0], [-1, -1]]: h_max = 6.1725 (e.g. Gu, Kharitonov
    & Chen 2003, the classic benchmark of delay-dependent criteria)."""
    r = delay_margin(np.diag([-2.0, -0.9]), [np.array([[-1.0, 0.0], [-1.0, -1.0]])],
                     method=method)
    assert published(r.h_max) == 6.1725
    # closed form of the second block: j w + 0.9 + exp(-j w h) = 0
    w = math.sqrt(1 - 0.81)
    assert r.h_max == pytest.approx(math.acos(-0.9) / w, rel=REL)
    assert r.omega == pytest.approx(w, rel=REL)


def allmargin_loop():
    """L(s) = 25 / (s^3 + 10 s^2 + 10 s + 10) under unity negative feedback with the delay
    in the loop: x' = A x - B C x(t - h)."""
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-10.0, -10.0, -10.0]])
    b = np.array([[0.0], [0.0], [1.0]])
    c = np.array([[25.0, 0.0, 0.0]])
    return a, [-b @ c]


@pytest.mark.parametrize("method", METHODS)
def test_matlab_allmargin_example_0_2847(method):
    a0, a = allmargin_loop()
    r = delay_margin(a0, a, method=method)
    assert published(r.h_max) == 0.2847  # MATLAB allmargin documentation: DelayMargin 0.2847
    control = pytest.importorskip("control")
    _, pm, _, _, wgc, _ = control.stability_margins(control.tf(25, [1, 10, 10, 10]),
                                                    returnall=True)
    siso = min(np.deg2rad(p % 360) / w for p, w in zip(pm, wgc, strict=True))
    assert r.h_max == pytest.approx(siso, rel=1e-9)


OLGAC_A = np.array([[-1.0, 13.5, -1.0], [-3.0, -1.0, -2.0], [-2.0, -1.0, -4.0]])
OLGAC_B = np.array([[-5.9, 7.1, -70.3], [2.0, -1.0, 5.0], [2.0, 0.0, 6.0]])


@pytest.mark.parametrize("method", METHODS)
def test_olgac_sipahi_2002_two_windows(method):
    """Olgac & Sipahi, IEEE TAC 47(5) 2002, example: stable for tau in [0, 0.1624) and
    (0.1859, 0.2219), unstable beyond. The matrices are confirmed by an independent copy:
    example 3 of Haag, Muenz & Allgoewer (2009) as transcribed in the glob_stab examples
    (github.com/schauss/glob_stab, examples/haag2009/haag2009examples.m). The window
    edges are recalled from the paper, not confirmed. The computed edges are 0.162346,
    0.185906, 0.221985: they match the recalled figures to 3 decimals but not all to 4
    (0.16235 is 0.1623 either rounded or truncated), so the test asserts 3 decimals and
    the two-window structure."""
    r = delay_margin(OLGAC_A, [OLGAC_B], method=method)
    windows = r.stability_windows((0.0, 2.0))
    assert len(windows) == 2
    (a1, b1), (a2, b2) = windows
    assert a1 == 0.0
    assert round(b1, 3) == round(0.1624, 3)
    assert round(a2, 3) == round(0.1859, 3)
    assert round(b2, 3) == round(0.2219, 3)
    assert r.h_max == b1


def test_olgac_sipahi_windows_by_the_spectral_method():
    """Independent: the rightmost root (spectral) is left of the axis inside each window
    and right of it between and after them."""
    from backlashkit.delay import rightmost_root

    s = DelaySystem(OLGAC_A, [OLGAC_B])
    r = delay_margin(OLGAC_A, [OLGAC_B], verify=False)
    (_, b1), (a2, b2) = r.stability_windows((0.0, 1.0))
    for h, stable in ((0.5 * b1, True), (0.5 * (b1 + a2), False), (0.5 * (a2 + b2), True),
                      (1.2 * b2, False), (0.5, False)):
        assert (rightmost_root(s, h, n_nodes=60).real < 0) == stable, h
    assert spectral_margin(s, 0.3, n_scan=30, n_nodes=60) == pytest.approx(b1, rel=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_tangential_touch(method):
    """x'' + 2 zeta x' + x + k x(t - h) = 0 with k = 2 zeta sqrt(1 - zeta^2): |z(omega)|
    touches 1 at omega* = sqrt(1 - 2 zeta^2) without crossing; the root touches the
    axis at h* and goes back. h_max = h*, windows split there."""
    zeta = 0.3
    k = 2 * zeta * math.sqrt(1 - zeta**2)
    w = math.sqrt(1 - 2 * zeta**2)
    z = -(1 - w * w + 2j * zeta * w) / k
    h_star = ((-cmath.phase(z)) % (2 * math.pi)) / w
    r = delay_margin(np.array([[0.0, 1.0], [-1.0, -2 * zeta]]),
                     [np.array([[0.0, 0.0], [-k, 0.0]])], method=method)
    assert r.h_max == pytest.approx(h_star, rel=1e-6)  # a double root: sqrt(eps)
    assert r.verification["touch"] and r.verification["passed"]
    windows = r.stability_windows((0.0, 3 * h_star))
    assert windows[0][1] == pytest.approx(h_star, rel=1e-6)
    assert windows[1][0] == pytest.approx(h_star, rel=1e-6)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("excess", [1e-6, 1e-3])
def test_clustered_crossings(method, excess):
    """Just past the touch the two crossings lie 1e-3 .. 1e-6 apart in frequency, inside
    one grid cell of the sweep; both are found and the system is unstable between."""
    zeta = 0.3
    k = 2 * zeta * math.sqrt(1 - zeta**2) * (1 + excess)
    r = delay_margin(np.array([[0.0, 1.0], [-1.0, -2 * zeta]]),
                     [np.array([[0.0, 0.0], [-k, 0.0]])], method=method)
    assert len(r.crossings) == 2
    (w1, h1), (w2, h2) = sorted((c.omega, c.h0) for c in r.crossings)
    assert 0 < (w2 - w1) / w1 < 10 * math.sqrt(excess)
    # each is a root of x'' + 2 zeta x' + x + k x(t-h) at s = j omega
    for w, h in ((w1, h1), (w2, h2)):
        assert abs(-w * w + 2j * zeta * w + 1 + k * cmath.exp(-1j * w * h)) < 1e-12
    assert r.verification["passed"] and not r.verification["touch"]
    (a1, b1), (a2, _) = r.stability_windows((0.0, 5.0))[:2]
    assert b1 == pytest.approx(r.h_max) and a2 > b1


@pytest.mark.parametrize("method", METHODS)
def test_omega_to_zero_is_not_a_huge_margin(method):
    """x' = -x - x(t - h) (and a 2x2 version): |z| -> 1 only as omega -> 0; the system
    is stable for every delay and no spurious finite h_max may be reported."""
    r = delay_margin(-1.0, [-1.0], method=method)
    assert r.h_max == math.inf and r.delay_independent
    a0 = np.array([[-1.0, 0.5], [0.0, -2.0]])
    a1 = np.array([[-1.0, 0.0], [0.3, -1.0]])
    r = delay_margin(a0, [a1], method=method)
    assert r.h_max == math.inf and r.delay_independent and r.stable_at_zero


@pytest.mark.parametrize("method", METHODS)
def test_singular_last_coefficient_infinite_eigenvalues(method):
    """A_q singular (and A_1 = 0): infinite generalized eigenvalues of the pencil."""
    a0 = np.array([[0.0, 1.0], [-2.0, -3.0]])
    a2 = np.array([[0.0, 0.0], [-4.0, -1.0]])  # rank 1: crossing at omega = sqrt(2)
    r = delay_margin(a0, [np.zeros((2, 2)), a2], method=method)
    s = DelaySystem(a0, [np.zeros((2, 2)), a2])
    assert 0 < r.h_max < math.inf
    assert r.verification["passed"]
    assert spectral_margin(s, 2 * r.h_max, n_scan=40, n_nodes=50) == pytest.approx(
        r.h_max, rel=1e-9)


def test_unstable_at_zero_is_an_answer():
    r = delay_margin(np.diag([0.5, -1.0]), [np.eye(2) * -0.2])
    assert r.h_max == 0.0 and not r.stable_at_zero and not r.delay_independent
    assert r.as_dict()["h_max"] == 0.0


def test_every_window_is_stable_by_the_spectral_method():
    """An oscillator with delayed damping: the windows come back periodically; the
    rightmost root (spectral, independent) is left of the axis in the middle of each."""
    from backlashkit.delay import rightmost_root

    a0 = np.array([[0.0, 1.0], [-1.0, 0.1]])
    a1 = np.array([[0.0, 0.0], [0.0, -0.5]])
    r = delay_margin(a0, [a1])
    s = DelaySystem(a0, [a1])
    windows = r.stability_windows((0.0, 15.0))
    assert windows and windows[0][0] == 0.0
    for a, b in windows:
        assert rightmost_root(s, 0.5 * (a + b), n_nodes=60).real < 0
    gaps = [(b, c) for (_, b), (c, _) in zip(windows[:-1], windows[1:], strict=True)]
    for b, c in gaps:
        assert rightmost_root(s, 0.5 * (b + c), n_nodes=60).real > 0


def test_no_delay_terms():
    r = delay_margin(np.diag([-1.0, -2.0]), [np.zeros((2, 2))])
    assert r.h_max == math.inf and r.delay_independent
