"""The joint search's stages, as plain functions over explicit state.

:class:`~backlashkit.identify._problem.Problem` holds what every stage fits and builds
its weighted residuals (:mod:`backlashkit.identify._problem`); :func:`run` calls the
stages in order: :func:`grid_minima`, :func:`first_window`, :func:`continue_on` (and
:func:`direct_path`), :func:`whole_record`, :func:`restart`, :func:`reestimate_noise`,
:func:`select_terms` (under the noise model's likelihood, :func:`tested_terms`),
:func:`whiten_noise`, :func:`uncertainty`; :func:`locate` groups
the first five, which :func:`research` runs again where the test adds a term after
them. The configuration is :mod:`backlashkit.identify.search`'s;
``docs/design/joint-search.md`` says why each stage exists.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from ..errors import InputError, Option
from ..plants import TwoMassDrive
from ._lm import LMState
from ._model import LINEAR_PARAMS, Span, model_angles
from ._problem import Problem, Residual, sample_count, selection
from ._quantised import log_theta_draws, quantised
from ._score import Linearised, bounds_theta, linearise, score_test
from .intervals import (
    CHI2_95,
    MAX_HALF_WIDTH,
    Z_95,
    IntervalInputs,
    ThetaInterval,
    quantisation_interval,
)
from .noise import sample_noise
from .record import Record
from .search import FirstHorizon, JointSearch, Restarts, ThetaGrid
from .terms import TERM_NAMES, Term, TermChoice
from .two_step import TwoStepIdentifier

#: First-window solutions costing more than this times the best one's are not
#: continued: the right basin was within 1.1 times the best where the first window
#: ranked it wrongly (``benchmarks/robustness_joint.py``).
CONTINUE_RATIO = 1.25
#: Candidates closer than this in every log-parameter count as one point.
SAME_POINT = 1e-3
#: Candidates within :data:`DISTINCT` of each other whose costs differ by less than
#: this (chi-square units) count as one point too: they lie along a flat direction of
#: one basin. On paper A's records from a prior 30 % off, two first-window solutions of
#: one basin were continued side by side to the same end; counted as one, the
#: continuation took 360 sensitivity runs instead of 438 and the whole records 18
#: simulations instead of 26 (``benchmarks/bench_identify.py --count`` before and
#: after: docs/design/sensitivities.md, "Fewer refits").
SAME_COST = 0.01
#: End points of the continuation paths within this (chi-square units) of the best on
#: the longest short window, and more than DISTINCT apart, make the search ambiguous.
AMBIGUITY_MARGIN = 30.0
#: Largest log-parameter difference of two end points that count as one basin.
DISTINCT = 1e-2
#: Candidates whose cost (chi-square units) on the longest short window exceeds the
#: best one's by more than this are not refined on the whole record: that cost ranks
#: candidates as the whole record does, to a few units.
WHOLE_RECORD_MARGIN = 10.0
#: Iterations a restart gets on its screening window before it must be below the
#: solution it restarts from: one climbing back to the same basin is still far above
#: it then, one falling into a better basin already below.
RESTART_SCREEN_ITER = 5
#: The window of the long restarts (``Restarts.long``), in times the longest short
#: one: records longer than the short windows hold more periods of the ringing, and so
#: more basins of its phase than those windows separate; twice the 3 s window holds all
#: of the second drive's 8 s records in ``benchmarks/real_drive.py``, and a small part of
#: paper A's 80 s ones, so the restarts that climb back cost little there.
LONG_WINDOW = 2.0
#: Iterations a ringing restart (``Restarts.ringing``) gets on the long window before it
#: must be below the solution it restarts from: moved in both the stiffness and the
#: motor's inertia, it takes more iterations to fall into a lower basin than the
#: RESTART_SCREEN_ITER of the other restarts, which stop it on the way (trial 18 of
#: the second drive's Coulomb row in ``benchmarks/real_drive.py`` with a 10 % prior,
#: ``test_ringing_restarts_reach_a_basin_a_stiffness_shift_alone_does_not``).
RINGING_SCREEN_ITER = 25
#: Share of the final data's residuals that the long window must hold for the ringing
#: restarts: screened to their minimum, each costs about a fit on that window, which
#: is spent where the window is most of the records (6 of the second drive's 8 s),
#: whose basins it then ranks as they do; of paper A's 80 s records it holds 6 s.
RINGING_SHARE = 0.5
#: A restart is refined on the whole records and may replace the best solution only if
#: it beats it by more than this (chi-square units) on the window it is screened on.
RESTART_MARGIN = 1.0
#: A restart whose screen ends above the solution it restarts from, but by less than
#: this (chi-square units, on the longest short window), and more than DISTINCT from
#: it, is refined on the whole records too: where it lands in another basin within
#: CHI2_95 above the best there, that basin is a rival, whose own profile the interval
#: spans. The short window ranks two basins nearly as the whole records do (as
#: WHOLE_RECORD_MARGIN has it); two units of slack keep a rival whose short-window rise
#: is a little above CHI2_95.
RIVAL_SCREEN = CHI2_95 + 2.0
#: A rival that the estimate's own Fisher quadratic puts within this of it (chi-square
#: units) lies on the floor of the estimate's basin, not in a basin of its own, and is
#: not counted as another minimum (its profile is still followed, one more start of the
#: profile's refits along that floor). Where a drive has no backlash the friction's
#: split is hardly determined, and the search's ends along that flat floor, as far apart
#: in their logarithms as two basins, lie 0.0025 or less up it
#: (tests/test_identify_real_drive.py, ``-k without_backlash_gets -s``); a basin of
#: another ringing phase, with k_sh several standard errors off, lies far up it.
BOWL_RISE = 1.0
#: Largest exponent :func:`bowl_rise` takes (``math.exp`` overflows past 709).
MAX_EXP = 700.0
#: A held-theta refit of the profile search ending more than this (chi-square units)
#: below the estimate's cost restarts the final refinement from there, at most
#: RECENTRE_MAX times: a rattling shaft's likelihood is rough at the scale of 1-2
#: units, and the refinement can stop on a bump next to a lower point.
RECENTRE_MARGIN = 0.5
RECENTRE_MAX = 2
#: Iterations of the screening refits of a term added after the search (the current
#: loop), one from each of its starts. Those that end within TEST_MARGIN (chi-square
#: units) of the model without it are converged. On speeds with friction and a loop,
#: the starts that find the loop's lag can still cost a little more than the model
#: without it after 4 iterations, and less once converged; on encoder angles, whose
#: noise is a count's, a loop at its floor (a quarter sample) costs orders of
#: magnitude more, and converging it took most of the fit's time for a term the test
#: drops anyway.
TEST_ITER = 4
TEST_MARGIN = 100.0
#: The added terms (friction, current loop) start from rough guesses
#: (:mod:`backlashkit.identify.terms`): the first window may move them a factor 100
#: either way, where the linear parameters stay within ``FirstHorizon.search_factor``.
EXTRA_BOX = math.log(100.0)
def resplit(z: np.ndarray, free: Sequence[str], pair: tuple[str, str],
            shift: float) -> np.ndarray | None:
    """Log-parameters ``z`` (theta first) with the ratio of a pair of parameters
    multiplied by ``e^shift``, their sum kept, and ``k_sh`` moved so that the ringing
    frequency ``k_sh (1/J_M + 1/J_L)`` is kept; None if the pair is not estimated."""
    if pair[0] not in free or pair[1] not in free:
        return None
    z = z.copy()
    ia, ib = 1 + free.index(pair[0]), 1 + free.index(pair[1])
    omega2 = None
    if "k_sh" in free and {"J_M", "J_L"} <= set(free):
        jm, jl = math.exp(z[1 + free.index("J_M")]), math.exp(z[1 + free.index("J_L")])
        omega2 = math.exp(z[1 + free.index("k_sh")]) * (1 / jm + 1 / jl)
    total = math.exp(z[ia]) + math.exp(z[ib])
    xa = total / (1.0 + math.exp(-(z[ia] - z[ib] + shift)))
    if not (0.0 < xa < total and math.isfinite(total)):  # one of the pair dwarfs the other
        return None
    z[ia], z[ib] = math.log(xa), math.log(total - xa)
    if omega2 is not None:
        jm, jl = math.exp(z[1 + free.index("J_M")]), math.exp(z[1 + free.index("J_L")])
        z[1 + free.index("k_sh")] = math.log(omega2 / (1 / jm + 1 / jl))
    return z


def distinct(states: Sequence[LMState], limit: float, worst: float,
             taken: Sequence[LMState] = ()) -> list[LMState]:
    """Up to ``limit`` of ``states`` (in order, until one costs more than ``worst``)
    apart from each other and from ``taken`` (:func:`same_point`)."""
    out: list[LMState] = []
    for st in states:
        if len(out) == limit or st.cost > worst:
            break
        if not any(same_point(st, c_) for c_ in [*taken, *out]):
            out.append(st)
    return out


def same_point(a: LMState, b: LMState) -> bool:
    """Whether two states count as one point: within :data:`SAME_POINT` in every
    log-parameter, or within :data:`DISTINCT` at a cost within :data:`SAME_COST`."""
    dz = float(np.max(np.abs(a.z - b.z)))
    return dz <= SAME_POINT or (dz <= DISTINCT and abs(a.cost - b.cost) <= SAME_COST)


def basins(ends: Sequence[LMState], core: Sequence[int]) -> int:
    """Distinct end points (:data:`DISTINCT` in the ``core`` log-parameters: theta and
    the linear ones) within :data:`AMBIGUITY_MARGIN` of the best. The added terms are
    left out: on the short windows Coulomb and viscous friction trade off freely,
    which moves no backlash."""
    best = min(st.cost for st in ends)
    found: list[np.ndarray] = []
    for st in sorted(ends, key=lambda st_: st_.cost):
        if st.cost <= best + AMBIGUITY_MARGIN and all(
                np.max(np.abs(st.z[core] - z)) > DISTINCT for z in found):
            found.append(st.z[core])
    return len(found)


def grid_minima(pb: Problem, rows0: Residual, grid: ThetaGrid, z_anchor: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Stage 1: the grid's points ``zg`` (log-parameters) and the indices of its local
    minima on the first window, lowest cost first."""
    thetas = grid.thetas()
    # the stiffness sets the ringing frequency: a wrong prior k_sh shifts its phase by
    # periods within the first window, so k_sh can be gridded too (rows)
    k_scales = grid.stiffness_scales() if "k_sh" in pb.free else [1.0]
    blocks = []
    for ks in k_scales:
        zk = z_anchor.copy()
        if "k_sh" in pb.free:
            zk[pb.free.index("k_sh")] += math.log(ks)
        blocks.append(np.column_stack([np.log(thetas), np.tile(zk, (thetas.size, 1))]))
    zg = np.concatenate(blocks)
    costs = np.sum(rows0(zg) ** 2, axis=1).reshape(len(k_scales), thetas.size)
    pad = np.pad(costs, 1, constant_values=np.inf)
    is_min = ((costs <= pad[1:-1, :-2]) & (costs <= pad[1:-1, 2:])
              & (costs <= pad[:-2, 1:-1]) & (costs <= pad[2:, 1:-1]))
    minima = np.flatnonzero(is_min.ravel())
    return zg, minima[np.argsort(costs.ravel()[minima])]


