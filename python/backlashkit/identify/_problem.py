"""What the joint estimator fits: the problem, its weighted residual, how it is built.

:class:`Problem` holds the spans of the records, the estimated parameters (logarithms,
or natural units for the Coulomb torques), the prior's penalty and the added terms'
floors; :class:`Residual` is the weighted residual of rows of estimated values over
chosen spans and windows; :func:`build_problem` makes the problem of a prior and
records. The stages that fit it are :mod:`backlashkit.identify._search`'s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .._sensitivity import PARAMS as SENSITIVITY_PARAMS
from ..actuator import CurrentLoop
from ..plants import TwoMassDrive
from ..signals import highpass_noise_std
from ._lm import LMState, lm
from ._model import (
    LINEAR_PARAMS,
    PACKED,
    PACKED_LONG,
    TAU_COL,
    TIED,
    Span,
    SpanRun,
    model_angles,
    screen_spans,
    simulate_span,
    span_start,
)
from ._model import spans as record_spans
from .noise import whiten
from .record import Record
from .search import JointSearch
from .terms import Term

#: A torque change larger than this, relative to the largest torque, is a jump (a
#: window starts there); smaller ones are rounding.
JUMP_RTOL = 1e-9
#: Points whose runs a residual keeps for the exact Jacobian there: Levenberg-Marquardt
#: asks for it at the last accepted point, which an extrapolation's rejected tries
#: (one, at most a few) may follow.
KEPT_POINTS = 4
#: Noise levels are floored at this fraction of the record's largest speed, so that a
#: noise-free record still has finite weights.
NOISE_FLOOR = 1e-9


def selection(spans: Sequence[Span], horizon: float | None) -> list:
    """Samples of each span within ``horizon`` s after its start and every torque jump
    (a slice of the whole span for None: views, not copies, of the long arrays)."""
    out: list = []
    for sp in spans:
        if horizon is None:
            out.append(slice(0, sp.t.size))
            continue
        u = sp.torque
        scale = max(float(np.max(np.abs(u))), 1e-300)
        jumps = np.r_[0, 1 + np.flatnonzero(np.abs(np.diff(u)) > JUMP_RTOL * scale)]
        keep = np.zeros(sp.t.size, bool)
        width = max(2, int(round(horizon / sp.record.ts)))
        for j in jumps:
            keep[j : j + width] = True
        out.append(np.flatnonzero(keep))
    return out


def sample_count(sel) -> int:
    return sel.stop if isinstance(sel, slice) else sel.size


@dataclass
class Problem:
    """What every stage fits: spans, estimated parameters (logarithms), the prior."""

    spans: list[Span]
    screen: list[Span]  # the same model on cheaper spans (holds on a coarse grid)
    free: list[str]
    names: tuple[str, ...]
    base: np.ndarray  # a packed parameter row at the prior, theta 0
    cols: list[int]  # where the estimated parameters go in it
    p_prior: np.ndarray
    pen: np.ndarray  # relative std of the prior per free parameter (inf: no penalty)
    law: str
    workers: int | None
    fd_step: float
    floors: dict[int, float]  # column -> smallest value simulated (terms.py)
    # per estimated parameter: 0 for a log-parameter, else the scale of a parameter
    # estimated in natural units (value = scale * z: the Coulomb torques, whose 0 a
    # logarithm would only approach)
    scales: np.ndarray

    def values(self, z: np.ndarray) -> np.ndarray:
        """The parameters of (rows of) estimated values ``z``, in natural units."""
        natural = self.scales > 0
        return np.where(natural, z * self.scales, np.exp(np.where(natural, 0.0, z)))

    def z_of(self, names: Sequence[str], values: Sequence[float]) -> np.ndarray:
        """The estimated values of parameters ``names`` at ``values`` (their starts)."""
        scale = [self.scales[self.names.index(n)] for n in names]
        return np.array([x / s_ if s_ > 0 else math.log(x)
                         for x, s_ in zip(values, scale, strict=True)])

    @property
    def ties(self) -> list[tuple[int, int]]:
        """``(dst, src)`` columns: breakaway torques equal to fitted Coulomb torques."""
        if self.base.size != len(PACKED_LONG):
            return []
        return [(PACKED_LONG.index(fs), PACKED_LONG.index(fc)) for fs, fc in TIED.items()
                if fc in self.names]

    def without(self, drop: Sequence[str]) -> tuple[Problem, list[int]]:
        """The nested problem without the parameters ``drop`` (set to 0: no friction, no
        current loop) and the indices of the kept estimated values."""
        keep = [i for i, n in enumerate(self.names) if n not in drop]
        names = tuple(self.names[i] for i in keep)
        base = self.base.copy()
        for n in drop:
            base[PACKED_LONG.index(n)] = 0.0
            for fs, fc in TIED.items():
                if fc == n:
                    base[PACKED_LONG.index(fs)] = 0.0
        if (base.size == len(PACKED_LONG) and not np.any(base[len(PACKED):])
                and all(n in PACKED for n in names)):
            base = base[: len(PACKED)]  # paper A's model: the kernel's historical path
        lin = [i - 1 for i in keep[1:]]
        nested = replace(self, free=list(names[1:]), names=names, base=base,
                         cols=[PACKED_LONG.index(n) for n in names],
                         p_prior=self.p_prior[lin], pen=self.pen[lin],
                         scales=self.scales[keep],
                         floors={c: x for c, x in self.floors.items()
                                 if PACKED_LONG[c] in names})
        return nested, keep

    def with_params(self, add: Sequence[str], floors: dict[str, float],
                    scales: dict[str, float],
                    priors: dict[str, tuple[float, float]] | None = None) -> Problem:
        """The larger problem with the parameters ``add`` estimated too (``floors``:
        their smallest values simulated; ``scales``: those estimated in natural units;
        ``priors``: name -> (value, relative std) of those with a prior, else none)."""
        priors = priors or {}
        base = self.base
        if base.size == len(PACKED):
            base = np.r_[base, np.zeros(len(PACKED_LONG) - len(PACKED))]
        names = (*self.names, *add)
        return replace(self, free=list(names[1:]), names=names, base=base,
                       cols=[PACKED_LONG.index(n) for n in names],
                       p_prior=np.r_[self.p_prior, [priors.get(n, (1.0,))[0] for n in add]],
                       pen=np.r_[self.pen, [priors.get(n, (0.0, np.inf))[1] for n in add]],
                       scales=np.r_[self.scales, [scales.get(n, 0.0) for n in add]],
                       floors={**self.floors,
                               **{PACKED_LONG.index(n): x for n, x in floors.items()}})

    def holding(self, name: str, value: float) -> Problem:
        """The same problem with the unestimated term parameter ``name`` (a current
        loop's ``tau_i``) held at ``value`` instead of its base value."""
        base = self.base
        if base.size == len(PACKED):
            base = np.r_[base, np.zeros(len(PACKED_LONG) - len(PACKED))]
        else:
            base = base.copy()
        base[PACKED_LONG.index(name)] = value
        return replace(self, base=base)

    def final_spans(self, final_h: float | None) -> list[Span]:
        """The spans of the final stages: the whole spans, or the cheaper ones when
        only windows are fitted (they skip the holds)."""
        return self.spans if final_h is None else self.screen

    def packed(self, z_rows: np.ndarray) -> np.ndarray:
        """The packed parameter rows the kernel simulates for estimated rows
        ``z_rows``: the floors and the tied breakaway torques applied."""
        p = np.repeat(self.base[np.newaxis, :], len(z_rows), axis=0)
        p[:, self.cols] = self.values(z_rows)
        for col, floor in self.floors.items():
            np.maximum(p[:, col], floor, out=p[:, col])
        for dst, src in self.ties:
            p[:, dst] = p[:, src]
        return p

    def simulate(self, z_rows: np.ndarray, spans: Sequence[Span],
                 ends: list[int] | None = None, *, runs: list[SpanRun] | None = None
                 ) -> list[np.ndarray]:
        """States of log-parameter rows over spans (each up to ``ends[k]`` samples);
        ``runs``, where given for a single row, gets its run of each span."""
        p = self.packed(z_rows)
        return [simulate_span(p, sp, self.law, self.workers,
                              None if ends is None else ends[k], runs=runs)
                for k, sp in enumerate(spans)]

    def exact_model(self, z: np.ndarray) -> tuple[TwoMassDrive, CurrentLoop | None] | None:
        """The drive and current loop (None: none) the compiled sensitivities take at
        ``z``, or None outside their scope: another contact law, a breakaway torque
        apart from its Coulomb torque, or an estimated parameter they do not cover."""
        if self.law != "paper" or not all(n in SENSITIVITY_PARAMS for n in self.names):
            return None
        p = self.packed(z[np.newaxis, :])[0]
        loop = None
        if p.size == len(PACKED_LONG):
            if any(p[PACKED_LONG.index(fs)] != p[PACKED_LONG.index(fc)]
                   for fs, fc in TIED.items()):
                return None
            loop = CurrentLoop(float(p[TAU_COL])) if p[TAU_COL] > 0 else None
            p = p[: PACKED_LONG.index("fs_M")]
        drive = TwoMassDrive(**{n: float(x) for n, x in zip(PACKED_LONG, p, strict=False)})
        return drive, loop

    def beyond_span(self, z: np.ndarray) -> bool:
        """Whether a linear parameter at ``z`` lies over :data:`SEARCH_SPAN` times off
        its prior (either way)."""
        idx = [i for i, n in enumerate(self.names) if n in LINEAR_PARAMS]
        ratio = self.values(z)[idx] / self.p_prior[[i - 1 for i in idx]]
        return bool(np.any((ratio > SEARCH_SPAN) | (ratio < 1.0 / SEARCH_SPAN)))

    def exact_scale(self, z: np.ndarray, *, upward: bool = False) -> np.ndarray:
        """``dp/dz`` of each estimated parameter at ``z``: ``p`` for a logarithm, the
        scale for one in natural units, and 0 where a floor holds it (the kernel
        simulates the floor, which does not move with ``z``); with ``upward``, the
        scale there too: the derivative up from the floor, the information of a
        parameter on its bound (a Coulomb torque fitted to 0), which 0 would take for
        no information at all."""
        out = np.where(self.scales > 0, self.scales, self.values(z))
        if not upward:
            out[self.on_floor(z)] = 0.0
        return out

    def on_floor(self, z: np.ndarray) -> np.ndarray:
        """Whether a floor holds each estimated parameter at ``z`` (its value below the
        smallest value simulated)."""
        values = self.values(z)
        return np.array([col in self.floors and values[i] < self.floors[col]
                         for i, col in enumerate(self.cols)], bool)

    def residual(self, spans: Sequence[Span], horizon: float | None, sig: np.ndarray,
                 ar: np.ndarray | None = None) -> Residual:
        """The weighted residual over ``spans`` within ``horizon`` (:class:`Residual`)."""
        return Residual(self, spans, horizon, sig, ar)

    def refine(self, res: Residual, z0: np.ndarray, max_iter: int, bounds=None,
               state: LMState | None = None) -> LMState:
        """Levenberg-Marquardt on ``res`` from ``z0`` (:meth:`Residual.jacobian`)."""
        return lm(res.at, res.jacobian, z0, max_iter=max_iter, bounds=bounds, state=state)

    def central_jacobian(self, res: Residual, z: np.ndarray) -> np.ndarray:
        """Jacobian of ``res`` at ``z`` for the uncertainty: exact
        (:meth:`Residual.exact_jacobian`) where the compiled sensitivities cover the
        model, else by central differences; a parameter a floor holds takes its
        derivative up from the floor (``upward``; a forward difference)."""
        exact = res.exact_jacobian(z, upward=True)
        if exact is not None:
            return exact
        n, h = len(self.names), self.fd_step
        floored = self.on_floor(z)
        zz = np.repeat(z[np.newaxis, :], 2 * n, axis=0)
        for i in range(n):
            zz[2 * i, i] += h
            if not floored[i]:  # below the floor the model does not move
                zz[2 * i + 1, i] -= h
        rr = res(zz)
        return ((rr[0::2] - rr[1::2]) / np.where(floored, h, 2 * h)).T


#: The searches take a point whose linear parameter lies over this factor off its prior
#: as no drive (an infinite residual): the records cannot show such a drive (a fit that
#: ends 5 times off is refused anyway, ``far_from_prior_``), and its simulation can take
#: minutes, an inertia near 0 making the fastest mode stiff (a fit to torques in mN m
#: read as N m walked the load's inertia 1e9 below its prior and hung the test suite:
#: ``tests/test_cli_input_errors.py::test_a_unit_mistake_is_named_from_the_held_speeds``).
SEARCH_SPAN = 1e3


class Residual:
    """Weighted residual rows of log-parameter rows: every selected sample of ``w_M``
    then ``w_L`` per span (of the angles ``phi_M``, ``phi_L`` from the span's start,
    less their mean, where the record holds encoder angles), divided by its noise
    level, then the prior's rows. With
    ``ar`` (record, channel, lag) each channel is whitened by ``A(q)`` first and
    ``sig`` is the innovation's std."""

    def __init__(self, problem: Problem, spans: Sequence[Span], horizon: float | None,
                 sig: np.ndarray, ar: np.ndarray | None = None) -> None:
        self.problem, self.spans, self.sig, self.ar = problem, list(spans), sig, ar
        self.sels = selection(spans, horizon)
        self.sizes = [sample_count(s_) for s_ in self.sels]
        self.ends = [s_.stop if isinstance(s_, slice) else int(s_[-1]) + 1 for s_ in self.sels]
        self.lag = 0 if ar is None else ar.shape[-1]  # samples without a past, dropped
        self.n_res = 2 * sum(m - self.lag for m in self.sizes) + len(problem.free)
        self.ys = [(sp.p_m[s_], sp.p_l[s_]) if sp.positions else (sp.y_m[s_], sp.y_l[s_])
                   for sp, s_ in zip(spans, self.sels, strict=True)]
        # single points' runs of the spans, by the point's bytes, newest last: the
        # exact Jacobian at one of them follows its runs (:meth:`exact_jacobian`)
        self.kept: dict[bytes, list[SpanRun]] = {}
        # each span's sensitivities, written again at each exact Jacobian with
        # autoregressive noise (white noise's rows come from the kernel): one array
        # per span and column count, as a new one each time costs its fresh pages
        # (docs/design/sensitivities.md, "The spans' sensitivities in kept arrays")
        self.sens_out: dict[tuple[int, int], np.ndarray] = {}
        self.selected: dict[int, np.ndarray] = {}  # :meth:`_selected`

    def __call__(self, z_rows: np.ndarray) -> np.ndarray:
        pb, lag = self.problem, self.lag
        runs = [] if len(z_rows) == 1 else None
        sims = pb.simulate(z_rows, self.spans, self.ends, runs=runs)
        if runs is not None:
            self.keep(z_rows[0], runs)
        out = np.empty((len(z_rows), self.n_res))
        pos = 0
        for sp, y2, s_, x, m in zip(self.spans, self.ys, self.sels, sims, self.sizes,
                                    strict=True):
            model = model_angles(x) if sp.positions else (x[:, :, 0], x[:, :, 1])
            for c, y in enumerate(y2):  # w_M (or phi_M), then w_L (or phi_L)
                dst = out[:, pos : pos + m - lag]
                if sp.positions or self.ar is not None:
                    dst[...] = self.weigh(sp, c, y - model[c][:, s_])
                else:  # weigh's arithmetic in place: the longest spans' rows are large
                    np.subtract(y, model[c][:, s_], out=dst)
                    np.divide(dst, self.sig[sp.k, c], out=dst)
                pos += m - lag
        p = pb.values(z_rows)[:, 1:]
        with np.errstate(invalid="ignore"):  # inf / inf: no penalty on an overflow
            out[:, pos:] = np.nan_to_num((p - pb.p_prior) / (pb.pen * pb.p_prior))
        return out

    def runs_at(self, z: np.ndarray) -> list[SpanRun]:
        """The runs of the spans at point ``z``: kept, or simulated now (and kept)."""
        runs = self.kept.get(z.tobytes())
        if runs is None:
            runs = []
            self.problem.simulate(z[np.newaxis, :], self.spans, self.ends, runs=runs)
            self.keep(z, runs)
        return runs

    def keep(self, z: np.ndarray, runs: list[SpanRun]) -> None:
        """Keep the runs of point ``z`` (the :data:`KEPT_POINTS` newest)."""
        self.kept[z.tobytes()] = runs
        while len(self.kept) > KEPT_POINTS:
            del self.kept[next(iter(self.kept))]

    def weigh(self, sp: Span, c: int, e: np.ndarray) -> np.ndarray:
        """The rows of errors ``e`` (``(b, m)``: the selected samples of channel ``c`` of
        span ``sp``): less their mean on angles, whitened, divided by the noise level."""
        if sp.positions:  # the angles' common offset: the first sample's error
            e = e - e.mean(axis=1, keepdims=True)
        if self.ar is not None:
            e = whiten(e, self.ar[sp.k, c])
        return e / self.sig[sp.k, c]

    def at(self, z: np.ndarray) -> np.ndarray:
        """The residual at one point (inf where the model cannot be simulated, or where
        it is no drive the search looks at: :meth:`Problem.beyond_span`)."""
        if self.problem.beyond_span(z):
            return np.full(1, np.inf)
        try:
            return self(z[np.newaxis, :])[0]
        except ValueError:  # e.g. a step to a mode too fast for the sample time
            return np.full(1, np.inf)

    def jacobian(self, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The Jacobian while iterating: exact (:meth:`exact_jacobian`, one sensitivity
        run per span) where the compiled sensitivities cover the model, else forward
        differences (:meth:`forward_jacobian`, one simulation per parameter)."""
        exact = self.exact_jacobian(z)
        return self.forward_jacobian(z, r) if exact is None else exact

    def forward_jacobian(self, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Forward differences (half the simulations of central ones) while iterating."""
        n, h = z.size, self.problem.fd_step
        zz = np.repeat(z[np.newaxis, :], n, axis=0) + h * np.eye(n)
        return ((self(zz) - r) / h).T

    def exact_jacobian(self, z: np.ndarray, *, with_theta: bool = True, upward: bool = False
                       ) -> np.ndarray | None:
        """The Jacobian in the estimated values from the compiled forward
        sensitivities, one run per span of the estimated parameters alone (without
        ``theta``'s column where ``with_theta`` is false: a refit that holds it; with
        ``upward``, a parameter on its floor moves up from it,
        :meth:`Problem.exact_scale`); None
        outside their scope (:meth:`Problem.exact_model`) or where a change grazes (no
        derivative there: the caller differences instead). The
        sensitivities follow the residual's own simulation at ``z`` (:attr:`kept`
        where it has just been simulated there, else simulated now), so they are
        those of the model the residual evaluates. A span that starts after a held
        torque or from a steady state starts with that state's sensitivity
        (:func:`~backlashkit.identify._model.span_start`). A span of encoder angles
        takes the sensitivity of the motor's angle, which its run tracks (:meth:`_angle_rows`)."""
        pb = self.problem
        model = pb.exact_model(z)
        if model is None:
            return None
        drive, loop = model
        from .._sensitivity import jacobian_rows_along, sensitivities_along

        first = 0 if with_theta else 1
        names = pb.names[first:]
        scale = pb.exact_scale(z, upward=upward)  # dp/dz
        # the residual is data - model: its rows move as -S (negating a factor is exact)
        minus_per_z = -scale[first:]
        out = np.empty((self.n_res, len(names)))
        pos = 0
        try:
            runs = self.runs_at(z)
            for i, (sp, s_, m, run) in enumerate(zip(self.spans, self.sels, self.sizes, runs,
                                                     strict=True)):
                # along a run the kernel does not warn (the differences would not)
                _, s0 = span_start(drive, sp, names, run.hold, actuator=loop)
                block = out[pos : pos + 2 * (m - self.lag)]
                if sp.positions:
                    sens = sensitivities_along(drive, run.span, initial_sensitivity=s0,
                                               params=names, out=self._sens_out(i, run, names),
                                               actuator=loop)
                    self._angle_rows(sp, s_, sens, minus_per_z, block)
                elif self.ar is None:  # weigh's arithmetic, by the kernel
                    jacobian_rows_along(drive, run.span, selected=self._selected(i),
                                        factor=minus_per_z, level=tuple(self.sig[sp.k]),
                                        out=block, initial_sensitivity=s0, params=names,
                                        actuator=loop)
                else:
                    sens = sensitivities_along(drive, run.span, initial_sensitivity=s0,
                                               params=names, out=self._sens_out(i, run, names),
                                               actuator=loop)
                    for c, rows in enumerate(np.split(block, 2)):
                        rows[...] = self.weigh(sp, c, (sens[s_, c, :] * minus_per_z).T).T
                pos += 2 * (m - self.lag)
        except ValueError:
            return None
        with np.errstate(invalid="ignore"):  # no penalty (inf) on the terms' parameters
            prior = np.nan_to_num(scale[1:] / (pb.pen * pb.p_prior))
        out[pos:] = 0.0
        out[pos:, 1 - first:] = np.diag(prior)  # theta has no prior row
        return out

    def _angle_rows(self, sp: Span, s_, sens: np.ndarray, minus_per_z: np.ndarray,
                    block: np.ndarray) -> None:
        """The rows of span ``sp`` of encoder angles into ``block``, from the
        sensitivities ``sens`` of its run's states, the motor's angle last: the motor's
        angle's, then the load's (the motor's less the twist's change since the span's
        first sample, :func:`~backlashkit.identify._model.model_angles`), of the selected
        samples ``s_``, each times ``minus_per_z`` and weighed as the residual's rows."""
        chosen = sens[s_]
        motor = chosen[:, -1, :]
        load = motor - (chosen[:, 2, :] - sens[0, 2, :])
        for c, (rows, angle) in enumerate(zip(np.split(block, 2), (motor, load), strict=True)):
            if self.ar is not None:
                rows[...] = self.weigh(sp, c, (angle * minus_per_z).T).T
                continue
            # weigh's arithmetic along the samples' axis, in place
            np.multiply(angle, minus_per_z, out=rows)
            rows -= rows.mean(axis=0)
            rows /= self.sig[sp.k, c]

    def _selected(self, i: int) -> np.ndarray:
        """Span ``i``'s selected samples as indices (int64), made once."""
        sel = self.selected.get(i)
        if sel is None:
            s_ = self.sels[i]
            sel = self.selected[i] = (np.arange(s_.start, s_.stop) if isinstance(s_, slice)
                                      else np.asarray(s_, np.int64))
        return sel

    def _sens_out(self, i: int, run: SpanRun, names: Sequence[str]) -> np.ndarray:
        """The kept array for span ``i``'s sensitivities to ``names`` along ``run``."""
        shape = (len(run.span.torque), run.span.states.shape[1], len(names))
        out = self.sens_out.get((i, len(names)))
        if out is None or out.shape != shape:
            out = self.sens_out[i, len(names)] = np.empty(shape)
        return out

    def channels(self, r: np.ndarray):
        """``(k, c, part)``: the part of ``r`` of record ``k``'s channel ``c``, per span."""
        pos = 0
        for sp, m in zip(self.spans, self.sizes, strict=True):
            for c in (0, 1):
                yield sp.k, c, r[pos : pos + m - self.lag]
                pos += m - self.lag

    def prior_rows(self, r: np.ndarray) -> np.ndarray:
        """The prior's rows of ``r``."""
        return r[self.n_res - len(self.problem.free):]


def angle_noise_std(rec: Record) -> np.ndarray:
    """Starting noise levels of a record's two angles in rad: the quantisation noise
    ``q / sqrt(12)`` of its encoders where their step ``q`` is known, else a high-pass
    estimate."""
    if rec.quantum > 0:
        return np.full(2, rec.quantum / math.sqrt(12.0))
    return np.array([highpass_noise_std(rec.phi_motor), highpass_noise_std(rec.phi_load)])


def build_problem(prior: TwoMassDrive, recs: list[Record], rel: dict, noise,
                  search: JointSearch, law: str, workers, terms: Sequence[Term] = ()
                  ) -> tuple[Problem, np.ndarray]:
    """The problem and the starting noise levels ``(n_records, 2)``: ``noise`` for every
    record, or a high-pass estimate of each record's and channel's. ``terms`` add the
    fitted or fixed parameters of friction and current loop (a long packed row)."""
    free = [n for n in LINEAR_PARAMS if n in rel and getattr(prior, n) > 0]
    extra = [n for term in terms if term.fitted for n in term.params]
    scales = {n: x for term in terms if term.fitted for n, x in term.scales(recs).items()}
    names = ("theta", *free, *extra)
    if noise is not None:
        sig0 = [np.array(noise, float)] * len(recs)
    else:
        sig0 = [np.array([highpass_noise_std(r.w_motor), highpass_noise_std(r.w_load)])
                for r in recs]
    spans_ = record_spans(recs, search.start, float(search.pre_window), sig0)
    if noise is None:  # records of encoder angles are fitted as angles
        sig0 = [angle_noise_std(r) if r.has_positions else s0 for r, s0 in zip(recs, sig0,
                                                                              strict=True)]
    sigma = np.array(sig0, float).reshape(len(recs), 2)
    scale = [max(float(np.ptp(r.phi_motor)), float(np.ptp(r.phi_load))) if r.has_positions
             else max(float(np.max(np.abs(r.w_motor))), float(np.max(np.abs(r.w_load))))
             for r in recs]
    sigma = np.maximum(sigma, NOISE_FLOOR * np.array(scale)[:, np.newaxis] + 1e-300)
    base = np.array([getattr(prior, n) for n in PACKED[:-1]] + [0.0])
    if any(term.present for term in terms):
        base = np.r_[base, np.zeros(len(PACKED_LONG) - len(PACKED))]
        for term in terms:
            for n, x in zip(term.params, term.fixed, strict=False):
                base[PACKED_LONG.index(n)] = x
    pb = Problem(
        spans=spans_, screen=screen_spans(spans_), free=[*free, *extra], names=names,
        base=base, cols=[PACKED_LONG.index(n) for n in names],
        # an added term's parameter without a prior std has a row of 0 (p_prior 1,
        # infinite std); with one, the prior's value is where its penalty is 0
        p_prior=np.array([getattr(prior, n) for n in free]
                         + [getattr(prior, n) if rel.get(n) else 1.0 for n in extra]),
        pen=np.array([rel[n] if rel[n] is not None else np.inf for n in free]
                     + [rel.get(n) or np.inf for n in extra]),
        law=law, workers=workers, fd_step=search.fd_step,
        floors={PACKED_LONG.index(n): x for term in terms if term.fitted
                for n, x in term.floors(recs).items()},
        scales=np.array([0.0] * (1 + len(free))
                        + [scales.get(n, 0.0) for n in extra]),
    )
    return pb, sigma
