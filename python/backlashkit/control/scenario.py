"""Scenario files (TOML) for ``backlashkit control``.

Layout (polynomials are coefficient lists, highest power first; times in s,
frequencies in rad/s)::

    [plant]            num = [1.0]; den = [1.0, -0.5, -1.5]
    [reference_model]  den = [1.0, 5.0, 6.0]          # R_m(s); optional
    [filter]           den = [1.0, 4.0, 4.0]          # Lambda(s); optional
    [backlash]         m = 0.7; c_r = 1.3; c_l = -0.5 # the true one, in the plant
    [adaptation]       gamma = 5.0; theta_b0 = [1.51, 0.2, -0.55]
                       m0 = 0.02 (default 0.1*theta_b0[1]); sigma = 0.1 (default)
                       sigma_bound = ... (optional)
    [reference]        amplitude = [10.0]; frequency = [1.3]   # sum of sines
                       # or: file = "ref.csv" (two columns t, r; header optional)
    [inverse]          kind = "exact"; alpha = 6.0; beta_r = 1.0; beta_l = 1.0  # optional
    [simulation]       duration = 60.0; ts = 0.01; step = 0.001 (optional)

Every error is one line naming the table, the key and the constraint.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io import did_you_mean
from ..nonlinearities import Backlash, InverseKind, inverse_from_name
from .adaptive import AdaptiveLaw
from .closed_loop import simulate_closed_loop
from .design import design_mrc
from .problem import DEFAULT_MAX_STEP, check_rows
from .references import SumOfSines, TableReference
from .response import ClosedLoopResponse

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["ControlScenario", "load_scenario"]

_ALLOWED: dict[str, set[str]] = {
    "plant": {"num", "den"},
    "reference_model": {"den"},
    "filter": {"den"},
    "backlash": {"m", "c_r", "c_l"},
    "adaptation": {"gamma", "theta_b0", "m0", "sigma", "sigma_bound"},
    "reference": {"amplitude", "frequency", "phase", "file"},
    "inverse": {"kind", "alpha", "beta_r", "beta_l"},
    "simulation": {"duration", "ts", "step"},
}
_REQUIRED_TABLES = ("plant", "backlash", "reference", "simulation")
#: The library's options a run's messages advise, as the scenario file's keys.
_KEYS = {"step": "[simulation] step", "duration": "[simulation] duration",
         "alpha": "[inverse] alpha"}


@dataclass
class ControlScenario:
    """A validated scenario.

    Attributes
    ----------
    plant : tuple
        ``(num, den)``.
    reference_model, filter : list of float or None
        ``R_m`` and ``Lambda``.
    backlash : Backlash
        The true backlash.
    adaptation : AdaptiveLaw
        Adaptive-law parameters.
    reference : SumOfSines or TableReference
        Reference signal.
    inverse : InverseKind
        Inverse given in the file (default exact).
    inverse_params : dict
        ``alpha``, ``beta_r``, ``beta_l`` given in the file (used when the CLI
        overrides the inverse kind).
    duration, ts : float
        Length of the run and trace sample time in s.
    step : float or None
        Largest integration step in s.
    source : str
        File name (for messages).
    """

    plant: tuple
    reference_model: list | None
    filter: list | None
    backlash: Backlash
    adaptation: AdaptiveLaw
    reference: Any
    inverse: InverseKind
    inverse_params: dict
    duration: float
    ts: float
    step: float | None
    source: str = "scenario"

    def make_inverse(self, name: str | None) -> InverseKind:
        """Inverse for a CLI ``--inverse`` name (``None``: the file's choice).

        Parameters
        ----------
        name : str or None
            ``exact``, ``smooth-filter``, ``smooth-ramp``, ``none`` or ``gain-only``.

        Returns
        -------
        InverseKind
            With the file's ``alpha`` / ``beta_r``, ``beta_l`` where they apply.
        """
        if name is None:
            return self.inverse
        return _inverse(name, self.inverse_params, self.source)

    def run(
        self, *, inverse: InverseKind | None = None, backend: str = "rust"
    ) -> ClosedLoopResponse:
        """Simulate the scenario.

        Parameters
        ----------
        inverse : InverseKind, optional
            Override of the file's inverse.
        backend : {"rust", "numpy"}
            Kernel.

        Returns
        -------
        ClosedLoopResponse
            The trace at ``ts``.

        Raises
        ------
        InputError
            What the library refuses of the run, named with the scenario's file, and
            with its tables' keys where the message advises a step or an ``alpha``.
        """
        try:
            return simulate_closed_loop(
                self.plant,
                self.backlash,
                reference=self.reference,
                duration=self.duration,
                ts=self.ts,
                step=self.step,
                inverse=inverse or self.inverse,
                adaptation=self.adaptation,
                reference_model=self.reference_model,
                filter=self.filter,
                backend=backend,
            )
        except InputError as exc:
            text = exc.worded(lambda option: _KEYS.get(option.name))
            raise InputError(f"{self.source}: {text}") from None


def _inverse(name: str, params: dict, src: str) -> InverseKind:
    keep = {"smooth-filter": ("alpha",), "smooth-ramp": ("beta_r", "beta_l")}.get(name, ())
    try:
        return inverse_from_name(name, **{k: params[k] for k in keep if k in params})
    except InputError as exc:  # the table's key is `kind`, the library's word `inverse`
        text = str(exc).replace("inverse must be one of", "kind must be one of", 1)
        raise InputError(f"{src}: [inverse] {text}") from None


def _num(
    src: str, table: str, key: str, value: Any, *, cond: str = "", allow_zero: bool = True
) -> float:
    where = f"{src}: [{table}] {key}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where} must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise InputError(f"{where} must be finite, got {value!r}")
    if cond == ">0" and not x > 0:
        raise InputError(f"{where} must be > 0, got {value!r}")
    if cond == ">=0" and not x >= 0:
        raise InputError(f"{where} must be >= 0, got {value!r}")
    return x


def _list(src: str, table: str, key: str, value: Any, *, min_len: int = 1,
          exact: bool = False) -> list[float]:
    where = f"{src}: [{table}] {key}"
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or len(value) < min_len or (exact and len(value) != min_len):
        size = f"exactly {min_len}" if exact else f"at least {min_len}"
        what = f"a list of {size} numbers"
        if min_len == 1:
            what = "a list of exactly one number" if exact else "a non-empty list of numbers"
        raise InputError(f"{where} must be {what}, got {value!r}")
    return [_num(src, table, key, x) for x in value]


def _read_table_file(src: str, base: Path, name: Any) -> TableReference:
    if not isinstance(name, str):
        raise InputError(f"{src}: [reference] file must be a string path, got {name!r}")
    path = (base / name) if not Path(name).is_absolute() else Path(name)
    if not path.is_file():
        raise InputError(f"{src}: [reference] file {str(path)!r} does not exist")
    try:
        data = np.genfromtxt(path, delimiter=",", names=None, comments="#")
    except ValueError as exc:
        raise InputError(f"{src}: [reference] file {path}: {exc}") from None
    if data.ndim == 2 and np.isnan(data[0]).all():
        data = data[1:]  # header row
    if data.ndim == 2 and data.shape[1] > 2:
        raise InputError(f"{src}: [reference] file {path} has {data.shape[1]} columns; give "
                         "two, t and r")
    if (
        data.ndim != 2
        or data.shape[1] < 2
        or data.shape[0] < 2
        or not np.isfinite(data[:, :2]).all()
    ):
        with open(path, encoding="utf-8", errors="replace") as fh:
            first = fh.readline()
        other = next((f" (its first line holds {sep!r}: the columns are separated by "
                      "',' here)" for sep in (";", "\t") if sep in first), "")
        raise InputError(
            f"{src}: [reference] file {path} must have >= 2 rows of two numeric columns t, r"
            f"{other}"
        )
    try:
        return TableReference(data[:, 0], data[:, 1])
    except InputError as exc:
        raise InputError(f"{src}: [reference] file {path}: {exc}") from None


def parse_scenario(
    doc: dict, *, source: str = "scenario", base: Path | None = None
) -> ControlScenario:
    """Validate a parsed TOML document.

    Parameters
    ----------
    doc : dict
        The parsed TOML.
    source : str
        Name used in messages.
    base : pathlib.Path, optional
        Directory against which a relative ``[reference] file`` is resolved.

    Returns
    -------
    ControlScenario
        The validated scenario.
    """
    src = source
    base = Path(".") if base is None else base
    _check_tables(doc, src)
    plant, rm, flt = _linear_part(doc, src)
    backlash = _backlash(doc, src)
    adaptation = _adaptation(doc, src, backlash.m)
    reference = _reference(doc, src, base)
    inverse, params = _inverse_table(doc, src)
    duration, ts, step = _simulation(doc, src, reference)
    return ControlScenario(
        plant=plant,
        reference_model=rm,
        filter=flt,
        backlash=backlash,
        adaptation=adaptation,
        reference=reference,
        inverse=inverse,
        inverse_params=params,
        duration=duration,
        ts=ts,
        step=step,
        source=src,
    )


def _check_tables(doc: dict, src: str) -> None:
    """Only known tables and keys, and every required table."""
    for table, val in doc.items():
        if table not in _ALLOWED:
            raise InputError(f"{src}: unknown table [{table}]"
                             f"{did_you_mean([table], list(_ALLOWED), brackets=True)}; "
                             f"expected one of {', '.join(f'[{t}]' for t in sorted(_ALLOWED))}")
        if not isinstance(val, dict):
            raise InputError(f"{src}: [{table}] must be a table")
        extra = set(val) - _ALLOWED[table]
        if extra:
            raise InputError(
                f"{src}: [{table}] has unknown key(s) {', '.join(sorted(extra))}"
                f"{did_you_mean(sorted(extra), sorted(_ALLOWED[table]))}; "
                f"allowed: {', '.join(sorted(_ALLOWED[table]))}"
            )
    for table in _REQUIRED_TABLES:
        if table not in doc:
            raise InputError(f"{src}: missing table [{table}]")


def _need(doc: dict, src: str, table: str, key: str) -> Any:
    if key not in doc[table]:
        raise InputError(f"{src}: [{table}] missing key {key}")
    return doc[table][key]


def _linear_part(doc: dict, src: str) -> tuple[tuple[list[float], list[float]], Any, Any]:
    """The plant, the reference model and the filter, checked by designing with them."""
    plant = (
        _list(src, "plant", "num", _need(doc, src, "plant", "num")),
        _list(src, "plant", "den", _need(doc, src, "plant", "den"), min_len=2),
    )
    rm = doc.get("reference_model", {}).get("den")
    rm = None if rm is None else _list(src, "reference_model", "den", rm, min_len=2)
    flt = doc.get("filter", {}).get("den")
    flt = None if flt is None else _list(src, "filter", "den", flt, min_len=2)
    try:
        design_mrc(plant, reference_model=rm, filter=flt)
    except InputError as exc:
        raise InputError(f"{src}: [plant]/[reference_model]/[filter]: {exc}") from None
    return plant, rm, flt


def _backlash(doc: dict, src: str) -> Backlash:
    m = _num(src, "backlash", "m", _need(doc, src, "backlash", "m"), cond=">0")
    c_r = _num(src, "backlash", "c_r", _need(doc, src, "backlash", "c_r"), cond=">=0")
    c_l = _num(src, "backlash", "c_l", _need(doc, src, "backlash", "c_l"))
    if c_l > 0:
        raise InputError(f"{src}: [backlash] c_l must be <= 0 (assumption A3), got {c_l!r}")
    if not c_l < c_r:
        raise InputError(f"{src}: [backlash] c_l must be < c_r, got c_l={c_l!r}, c_r={c_r!r}")
    return Backlash(m, c_r, c_l)


def _adaptation(doc: dict, src: str, m: float) -> AdaptiveLaw:
    """The [adaptation] table; ``m0`` may not exceed the true slope ``m`` (A3)."""
    ad = doc.get("adaptation", {})
    kw: dict[str, Any] = {}
    if "gamma" in ad:
        g = ad["gamma"]
        kw["gamma"] = (
            _list(src, "adaptation", "gamma", g, min_len=1)
            if isinstance(g, list)
            else _num(src, "adaptation", "gamma", g, cond=">0")
        )
    if "theta_b0" in ad:
        kw["theta_b0"] = _list(src, "adaptation", "theta_b0", ad["theta_b0"], min_len=3,
                               exact=True)
    if "m0" in ad:
        kw["m0"] = _num(src, "adaptation", "m0", ad["m0"], cond=">0")
    if "sigma" in ad:
        kw["sigma"] = _num(src, "adaptation", "sigma", ad["sigma"], cond=">=0")
    if "sigma_bound" in ad:
        kw["sigma_bound"] = _num(src, "adaptation", "sigma_bound", ad["sigma_bound"], cond=">0")
    if "m0" in kw and kw["m0"] > m:
        raise InputError(
            f"{src}: [adaptation] m0 must be <= the true slope [backlash] m = {m!r} (A3), "
            f"got {kw['m0']!r}"
        )
    try:
        return AdaptiveLaw(**kw)
    except InputError as exc:
        raise InputError(f"{src}: [adaptation] {exc}") from None


def _reference(doc: dict, src: str, base: Path) -> SumOfSines | TableReference:
    """The [reference] table: a file, or sines."""
    ref = doc["reference"]
    if "file" in ref:
        if {"amplitude", "frequency", "phase"} & set(ref):
            raise InputError(
                f"{src}: [reference] give either file or amplitude/frequency, not both"
            )
        return _read_table_file(src, base, ref["file"])
    amp = _list(src, "reference", "amplitude", _need(doc, src, "reference", "amplitude"))
    freq = _list(src, "reference", "frequency", _need(doc, src, "reference", "frequency"))
    if len(amp) != len(freq):
        raise InputError(
            f"{src}: [reference] amplitude and frequency must have the same length, got "
            f"{len(amp)} and {len(freq)}"
        )
    phase = ref.get("phase")
    phase = None if phase is None else _list(src, "reference", "phase", phase)
    if phase is not None and len(phase) != len(amp):
        raise InputError(
            f"{src}: [reference] phase must have {len(amp)} values, got {len(phase)}"
        )
    return SumOfSines(amp, freq, phase)


def _inverse_table(doc: dict, src: str) -> tuple[InverseKind, dict[str, float]]:
    """The [inverse] table: the inverse, and every parameter given (for the CLI's
    --inverse)."""
    inv_tab = doc.get("inverse", {})
    params = {}
    for k in ("alpha", "beta_r", "beta_l"):
        if k in inv_tab:
            params[k] = _num(src, "inverse", k, inv_tab[k], cond=">0")
    kind = inv_tab.get("kind", "exact")
    if not isinstance(kind, str):
        raise InputError(f"{src}: [inverse] kind must be a string, got {kind!r}")
    return _inverse(kind, params, src), params


def _simulation(doc: dict, src: str,
                reference: SumOfSines | TableReference) -> tuple[float, float, float | None]:
    """Duration, sample time and largest step of the [simulation] table."""
    sim = doc["simulation"]
    duration = _num(src, "simulation", "duration", _need(doc, src, "simulation", "duration"),
                    cond=">0")
    ts = _num(src, "simulation", "ts", _need(doc, src, "simulation", "ts"), cond=">0")
    if ts > duration:
        raise InputError(f"{src}: [simulation] ts must be <= duration ({duration!r}), got {ts!r}")
    try:
        check_rows(duration, ts)  # the library's rule, said with the file's name
    except InputError as exc:
        raise InputError(f"{src}: [simulation] {exc}") from None
    try:
        reference.check_covers(duration)
    except InputError as exc:
        raise InputError(f"{src}: [reference] file: {exc}") from None
    step = sim.get("step")
    step = None if step is None else _num(src, "simulation", "step", step, cond=">0")
    if isinstance(reference, SumOfSines):  # the integrator would alias it silently
        h = min(ts, DEFAULT_MAX_STEP) if step is None else step  # the largest step
        fastest = float(max(np.abs(reference.frequency)))
        if fastest * h >= math.pi:
            raise InputError(
                f"{src}: [reference] frequency {fastest:.6g} rad/s is at or above the Nyquist "
                f"frequency pi/step = {math.pi / h:.6g} rad/s of the integration step "
                f"{h:.3g} s: lower the frequency or set a shorter [simulation] step"
            )
    return duration, ts, step


def load_scenario(path: str | Path) -> ControlScenario:
    """Read and validate a scenario file.

    Parameters
    ----------
    path : str or pathlib.Path
        The TOML file.

    Returns
    -------
    ControlScenario
        The validated scenario.

    Raises
    ------
    InputError
        One-line message naming the table, key and constraint.
    """
    p = Path(path)
    if p.is_dir():
        raise InputError(f"scenario file {str(p)!r} is a directory; give a TOML file")
    if not p.is_file():
        raise InputError(f"scenario file {str(p)!r} does not exist")
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{p.name}: not valid TOML: {str(exc).splitlines()[0]}") from None
    return parse_scenario(doc, source=p.name, base=p.parent)