def two_step_start(drive: TwoMassDrive, recs: list[Record], workers
                   ) -> tuple[float, float] | None:
    """Paper A's two-step estimate and its pre-estimate, or None where it fails; the
    records ``recs`` as the joint fit checked them (not checked again)."""
    try:
        with warnings.catch_warnings():  # a start only: the joint fit says what matters
            warnings.simplefilter("ignore")
            est = TwoStepIdentifier(drive, allow_far_from_prior=True,
                                    workers=workers)._fit_checked(recs)
    except InputError:
        return None
    return float(est.theta_), float(est.theta_ini_)


def first_window(pb: Problem, rows0: Residual, z_starts: list[np.ndarray],
                 cfg: FirstHorizon, box) -> list[LMState]:
    """Stage 2: every start refined on the first window, then the best one from other
    splits of ``J_M + J_L`` and ``f_M + f_L``; lowest cost first."""
    states = [pb.refine(rows0, z0, cfg.max_iter, box) for z0 in z_starts]
    states.sort(key=lambda st: st.cost)
    variants = [resplit(states[0].z, pb.free, pair, d)
                for pair in (("J_M", "J_L"), ("f_M", "f_L"))
                for x in cfg.split_shifts for d in (-x, x)]
    variants = [z for z in variants if z is not None]
    if variants:
        states += [pb.refine(rows0, z, cfg.max_iter, box) for z in variants]
        states.sort(key=lambda st: st.cost)
    return states


def continue_on(pb: Problem, path: Sequence[float], states: list[LMState],
                windows: dict[float, Residual], sig: np.ndarray, max_iter: int,
                trail: list[list[LMState]] | None = None) -> list[LMState]:
    """Stage 3: ``states`` refined on each window of ``path`` in turn (``windows``
    caches the residuals by window); ``trail`` receives the states of every window."""
    for hz in path:
        if hz not in windows:
            windows[hz] = pb.residual(pb.screen, hz, sig)
        states = [pb.refine(windows[hz], st.z, max_iter) for st in states]
        if trail is not None:
            trail.append(states)
    return states


def direct_path(pb: Problem, path: Sequence[float], z0: np.ndarray,
                windows: dict[float, Residual], max_iter: int,
                rivals: Sequence[LMState]) -> list[LMState]:
    """The best start ``z0`` (the grid's lowest, at the prior's linear parameters)
    refined on each window of ``path`` in turn (cached in ``windows``), without the
    first window; empty unless, on the path's first window, it ends apart from every
    one of ``rivals`` (the continued candidates there) and below them all.

    On the first window the added terms may move a factor :data:`EXTRA_BOX` either way,
    and on noisy records with Coulomb friction every start can leave for a basin that
    the longer windows keep: at 30 dB one Coulomb torque went to 0, and the fit ended
    ``theta`` 5.6 % low and 65 above the truth in ``-2 log L``
    (``test_the_best_start_is_continued_past_the_first_window``). Where the first
    window did no harm, this path ends on its first window where the candidates did,
    and stops there."""
    st = pb.refine(windows[path[0]], z0, max_iter)
    if not (distinct([st], 1, math.inf, taken=rivals)
            and st.cost < min(r.cost for r in rivals)):
        return []
    for hz in path[1:]:
        st = pb.refine(windows[hz], st.z, max_iter)
    return [st]


def whole_record(pb: Problem, ends: list[LMState], rows_full: Residual, max_iter: int
                 ) -> tuple[LMState, list[LMState]]:
    """Stage 4: the distinct ends within :data:`WHOLE_RECORD_MARGIN` of the best refined
    on the final data; the lowest final cost and its rivals (:func:`rivals_of`)."""
    ends.sort(key=lambda st: st.cost)
    kept = distinct(ends, math.inf, ends[0].cost + WHOLE_RECORD_MARGIN)
    finals = sorted((pb.refine(rows_full, st.z, max_iter) for st in kept),
                    key=lambda st: st.cost)
    return finals[0], rivals_of(finals[0], finals[1:])


