"""backlashkit.delay: one-line errors on bad input, the result's API, the TOML reader and
the numpydoc docstrings of the public names."""

from __future__ import annotations

import importlib
import inspect
import json
import math

import numpy as np
import pytest

from backlashkit.delay import DelaySystem, delay_margin, read_delay_system
from backlashkit.errors import InputError


@pytest.mark.parametrize(
    "args, match",
    [
        ((np.ones((2, 3)), [np.eye(2)]), r"A0 must be a square matrix; got shape \(2, 3\)"),
        ((np.eye(2), [np.eye(3)]), r"A\[0\] \(delay 1 h\) has shape \(3, 3\); it must match A0"),
        ((np.eye(2), [np.eye(2), np.ones((2, 1))]), r"A\[1\] \(delay 2 h\) must be a square"),
        ((np.array([[1.0, np.nan], [0, 1]]), [np.eye(2)]), r"A0\[0, 1\] is nan"),
        ((-np.eye(2), [np.array([[0, np.inf], [0, 0]])]), r"A\[0\] \(delay 1 h\)\[0, 1\] is inf"),
        ((-1.0, [-0.5], [np.eye(2)]), r"B\[0\] \(delay 1 h\) has shape \(2, 2\)"),
        ((np.eye(2), np.eye(2)), r"A must be a list of 2x2 matrices .* wrap it in a list"),
        ((-1.0, [[1, 2], [3]]), r"A\[0\] \(delay 1 h\) must be a square matrix"),
        ((["a"], [-1.0]), r"A0 must be a real matrix of numbers"),
        ((-1.0, [-0.5], [1.0]), r"B: the neutral difference operator is not strongly stable"),
        ((-1.0, [-0.5], [[0.0], [-1.0]]), r"not strongly stable"),
        ((np.eye(1) * -1, [1j]), r"must be a real matrix"),
    ],
)
def test_one_line_input_errors(args, match):
    with pytest.raises(InputError, match=match) as exc:
        delay_margin(*args)
    assert "\n" not in str(exc.value)


def test_bad_options():
    with pytest.raises(InputError, match="method must be one of sweep, kronecker; got 'x'"):
        delay_margin(-1.0, [-0.5], method="x")
    with pytest.raises(InputError, match="n_omega must be an integer from 10 to 1,000,000"):
        delay_margin(-1.0, [-0.5], n_omega=3)
    r = delay_margin(0.0, [-1.0])
    with pytest.raises(InputError, match="h_range must be finite with 0 <= lo < hi"):
        r.stability_windows((2.0, 1.0))


def test_options_are_keyword_only():
    with pytest.raises(TypeError):
        delay_margin(0.0, [-1.0], None, "kronecker")  # type: ignore[misc]


def test_system_shapes_padding_and_trimming():
    s = DelaySystem(-1.0, [-0.5, 0.0, 0.0], [0.0, 0.2])
    assert (s.n, s.q, s.neutral) == (1, 2, True)
    assert s.A[1][0, 0] == 0.0 and s.B[0][0, 0] == 0.0
    assert repr(s) == "DelaySystem(n=1, q=2, neutral)"


def test_result_fields_and_json():
    r = delay_margin(0.0, [-2.0])
    d = r.as_dict()
    assert d["h_max"] == pytest.approx(math.pi / 4)
    assert d["omega"] == pytest.approx(2.0)
    assert d["stable_at_zero"] is True and d["delay_independent"] is False
    assert d["windows"] == [[0.0, pytest.approx(math.pi / 4)]]
    json.dumps(d)
    v = r.vector
    assert v.shape == (1,) and abs(np.linalg.norm(v) - 1) < 1e-12
    inf = delay_margin(-2.0, [-1.0]).as_dict()
    assert inf["h_max"] is None and inf["omega"] is None and inf["delay_independent"]
    assert inf["windows"] == [[0.0, 100.0]]


def test_crossing_vector_is_a_null_vector():
    a0 = np.diag([-2.0, -0.9])
    a1 = np.array([[-1.0, 0.0], [-1.0, -1.0]])
    r = delay_margin(a0, [a1])
    s = DelaySystem(a0, [a1])
    t = s.characteristic_matrix(1j * r.omega, r.h_max)
    assert np.linalg.norm(t @ r.vector) < 1e-12 * np.linalg.norm(t)


def test_plot_returns_figure_on_given_axes():
    from matplotlib.figure import Figure

    r = delay_margin(np.diag([-2.0, -0.9]), [np.array([[-1.0, 0.0], [-1.0, -1.0]])])
    fig = r.plot(n_h=10)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    fig2 = Figure()
    axes = fig2.subplots(1, 2)
    assert r.plot(ax=axes, n_h=5, h_range=(0, 8)) is fig2
    rk = delay_margin(0.0, [-1.0], method="kronecker")
    assert isinstance(rk.plot(n_h=5), Figure)


def test_read_delay_system(tmp_path):
    p = tmp_path / "sys.toml"
    p.write_text("[delay_system]\nA0 = [[-2.0, 0.0], [0.0, -0.9]]\n"
                 "A = [[[-1.0, 0.0], [-1.0, -1.0]]]\n")
    s = read_delay_system(p)
    assert (s.n, s.q) == (2, 1)
    p.write_text("[delay_system]\nA0 = [[-1.0]]\nA = [[[-0.5]]]\nB = [[[0.3]]]\n")
    assert read_delay_system(p).neutral
    for text, match in [
        ("[other]\nx = 1\n", r"no \[delay_system\] table"),
        ("[delay_system]\nA0 = [[1.0]]\n", r"\[delay_system\] needs A"),
        ("[delay_system]\nA0 = [[1.0]]\nA = [[[1.0]]]\nC = 1\n", r"unknown key\(s\) C"),
        ("[delay_system]\nA0 = [[1.0, 2.0]]\nA = [[[1.0]]]\n", r"A0 must be a square matrix"),
        ("[delay_system\n", r"not valid TOML"),
    ]:
        p.write_text(text)
        with pytest.raises(InputError, match=match) as exc:
            read_delay_system(p)
        assert str(p) in str(exc.value) and "\n" not in str(exc.value)


#: Modules of backlashkit.delay whose ``__all__`` is documented API.
DELAY_MODULES = ("", ".system", ".chen", ".kronecker", ".crossings", ".spectral", ".result",
                 ".margin", ".loops", ".cases", ".plotting")


def _public():
    seen = set()
    for suffix in DELAY_MODULES:
        modname = f"backlashkit.delay{suffix}"
        mod = importlib.import_module(modname)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if not callable(obj) or getattr(obj, "__module__", "") != mod.__name__:
                continue
            if (mod.__name__, name) in seen:
                continue
            seen.add((mod.__name__, name))
            yield f"{modname}.{name}", obj
            if inspect.isclass(obj):
                for attr, member in vars(obj).items():
                    if not attr.startswith("_") and inspect.isfunction(member):
                        yield f"{modname}.{name}.{attr}", member


@pytest.mark.parametrize("qualname", [q for q, _ in _public()])
def test_public_docstrings(qualname):
    """The checks of tests/test_docstrings.py, on backlashkit.delay's public names."""
    from numpydoc.validate import validate

    enforced = {"GL08", "SS01", "PR01", "PR02", "PR03", "RT01", "RT03"}
    errors = [(c, m) for c, m in validate(qualname)["errors"] if c in enforced]
    assert not errors, errors