def rivals_of(best: LMState, states: Sequence[LMState]) -> list[LMState]:
    """The ``states`` (on the final data) in other basins than ``best``, more than
    :data:`DISTINCT` from it and from each other in some log-parameter, from
    :data:`RESTART_MARGIN` below its cost to ``CHI2_95`` above: minima of the
    likelihood whose basins the 95 % interval must span too. A point lower still would
    have replaced ``best`` (:func:`restart`)."""
    out: list[LMState] = []
    for st in sorted(states, key=lambda st_: st_.cost):
        if -RESTART_MARGIN <= st.cost - best.cost < CHI2_95 and all(
                np.max(np.abs(st.z - o.z)) > DISTINCT for o in [best, *out]):
            out.append(st)
    return out


def bowl_rise(jz: np.ndarray, z: np.ndarray, point: np.ndarray, natural: np.ndarray
              ) -> float:
    """The rise of ``-2 log L`` from the estimate ``z`` (Jacobian ``jz`` of its residual)
    to ``point`` by its Fisher quadratic in natural units: ``|jz dp/p|^2`` for the
    log-parameters (``jz``'s columns are ``p dr/dp``), each step a share of the value,
    and ``jz dz`` for those estimated in natural units (``natural``: their mask,
    ``Problem.scales > 0``). The logarithms' steps would not do: between two points
    near ``theta = 0`` they mean nothing, and a valley straight in natural units, as a
    friction split's of fixed sum, is curved in them."""
    dz = np.asarray(point, float) - z
    # capped where the ratio overflows (a theta next to 0, whose column is then about 0)
    step = np.where(natural, dz, np.expm1(np.minimum(dz, MAX_EXP)))
    return float(np.sum((jz @ step) ** 2))


def outside_bowl(jz: np.ndarray, z: np.ndarray, points: Sequence[np.ndarray],
                 natural: np.ndarray) -> list[np.ndarray]:
    """The ``points`` more than :data:`BOWL_RISE` up the Fisher quadratic of the
    estimate ``z`` (:func:`bowl_rise`): possible rivals in basins of their own."""
    return [pt for pt in points if bowl_rise(jz, z, pt, natural) > BOWL_RISE]


def prior_point(z: np.ndarray, free: Sequence[str], anchor: dict[str, float]
                ) -> np.ndarray:
    """Log-parameters ``z`` (theta first, then ``free``) with the linear parameters
    at the prior's, ``anchor`` (z units by name); theta and the terms kept."""
    z0 = z.copy()
    for i, name in enumerate(free):
        if name in LINEAR_PARAMS and name in anchor:
            z0[1 + i] = anchor[name]
    return z0


def restart_start(kind: str, shift: float, z: np.ndarray, free: Sequence[str],
                  anchor: dict[str, float]) -> np.ndarray | None:
    """The start of one restart (:meth:`~.search.Restarts.shifts`) of the solution
    ``z``: its linear parameters at the prior's ``anchor`` (:func:`prior_point`),
    ``k_sh`` shifted, the friction split shifted, or the prior's linear parameters with
    ``theta`` shifted; None where there is none."""
    if kind == "prior":
        return prior_point(z, free, anchor)
    if kind == "k_sh":
        z0 = z.copy()
        z0[1 + free.index("k_sh")] += shift
        return z0
    if kind == "theta":
        z0 = prior_point(z, free, anchor)
        z0[0] += shift
        return z0
    return resplit(z, free, ("f_M", "f_L"), shift)


def restart(pb: Problem, best: LMState, rows_short: Residual, rows_full: Residual,
            rows_long: Residual, cfg: Restarts, max_iter: int, anchor: dict[str, float],
            rivals: Sequence[LMState] = ()) -> tuple[LMState, list[LMState]]:
    """Stage 5: the best solution restarted from the prior's linear parameters
    ``anchor`` (z units by name), with ``k_sh`` and with the friction split shifted; a
    restart that screens :data:`RESTART_MARGIN` below the best is refined on the whole
    records, and kept if it lowers the final cost (:class:`~.search.Restarts`); one
    that screens within :data:`RIVAL_SCREEN` above it is refined there as a rival.
    Returns the best point and its rivals (:func:`rivals_of`) among the restarts and
    ``rivals`` (stage 4's). Then the restarts of :func:`long_restarts` on
    ``rows_long``."""
    shifts = cfg.shifts(pb.free)
    if not shifts:
        return long_restarts(pb, best, rows_long, rows_full, cfg, max_iter, list(rivals))
    ref = pb.refine(rows_short, best.z, max_iter)
    seen, near = [ref], list(rivals)  # seen: the basins on the short window

    def rival(st: LMState) -> bool:  # near enough, in a basin of its own
        return st.cost < ref.cost + RIVAL_SCREEN and all(
            np.max(np.abs(st.z - o.z)) > DISTINCT for o in seen)

    for kind, d_ in shifts:  # each from the best solution so far
        z0 = restart_start(kind, d_, best.z, pb.free, anchor)
        if z0 is None:
            continue
        st = pb.refine(rows_short, z0, min(RESTART_SCREEN_ITER, max_iter))
        if not (st.cost < ref.cost or rival(st)):
            continue
        if not st.done:
            st = pb.refine(rows_short, st.z, max_iter - RESTART_SCREEN_ITER, state=st)
        if st.cost < ref.cost - RESTART_MARGIN:
            st = pb.refine(rows_full, st.z, max_iter)
            if st.cost < best.cost:
                best, st = st, best
            near.append(st)
        elif rival(st):  # a rival, or better on the whole records
            seen.append(st)
            st = pb.refine(rows_full, st.z, max_iter)
            if st.cost < best.cost - RESTART_MARGIN:
                best, st = st, best
            near.append(st)
    return long_restarts(pb, best, rows_long, rows_full, cfg, max_iter, near)


def long_restarts(pb: Problem, best: LMState, rows_long: Residual, rows_full: Residual,
                  cfg: Restarts, max_iter: int, near: list[LMState]
                  ) -> tuple[LMState, list[LMState]]:
    """The best solution restarted with ``k_sh`` shifted by
    :meth:`~.search.Restarts.long_shifts`, each screened for
    :data:`RESTART_SCREEN_ITER` iterations on the long window ``rows_long``
    (:data:`LONG_WINDOW` times the longest short one); then, where that window holds
    :data:`RINGING_SHARE` of the final data or more, with ``k_sh`` and ``J_M`` shifted
    by :meth:`~.search.Restarts.ringing_shifts`, each screened there for up to
    :data:`RINGING_SCREEN_ITER`. One that ends :data:`RESTART_MARGIN` below the best
    there (:func:`long_reference`) is refined on the whole records and kept where it
    lowers their cost by :data:`RESTART_MARGIN` too. Returns the best point and its
    rivals among ``near`` and these (:func:`rivals_of`)."""
    shifts = [({"k_sh": d_}, RESTART_SCREEN_ITER) for d_ in cfg.long_shifts(pb.free)]
    if rows_long.n_res >= RINGING_SHARE * rows_full.n_res:
        shifts += [(d_, RINGING_SCREEN_ITER) for d_ in cfg.ringing_shifts(pb.free)]
    refs: dict[int, float] = {}
    for d_, screen in shifts:
        z0 = best.z.copy()
        for name, x in d_.items():
            z0[1 + pb.free.index(name)] += x
        st = pb.refine(rows_long, z0, min(screen, max_iter))
        if screen not in refs:
            refs[screen] = long_reference(pb, rows_long, best.z, screen, max_iter)
        if st.cost >= refs[screen] - RESTART_MARGIN:  # climbing back
            continue
        st = pb.refine(rows_full, st.z, max_iter)
        if st.cost < best.cost - RESTART_MARGIN:
            best, st, refs = st, best, {}
        near.append(st)
    return best, rivals_of(best, near)


def long_reference(pb: Problem, rows_long: Residual, z: np.ndarray, screen: int,
                   max_iter: int) -> float:
    """The cost on the long window that a restart screened there for ``screen``
    iterations must beat, from the best solution ``z``: against a screen of
    :data:`RESTART_SCREEN_ITER` iterations, its cost there as it is (near its minimum
    there, while a restart climbing back is still far above it); against a longer
    screen, which runs on to the minimum it reaches, ``z`` refined there as long, so
    that a restart back in its basin does not count as below it."""
    if screen <= RESTART_SCREEN_ITER:
        return float(np.sum(rows_long.at(z) ** 2))
    return pb.refine(rows_long, z, min(screen, max_iter)).cost


def reestimate_noise(pb: Problem, best: LMState, sig: np.ndarray, final_h: float | None,
                     n_recs: int, passes: int, max_iter: int) -> tuple[LMState, np.ndarray]:
    """Stage 6: each record's and channel's noise level from the residuals
    (``sqrt(RSS / N)``), then a refit; ``passes`` times."""
    spans = pb.final_spans(final_h)
    for _ in range(passes):
        r = best.r
        sq, count, pos = np.zeros_like(sig), np.zeros(n_recs), 0
        for sp, s_ in zip(spans, selection(spans, final_h), strict=True):
            m = sample_count(s_)
            sq[sp.k] += (np.sum(r[pos : pos + m] ** 2), np.sum(r[pos + m : pos + 2 * m] ** 2))
            count[sp.k] += m
            pos += 2 * m
        sig = np.maximum(sig * np.sqrt(sq / count[:, np.newaxis]), 1e-300)
        best = pb.refine(pb.residual(spans, final_h, sig), best.z, max_iter)
    return best, sig


def whiten_noise(pb: Problem, best: LMState, sig: np.ndarray, noise_model, n_recs: int,
                 noise_iter: int, max_iter: int
                 ) -> tuple[LMState, np.ndarray, np.ndarray | None]:
    """Stage 7: with a coloured noise model, ``A(q)`` and the innovation's level fitted
    to the residuals of the whole records, and a refit on the whitened residuals."""
    ar = None
    passes = noise_model._whitening_passes(noise_iter)
    if passes:
        sig = sig.copy()  # the earlier stages' residual functions keep theirs
    for _ in range(passes):
        sims = pb.simulate(best.z[np.newaxis, :], pb.spans)
        coef: dict[tuple[int, int], np.ndarray] = {}
        for sp, x in zip(pb.spans, sims, strict=True):
            for c, y in enumerate((sp.y_m, sp.y_l)):
                coef[sp.k, c], var = noise_model._fit_channel(y - x[0, :, c])
                sig[sp.k, c] = math.sqrt(max(var, 1e-300))
        ar = np.array([[coef[k, c] for c in (0, 1)] for k in range(n_recs)])
        best = pb.refine(pb.residual(pb.spans, None, sig, ar), best.z, max_iter)
    return best, sig, ar


@dataclass
class Uncertain:
    """The final point, its Fisher covariance (natural units) and its interval."""

    best: LMState
    values: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    interval: ThetaInterval
    jz: np.ndarray = field(repr=False)  # Jacobian of the residual in log-parameters
    cov_z: np.ndarray = field(repr=False)  # inverse of jz^T jz


def uncertainty(pb: Problem, best: LMState, rows_unc: Residual, interval, max_iter: int,
                draw: Callable[[np.ndarray, np.random.Generator], list[Record]],
                refit: Callable[[list[Record]], float], *, look_past: bool = False,
                anchor: dict[str, float] | None = None,
                rivals: Sequence[np.ndarray] = (), jacobian: np.ndarray | None = None
                ) -> Uncertain:
    """Stage 8: Gauss-Newton covariance and the interval object's interval; a profile
    refit well below the estimate's cost moves the estimate there (at most
    :data:`RECENTRE_MAX` times). ``draw(z, rng)``: a bootstrap resample at ``z``;
    ``refit(records)``: its ``theta``; ``look_past``: :attr:`IntervalInputs.look_past`;
    ``anchor``: the prior's point (z units by name), a second start of the profile's
    end refits (:attr:`IntervalInputs.anchor`); ``rivals``: the search's other minima
    (log-parameters of ``pb``), refitted on ``rows_unc`` and handed on where they stay
    rivals (:attr:`IntervalInputs.rivals`; those outside the estimate's Fisher
    quadratic, :func:`outside_bowl`, are counted as :attr:`ThetaInterval.rivals`);
    ``jacobian``: the Jacobian of ``rows_unc`` at ``best.z``, where already made."""
    near = [pb.refine(rows_unc, z, max_iter) for z in rivals]
    for k_centre in range(RECENTRE_MAX + 1):
        z = best.z
        jz = (jacobian if k_centre == 0 and jacobian is not None
              else pb.central_jacobian(rows_unc, z))
        cov_z = fisher_covariance(jz)
        values = pb.values(z)
        dv = np.where(pb.scales > 0, pb.scales, values)  # delta method: dp = p dz
        cov = cov_z * np.outer(dv, dv)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        others = rivals_of(best, near)
        found = interval._interval(IntervalInputs(
            float(values[0]), float(std[0]), z, cov_z, float(best.cost), rows_unc,
            pb.fd_step, partial(draw, z), refit,
            partial(rows_unc.exact_jacobian, with_theta=False), look_past,
            None if anchor is None else prior_point(z, pb.free, anchor)[1:],
            [(st.z, st.cost) for st in others]))
        if found.rivals:  # the profile's: of those, the minima in basins of their own
            found = replace(found, rivals=len(outside_bowl(jz, z, [st.z for st in others],
                                                           pb.scales > 0)))
        if k_centre == RECENTRE_MAX or found.lowest_rise > -RECENTRE_MARGIN:
            break
        st = pb.refine(rows_unc, found.lowest_z, max_iter)
        if st.cost > best.cost - RECENTRE_MARGIN:
            break
        best = st
    return Uncertain(best, values, cov, std, found, jz, cov_z)  # z is best.z on every exit


def prior_rise(pb: Problem, rows: Residual, z: np.ndarray) -> float:
    """-2 log L on ``rows`` of the prior's linear parameters, ``theta`` and the added
    terms as at the estimate ``z``, above the estimate's (``step.prior_refuted``)."""
    z_prior = z.copy()
    for i, name in enumerate(pb.free):
        if name in LINEAR_PARAMS:
            z_prior[1 + i] = math.log(pb.p_prior[i])
    return float(np.sum(rows.at(z_prior) ** 2) - np.sum(rows.at(z) ** 2))


def fisher_covariance(jz: np.ndarray) -> np.ndarray:
    """The Gauss-Newton covariance ``(J^T J)^-1`` of the estimated values from the
    residual's Jacobian ``jz`` (the prior's rows are in it: its information is in
    ``J^T J``); where that is singular, the pseudo-inverse of its columns scaled to
    unit norm. Unscaled, the pseudo-inverse's cut-off (relative to the largest
    singular value) would take the column of a ``theta`` next to 0, ``theta dr/dtheta``
    in its logarithm, for no information, and give it a standard error of 0."""
    info = jz.T @ jz
    try:
        return np.linalg.inv(info)
    except np.linalg.LinAlgError:
        norm = np.sqrt(np.diag(info))
        s = 1.0 / np.where(norm > 0, norm, 1.0)  # a column of zeros stays as it is
        return np.linalg.pinv(info * np.outer(s, s)) * np.outer(s, s)


def resample(pb: Problem, sig: np.ndarray, ar: np.ndarray | None, z: np.ndarray,
             rng: np.random.Generator) -> list[Record]:
    """Records simulated from log-parameters ``z`` with the fitted noise added (read by
    the records' encoders where they hold encoder angles)."""
    sims = pb.simulate(z[np.newaxis, :], pb.spans)
    records = []
    for sp, x in zip(pb.spans, sims, strict=True):
        if sp.positions and sp.record.quantum > 0:
            records.append(quantised_resample(sp, model_angles(x), rng))
            continue
        clean = model_angles(x) if sp.positions else (x[:, :, 0], x[:, :, 1])
        y_m, y_l = (clean[c][0] + sample_noise(rng, sig[sp.k, c],
                                               None if ar is None else ar[sp.k, c], sp.t.size)
                    for c in (0, 1))
        name = f"{sp.record.name} (bootstrap)"
        records.append(Record.from_positions(sp.t, sp.torque, y_m, y_l, name=name)
                       if sp.positions else Record(sp.t, sp.torque, y_m, y_l, name=name))
    return records


def quantised_resample(sp: Span, angles: tuple[np.ndarray, np.ndarray],
                       rng: np.random.Generator) -> Record:
    """A span's record read by its encoders from the model's angles, each encoder from
    a uniformly random offset within a count (its quantisation is the noise)."""
    q = sp.record.quantum
    counts = [np.floor((a[0] + rng.uniform(0.0, q)) / q) for a in angles]
    return Record.from_positions(sp.t, sp.torque, *counts, counts_per_rev=2 * math.pi / q,
                                 name=f"{sp.record.name} (bootstrap)")


def residuals_and_fit(spans: Sequence[Span], sims: list[np.ndarray]):
    """Residuals ``(w_M, w_L)`` per span and the NRMSE fit % array ``(n_spans, 2)``."""
    residuals, fits = [], []
    for sp, x in zip(spans, sims, strict=True):
        em, el = sp.y_m - x[0, :, 0], sp.y_l - x[0, :, 1]
        residuals.append((em, el))
        fits.append([
            100.0 * (1.0 - np.linalg.norm(e) / max(np.linalg.norm(y - y.mean()), 1e-300))
            for e, y in ((em, sp.y_m), (el, sp.y_l))
        ])
    return residuals, np.array(fits)


def refuse_unexplained(recs: list[Record], fits: np.ndarray, terms: Sequence[Term] = ()
                       ) -> None:
    """Raise when the model explains a speed worse than its mean (fit % <= 0); a
    term fixed by the user (a known current loop) is named as a suspect too."""
    worst = np.unravel_index(int(np.argmin(fits)), fits.shape)
    if not fits[worst] > 0:
        fixed: list[str | Option] = []
        for term in terms:
            if term.mode == "fixed":
                fixed += [f", and the fixed {TERM_NAMES[term.name]} (try ",
                          Option(term.name, "auto"), ")"]
        raise InputError(
            f"{recs[worst[0]].name}: the identified model does not explain "
            f"{('w_motor', 'w_load')[worst[1]]} (fit {fits[worst]:.3g} %, worse than its "
            "mean): these speeds do not show a two-mass drive responding to this torque; "
            "check the columns, units and the prior", *fixed
        )


def select_terms(pb: Problem, best: LMState, sig: np.ndarray, final_h: float | None,
                 terms: Sequence[Term], recs: list[Record], max_iter: int,
                 ar: np.ndarray | None = None
                 ) -> tuple[Problem, LMState, list[TermChoice]]:
    """Likelihood-ratio tests of the ``"auto"`` terms, in order. A term in the search
    is removed and the nested model refitted from ``best``; one outside it is first
    screened by its score test (:mod:`._score`), then added (each start of
    :meth:`Term.start_grid` refitted, the lowest going on) and the larger model
    refitted. The term is kept where ``-2 log L`` is lower with it by more than its
    threshold, or where removing it moves ``theta`` (:meth:`TermChoice.decide`). Every
    residual is weighed by ``sig`` and whitened by ``ar`` (None: white noise)."""
    choices = []
    seen: dict[tuple[int, bytes], tuple[Problem, Linearised]] = {}
    for term in terms:
        if term.mode != "auto":
            continue
        if term.searched:
            other, keep = pb.without(term.params)
            res = other.residual(other.final_spans(final_h), final_h, sig, ar)
            st = other.refine(res, best.z[keep], max_iter)
            (small, st_small), st_big = (other, st), best
            # stopped far from its optimum, its theta says nothing: no shift
            theta_std = (linearised(seen, small, st_small, sig, final_h, ar).theta_std
                         if st.done else math.nan)
        else:
            other = pb.with_params(term.params, term.floors(recs), term.scales(recs))
            res = other.residual(other.final_spans(final_h), final_h, sig, ar)
            score = score_test(pb, best, linearised(seen, pb, best, sig, final_h, ar), other, res,
                               term, recs)
            if score.screened:
                choices.append(TermChoice(
                    term.name, False, score.drop, term.threshold, score.shift,
                    screened=True, widening=score.widening,
                    held_ci95=held_ci95(pb, best, term, recs, final_h, sig, max_iter,
                                        linearised(seen, pb, best, sig, final_h, ar).theta_std,
                                        ar)))
                continue
            widening = score.widening
            st = added_term_fit(other, res, best.z, best.cost, term, recs, max_iter)
            (small, st_small), st_big = (pb, best), st
            theta_std = linearised(seen, pb, best, sig, final_h, ar).theta_std
        rise = st_small.cost - st_big.cost
        big = pb if term.searched else other
        std_big = linearised(seen, big, st_big, sig, final_h, ar).std
        choice = TermChoice.decide(
            term.name, rise, term.threshold, abs(st_big.z[0] - st_small.z[0]) / theta_std,
            determined(big, st_big.z, std_big, [big.names.index(n) for n in term.params]),
            (fisher_ci95(st_big.z, std_big), fisher_ci95(st_small.z, np.r_[theta_std])))
        if not term.searched and not choice.kept:
            choice = replace(choice, widening=widening,
                             held_ci95=held_ci95(pb, best, term, recs, final_h, sig, max_iter,
                                                 theta_std, ar))
        choices.append(choice)
        if choice.kept != term.searched:  # the other model wins
            pb, best = other, st
    return pb, best, choices


def tested_terms(pb: Problem, best: LMState, sig: np.ndarray, final_h: float | None,
                 terms: Sequence[Term], recs: list[Record], max_iter: int, noise_model,
                 noise_iter: int) -> tuple[Problem, LMState, list[TermChoice]]:
    """:func:`select_terms` under the likelihood of ``noise_model``. Under coloured
    noise the white likelihood's rises are too large, so the test keeps terms the
    data do not call for, and its intervals and spans too narrow: the residual is
    whitened first (:func:`whiten_noise`) and the chosen model refitted on the white
    one after, which the stages up to the final whitening weigh. White noise: the
    tests as they were, at no cost."""
    w_best, w_sig, ar = whiten_noise(pb, best, sig, noise_model, len(recs), noise_iter,
                                     max_iter)
    pb, w_best, choices = select_terms(pb, w_best, w_sig, final_h, terms, recs, max_iter,
                                       ar)
    if ar is None:
        return pb, w_best, choices
    white = pb.residual(pb.final_spans(final_h), final_h, sig)
    return pb, pb.refine(white, w_best.z, max_iter), choices


def held_ci95(pb: Problem, best: LMState, term: Term, recs: list[Record],
              final_h: float | None, sig: np.ndarray, max_iter: int, theta_std: float,
              ar: np.ndarray | None = None) -> tuple[float, float] | None:
    """The 95 % interval of ``theta`` in rad over the values of a dropped one-parameter
    ``term`` the data do not rule out: ``pb`` (the model without it) refitted from
    ``best`` with the term held at each of its starts (:meth:`Term.start_grid`, in
    ascending order, each from the one before), the union of ``theta_k -+ 1.96 s
    sqrt(1 - rise_k / 3.84)`` in logarithms over those whose ``-2 log L`` lies within
    :data:`CHI2_95` of the lowest (the fit without the term, at 0, among them); ``s``:
    ``theta_std``, the model's own standard error of ``log theta``. It stops at the
    first beyond, and at the first start the kernel cannot simulate. The residual is
    weighed by ``sig`` and whitened by ``ar`` (None: white noise). None where no
    held fit lies within, or where the model's own interval reaches ``theta = 0``
    (:func:`._score.bounds_theta`).

    The score test's linearisation (:attr:`TermChoice.widening`) takes ``theta``'s
    move with the term as linear; on a stiff drive with Coulomb friction it is not, and
    the held fits reach nearly twice as far from the estimate (docs/design/real-drives.md,
    trial 19 of the real-drive study)."""
    (name,) = term.params
    if not bounds_theta(theta_std):
        return None
    held, z = [], best.z
    for start in sorted(term.start_grid(recs), key=lambda st: st[name]):
        other = pb.holding(name, start[name])
        rows = other.residual(other.final_spans(final_h), final_h, sig, ar)
        st = other.refine(rows, z, max_iter)
        if not math.isfinite(st.cost):
            break
        held.append((float(st.z[0]), st.cost - best.cost))
        if st.cost - best.cost - min(0.0, *(r for _, r in held)) > CHI2_95:
            break
        z = st.z
    lowest = min([0.0, *(r for _, r in held)])
    ends = [(zt - Z_95 * theta_std * math.sqrt(room), zt + Z_95 * theta_std * math.sqrt(room))
            for zt, rise in held if (room := 1.0 - (rise - lowest) / CHI2_95) >= 0]
    if not ends:
        return None
    return math.exp(min(e[0] for e in ends)), math.exp(max(e[1] for e in ends))


def added_term_fit(pb: Problem, res: Residual, z: np.ndarray, cost: float, term: Term,
                   recs: list[Record], max_iter: int) -> LMState:
    """The larger model's fit from the smaller one's point ``z`` (of cost ``cost``):
    every start of the added term refitted for :data:`TEST_ITER` iterations, those
    then within :data:`TEST_MARGIN` of ``cost`` converged, the lowest kept. A start that
    walks the term to its floor can be a local minimum where the drive has friction as
    well, so more than the best screened start goes on."""
    screened = [pb.refine(res, np.r_[z, pb.z_of(term.params, [start[n] for n in term.params])],
                          TEST_ITER) for start in term.start_grid(recs)]
    hopeful = [st for st in screened if st.cost < cost + TEST_MARGIN]
    return min((pb.refine(res, st.z, max_iter, state=st) for st in hopeful) if hopeful
               else screened, key=lambda st: st.cost)


def linearised(seen: dict, pb: Problem, st: LMState, sig: np.ndarray,
               final_h: float | None, ar: np.ndarray | None = None) -> Linearised:
    """The whole-record residual of ``pb`` linearised at ``st`` (:func:`._score.linearise`),
    once per model and point: the model the friction test keeps is the one the loop's
    test starts from. ``seen`` holds those already made."""
    key = (id(pb), st.z.tobytes())
    if key not in seen or seen[key][0] is not pb:
        seen[key] = (pb, linearise(pb.residual(pb.final_spans(final_h), final_h, sig, ar),
                                   st.z))
    return seen[key][1]


def fisher_ci95(z: np.ndarray, std: np.ndarray) -> tuple[float, float]:
    """``theta -+ 1.96 std`` in rad of log-parameters ``z`` (theta first) and their
    standard errors."""
    theta = math.exp(z[0])
    return theta * (1.0 - Z_95 * std[0]), theta * (1.0 + Z_95 * std[0])


def widened(found: ThetaInterval, choices: Sequence[TermChoice]) -> ThetaInterval:
    """The interval, widened to the other model's where a test could not tell the two
    apart (:attr:`TermChoice.other_ci95`), and out by a dropped term's
    :attr:`TermChoice.widening` and :attr:`TermChoice.held_ci95`."""
    lo0, hi0 = lo, hi = found.ci95
    for c in choices:
        down, up = c.widening
        lo = min(lo, lo0 * math.exp(-down))
        # no further than the profile follows theta: past it the end is open
        hi = max(hi, min(hi0 * math.exp(min(up, MAX_EXP)), MAX_HALF_WIDTH))
        for other in (c.other_ci95, c.held_ci95):
            if other is not None:
                lo, hi = min(lo, other[0]), max(hi, min(other[1], MAX_HALF_WIDTH))
    if (lo, hi) == found.ci95:
        return found
    opened = hi >= MAX_HALF_WIDTH > hi0
    return replace(found, ci95=(lo, hi), bounded=(found.bounded[0],
                                                  found.bounded[1] and not opened))


def determined(pb: Problem, z: np.ndarray, std: np.ndarray, cols: list[int]) -> bool:
    """Whether the data pin the values ``z[cols]`` down: a logarithm within a factor
    ``e`` at one standard error, a value in natural units away from 0 (a parameter
    sitting on its floor has next to no information and fails)."""
    return all(std[i] < (1.0 if pb.scales[i] == 0 else abs(z[i])) for i in cols)


@dataclass
class Outcome:
    """What one search found, for the estimator to publish."""

    problem: Problem
    unc: Uncertain  # the final point, its covariance and interval
    sigma: np.ndarray  # noise (innovation) std per record and channel
    ar: np.ndarray | None
    rows_unc: Residual  # the residual of the final point's likelihood
    sims: list[np.ndarray]  # the model at the estimate over the spans
    starts: list[float]
    two_step: tuple[float, float] | None
    ambiguous: bool
    choices: list[TermChoice]  # the likelihood-ratio tests of the "auto" terms
    fixed: dict[str, FixedTest] = field(default_factory=dict)  # fixed terms' tests
    prior_rise: float = math.nan  # :func:`prior_rise` at the search's answer


#: Stages of :func:`run` reported to its ``stage`` callback, by name (a progress bar
#: shows the one running).
STAGE_NAMES = ("starts (theta grid)", "first window", "continuation", "whole records",
               "noise levels", "model terms (friction, loop)", "uncertainty and interval")
STAGES = len(STAGE_NAMES)
#: ``locate``'s default: make the two-step start (None: there is none).
_UNSET = object()


def run(pb: Problem, search: JointSearch, sigma: np.ndarray, recs: list[Record], *,
        start_drive: TwoMassDrive, z_anchor: np.ndarray, fixed_noise: bool, noise_model,
        interval, refit: Callable[[list[Record]], float], terms: Sequence[Term] = (),
        refuse_far: Callable[[dict[str, float], float, dict[str, float]], None]
        = lambda linear, rise, log_std: None,
        stage: Callable[[int], None] = lambda done: None) -> Outcome:
    """The whole search from ``z_anchor`` (log linear parameters, then the added
    terms'), the noise levels, the choice of the ``"auto"`` terms, the uncertainty and
    the interval. ``refit(records)``: ``theta`` of a bootstrap resample's fit;
    ``refuse_far(linear, rise, log_std)``: raises where the estimated linear parameters
    (by name; ``log_std``: the standard errors of their logarithms) are too far from
    the prior (``rise``: :func:`prior_rise`), checked before the uncertainty;
    ``stage(k)``: called as each of the :data:`STAGES` stages ends."""
    final_h = search.final_horizon
    anchor = dict(zip(pb.free, z_anchor, strict=True))
    located = locate(pb, search, sigma, recs, start_drive, z_anchor, stage=stage)
    best, starts, two_step, ambiguous, rivals = located
    # by name: the terms' tests below can drop a parameter or add one
    rival_points = [dict(zip(pb.names, st.z, strict=True)) for st in rivals]
    stage(4)
    noise_passes = 0 if fixed_noise else search.noise_iter
    best, sig = reestimate_noise(pb, best, sigma, final_h, len(recs), noise_passes,
                                 search.max_iter)
    stage(5)
    pb, best, choices = tested_terms(pb, best, sig, final_h, terms, recs, search.max_iter,
                                     noise_model, search.noise_iter)
    pb, best = prior_terms(pb, best, sig, final_h, terms, recs, search.max_iter)
    if joined_terms(terms, choices):
        pb, best, sig, choices = research(pb, best, sig, search, sigma, recs, start_drive,
                                          anchor, terms, choices, two_step, noise_passes,
                                          noise_model)
    best, sig, ar = whiten_noise(pb, best, sig, noise_model, len(recs), search.noise_iter,
                                 search.max_iter)
    stage(6)
    # a model that explains a speed worse than its mean has fitted nothing: say so
    # before the uncertainty (whose refits at such a point can take minutes)
    checked_z, sims = best.z, pb.simulate(best.z[np.newaxis, :], pb.spans)
    refuse_unexplained(recs, residuals_and_fit(pb.spans, sims)[1], terms)
    rows_unc = pb.residual(pb.final_spans(final_h), final_h, sig, ar)
    rise = prior_rise(pb, rows_unc, best.z)
    jz = pb.central_jacobian(rows_unc, best.z)  # the uncertainty's first, made here
    log_std = np.sqrt(np.maximum(np.diag(fisher_covariance(jz)), 0.0))
    refuse_far({n: float(x) for n, x in zip(pb.names, pb.values(best.z), strict=True)
                if n in LINEAR_PARAMS}, rise,
               {n: float(x) for n, x in zip(pb.names, log_std, strict=True)
                if n in LINEAR_PARAMS})
    # a term added after the search (a loop's lag) trades against the linear parameters
    # along a curved valley, and theta's profile can fall again past a crossing
    unc = uncertainty(pb, best, rows_unc, interval, search.max_iter,
                      partial(resample, pb, sig, ar), refit,
                      look_past=bool(joined_terms(terms, choices))
                      or any(t.mode == "prior" for t in terms),
                      anchor=anchor if search.restarts.prior else None,
                      rivals=[np.array([pt.get(n, x) for n, x in zip(pb.names, best.z,
                                                                    strict=True)])
                              for pt in rival_points], jacobian=jz)
    if quantised(rows_unc):
        errors = quantisation_errors(unc, rows_unc)
        unc.interval = interval._quantised(unc.interval, float(unc.values[0]), errors)
        choices = quantised_choices(choices, errors)
    unc.interval = widened(unc.interval, choices)
    stage(7)
    if unc.best.z is not checked_z:  # the profile search re-centred the estimate
        sims = pb.simulate(unc.best.z[np.newaxis, :], pb.spans)
    fixed = {t.params[0]: fixed_test(pb, unc.best, t, recs, final_h, sig, search.max_iter)
             for t in terms if t.mode == "fixed"}
    return Outcome(pb, unc, sig, ar, rows_unc, sims, starts, two_step, ambiguous, choices,
                   fixed, rise)


@dataclass(frozen=True)
class FixedTest:
    """The test of a term the user fixed (a known current loop's ``tau_i``): the fall
    of ``-2 log L`` when it is fitted too (chi-square, one degree of freedom where the
    fixed value is right), and the value it is fitted to."""

    fall: float
    value: float


def fixed_test(pb: Problem, best: LMState, term: Term, recs: list[Record],
              final_h: float | None, sig: np.ndarray, max_iter: int) -> FixedTest:
    """:class:`FixedTest` of the one-parameter fixed ``term``: the model refitted with
    it free from the estimate (a fit's cost). A score test there would not do: the
    other parameters have made up for a wrong lag, so its linearised fall understates
    the refit's."""
    (name,) = term.params
    big = pb.with_params([name], term.floors(recs), {})
    res = big.residual(big.final_spans(final_h), final_h, sig)
    z_fixed = np.r_[best.z, math.log(term.fixed[0])]
    r = res.at(z_fixed)
    cost = float(r @ r)
    if not math.isfinite(cost):
        return FixedTest(math.nan, math.nan)
    st = big.refine(res, z_fixed, max_iter)
    return FixedTest(max(cost - st.cost, 0.0), math.exp(float(st.z[-1])))


def locate(pb: Problem, search: JointSearch, sigma: np.ndarray, recs: list[Record],
           start_drive: TwoMassDrive, z_anchor: np.ndarray, *, two_step=_UNSET,
           stage: Callable[[int], None] = lambda done: None, restarted: bool = True,
           seen: list[list[LMState]] | None = None
           ) -> tuple[LMState, list[float], tuple[float, float] | None, bool,
                      list[LMState]] | None:
    """Stages 1-4 from ``z_anchor``: the grid, the first window, the continuation, the
    whole records and, where ``restarted``, the restarts (:func:`restarts_of`). Returns
    the best point, the starts' ``theta``, the two-step estimate (``two_step`` reuses
    one already made), whether the landscape was ambiguous and the rivals of the best
    point (:func:`rivals_of`). With ``seen`` (the continuation's candidates of earlier
    searches, extended here), None where every candidate of this one is one of them
    (:func:`same_point`): its continuation would end where theirs did."""
    short = [search.first.horizon, *search.continuation.horizons]
    rows0 = pb.residual(pb.screen, short[0], sigma)
    zg, minima = grid_minima(pb, rows0, search.grid, z_anchor)
    n_starts = search.grid.starts
    z_starts = [zg[i] for i in minima[:n_starts]]
    starts = [float(math.exp(z[0])) for z in z_starts]
    if two_step is _UNSET:
        two_step = (two_step_start(start_drive, recs, pb.workers)
                    if search.grid.two_step_start else None)
    if two_step is not None:
        starts.append(two_step[0])
        z_starts.append(np.concatenate([[math.log(two_step[0])], z_anchor]))
    stage(1)
    box = widen_box(pb, search.first.box(search.grid.theta_max, z_anchor))
    states = first_window(pb, rows0, z_starts, search.first, box)
    stage(2)
    cont, max_iter = search.continuation, search.max_iter
    cands = distinct(states, cont.candidates, CONTINUE_RATIO * states[0].cost)
    if seen is not None:
        if any(all(any(same_point(c, o) for o in old) for c in cands) for old in seen):
            return None
        seen.append(cands)
    # two paths, the second finer and from the best candidate only: a long step can
    # jump to a wrong basin where the ringing is rich, a short one elsewhere
    paths = cont.paths(short[0])
    windows: dict[float, Residual] = {}
    ends: list[LMState] = []
    trail: list[list[LMState]] = []
    for k_path, path in enumerate(paths):
        ends += continue_on(pb, path, cands if k_path == 0 else cands[:1], windows, sigma,
                            max_iter, trail if k_path == 0 else None)
    # distinct ends of nearly equal cost: the landscape is multimodal here, so continue
    # more first-window solutions (more grid minima among their starts)
    core = [i for i, n in enumerate(pb.names) if n == "theta" or n in LINEAR_PARAMS]
    ambiguous = bool(len(paths[0]) and basins(ends, core) > 1)
    if cont.ambiguity_starts and ambiguous:
        more = minima[n_starts : n_starts + cont.ambiguity_starts]
        states += [pb.refine(rows0, zg[i], search.first.max_iter, box) for i in more]
        states.sort(key=lambda st: st.cost)
        extra = distinct(states, cont.ambiguity_starts, math.inf, taken=cands)
        ends += continue_on(pb, paths[0], extra, windows, sigma, max_iter)
    if cont.direct and paths[0]:
        ends += distinct(direct_path(pb, paths[0], z_starts[0], windows, max_iter,
                                     trail[0]), 1, math.inf, taken=ends)
    stage(3)
    final_h = search.final_horizon
    rows_full = pb.residual(pb.final_spans(final_h), final_h, sigma)
    best, rivals = whole_record(pb, ends, rows_full, max_iter)
    if restarted:
        best, rivals = restarts_of(pb, search, sigma, best, rivals, z_anchor)
    return best, starts, two_step, ambiguous, rivals


def restarts_of(pb: Problem, search: JointSearch, sigma: np.ndarray, best: LMState,
                rivals: list[LMState], z_anchor: np.ndarray
                ) -> tuple[LMState, list[LMState]]:
    """The restarts of the whole records' best point (:func:`restart`), with the prior's
    linear parameters in ``z_anchor``: the best point and its rivals."""
    final_h = search.final_horizon
    short_h = [search.first.horizon, *search.continuation.horizons][-1]
    rows_full = pb.residual(pb.final_spans(final_h), final_h, sigma)
    long_h = LONG_WINDOW * short_h
    # a final horizon no longer than the long window: the final data are the longest
    rows_long = (rows_full if final_h is not None and final_h <= long_h
                 else pb.residual(pb.screen, long_h, sigma))
    return restart(pb, best, pb.residual(pb.screen, short_h, sigma), rows_full, rows_long,
                   search.restarts, search.max_iter, dict(zip(pb.free, z_anchor, strict=True)),
                   rivals)


def prior_terms(pb: Problem, best: LMState, sig: np.ndarray, final_h: float | None,
                terms: Sequence[Term], recs: list[Record], max_iter: int
                ) -> tuple[Problem, LMState]:
    """The terms with a prior std (a known loop's ``tau_i``), held at their values
    through the search, now fitted about them with that prior (a penalty row, as the
    linear parameters'), from the search's point; always kept."""
    for term in terms:
        if term.mode != "prior":
            continue
        priors = {n: (x, term.prior_std) for n, x in zip(term.params, term.fixed,
                                                          strict=True)}
        pb = pb.with_params(term.params, term.floors(recs), term.scales(recs), priors)
        res = pb.residual(pb.final_spans(final_h), final_h, sig)
        best = pb.refine(res, np.r_[best.z, pb.z_of(term.params, term.fixed)], max_iter)
    return pb, best


def joined_terms(terms: Sequence[Term], choices: Sequence[TermChoice]) -> list[Term]:
    """The ``"auto"`` terms added after the search whose test kept them."""
    kept = {c.term for c in choices if c.kept}
    return [t for t in terms if t.mode == "auto" and not t.searched and t.name in kept]


def research(pb: Problem, best: LMState, sig: np.ndarray, search: JointSearch,
             sigma: np.ndarray, recs: list[Record], start_drive: TwoMassDrive,
             anchor: dict[str, float], terms: Sequence[Term], choices: list[TermChoice],
             two_step, noise_passes: int, noise_model
             ) -> tuple[Problem, LMState, np.ndarray, list[TermChoice]]:
    """Stages 1-5 again with a term the test added in the search, from the prior's
    point ``anchor`` (z units by name) with each of the added term's starts
    (:func:`research_anchors`), the lowest going on; then every
    ``"auto"`` term of the model tested again by removal (a term the first test
    removed stays out).

    A term added after the search is refitted from the search's answer, where the
    linear parameters have absorbed what the term does: on a stiff drive a current
    loop's lag moves ``J_M`` and ``k_sh`` by several per cent, and the refit from there
    crawls along a narrow valley and stops short of the truth even on noise-free
    records, while the search with the term in it lands on it
    (``test_a_loop_found_after_the_search_is_searched_again``). The first answer is
    kept where it is lower. Each start costs a search up to the whole records (a fit
    that keeps a loop searches once more per start of its lag, four,
    ``terms.TAU_START_SAMPLES``), but one whose first window lands where an earlier
    start's did stops there (:func:`locate`'s ``seen``): the lag is free in the first
    window, which on paper A's records takes every start of it to the same candidates.
    Only the lowest on the whole records is restarted (:func:`restarts_of`): the
    starts differ in the lag alone, and their restarts, from the same prior, search the
    same basins again."""
    final_h = search.final_horizon
    rows = pb.residual(pb.final_spans(final_h), final_h, sig)
    seen: list[list[LMState]] = []
    found = [(out, z_anchor) for z_anchor in research_anchors(pb, best, anchor, terms, recs)
             if (out := locate(pb, search, sigma, recs, start_drive, z_anchor,
                               two_step=two_step, restarted=False, seen=seen)) is not None]
    (st, *_, rivals), z_anchor = min(found, key=lambda f: f[0][0].cost)
    st, _ = restarts_of(pb, search, sigma, st, rivals, z_anchor)
    again, sig2, cost = best, sig, best.cost
    st, s2 = reestimate_noise(pb, st, sigma, final_h, len(recs), noise_passes,
                              search.max_iter)
    c = float(np.sum(rows.at(st.z) ** 2))
    if c < cost:
        again, sig2, cost = st, s2, c
    tested = [replace(t, searched=True) for t in terms
              if t.mode == "auto" and all(n in pb.names for n in t.params)]
    pb, again, retested = tested_terms(pb, again, sig2, final_h, tested, recs,
                                       search.max_iter, noise_model, search.noise_iter)
    new = {c.term: c for c in retested}
    return pb, again, sig2, [new.get(c.term, c) for c in choices]


def research_anchors(pb: Problem, best: LMState, anchor: dict[str, float],
                     terms: Sequence[Term], recs: list[Record]) -> list[np.ndarray]:
    """Starts of the search again: the prior's point with each start of the terms added
    after the search (:meth:`Term.start_grid`). The lag the test fitted is not among
    them: it comes from linear parameters that absorbed the lag, and a search from it
    can stay in that part of the lag's curved valley (docs/validation/real-drives.md)."""
    added = [t for t in terms if t.mode == "auto" and not t.searched
             and all(n in pb.names for n in t.params)]
    grids = [t.start_grid(recs) for t in added] or [[{}]]
    out = []
    for combo in itertools.product(*grids):
        start = {n: v for d in combo for n, v in d.items()}
        out.append(np.array([anchor[n] if n in anchor
                             else pb.z_of([n], [start[n]])[0] if n in start
                             else best.z[pb.names.index(n)] for n in pb.free]))
    return out


def quantisation_errors(unc: Uncertain, rows: Residual) -> np.ndarray:
    """Draws of the error of ``theta`` in rad over the encoders' offsets (a fit to
    encoder angles: :mod:`._quantised`)."""
    z = unc.best.z
    return math.exp(z[0]) * np.expm1(log_theta_draws(rows, unc.jz, unc.cov_z, z))


def quantised_choices(choices: Sequence[TermChoice], errors: np.ndarray
                      ) -> list[TermChoice]:
    """The choices with the other model's interval (Fisher, white noise) made from the
    same quantisation ``errors`` about that model's ``theta`` (its midpoint)."""
    return [c if c.other_ci95 is None else
            replace(c, other_ci95=quantisation_interval(0.5 * sum(c.other_ci95), errors).ci95)
            for c in choices]


def widen_box(pb: Problem, box: tuple[np.ndarray, np.ndarray] | None
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """The first window's box, :data:`EXTRA_BOX` wider for the added terms."""
    if box is None:
        return None
    extra = [i for i, n in enumerate(pb.names) if n != "theta" and n not in LINEAR_PARAMS]
    lo, hi = box[0].copy(), box[1].copy()
    lo[extra] -= EXTRA_BOX
    hi[extra] += EXTRA_BOX
    return lo, hi
