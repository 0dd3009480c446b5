"""Sample-by-sample adaptive backlash-inverse controller, as it runs in a drive.

:class:`DiscreteAdaptiveController` implements paper B's controller at a sample time
``ts``: at each call ``v = ctrl.step(y, r)`` it

1. forms ``u_d = theta_1' omega_1 + theta_2' omega_2 + theta_3 r`` (3.2) from its
   filter states and ``du_d/dt`` from the same states, the measured ``y`` and
   ``dr/dt`` (given, or a backward difference of ``r``);
2. chooses the side of the inverse from the sign of ``du_d/dt`` (held at 0) and
   returns ``v`` from the adaptive inverse (2.7) or an approximation (2.8);
3. advances the adaptive law (3.11) by one forward-Euler step (with projection and
   switching sigma-modification) and all its linear filters (``a(s)/Lambda(s)``,
   ``1/R_m(s)``, four copies of ``H(s)``) by their exact zero-order-hold
   discretisation, with the inputs of this sample held over the sample.

``v`` is meant to be held by the drive until the next call. The cost per call is a few
small matrix-vector products (no allocation in the hot path beyond NumPy temporaries).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from ..lti import as_state_space, zoh_discretize
from ..nonlinearities import (
    Backlash,
    ExactInverse,
    InverseKind,
    InverseMemory,
    inverse_kind_error,
)
from .adaptive import AdaptiveLaw, adaptive_rate
from .design import MRCDesign, companion, design_mrc
from .problem import RUNAWAY, check_rows
from .response import ClosedLoopResponse

__all__ = ["DiscreteAdaptiveController", "simulate_discrete_loop"]


class DiscreteAdaptiveController:
    """Paper B's adaptive backlash-inverse controller running at a fixed sample time.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        Known linear part ``G(s)`` (A1-A2 must hold, see :func:`design_mrc`).
    ts : float
        Sample time in s (``> 0``).
    inverse : InverseKind, optional
        Default :class:`ExactInverse`.
    adaptation : AdaptiveLaw, optional
        Gains, initial estimate, ``m0``, sigma-modification (default paper B's).
    reference_model, filter : array_like, optional
        ``R_m(s)`` and ``Lambda(s)`` (see :func:`design_mrc`).
    design : MRCDesign, optional
        A precomputed design (then ``plant``, ``reference_model``, ``filter`` are only
        used if it is None).

    Examples
    --------
    >>> ctrl = DiscreteAdaptiveController(([1.0], [1.0, -0.5, -1.5]), ts=1e-3)
    >>> v = ctrl.step(0.0, 0.0)
    """

    def __init__(
        self,
        plant: Any,
        *,
        ts: float,
        inverse: InverseKind | None = None,
        adaptation: AdaptiveLaw | None = None,
        reference_model: Any = None,
        filter: Any = None,  # noqa: A002 - the paper's name
        design: MRCDesign | None = None,
    ) -> None:
        self.ts = v.positive("ts", ts)
        self.inverse = ExactInverse() if inverse is None else inverse
        if not isinstance(self.inverse, InverseKind):
            raise inverse_kind_error(self.inverse)
        self.adaptation = AdaptiveLaw() if adaptation is None else adaptation
        if not isinstance(self.adaptation, AdaptiveLaw):
            raise InputError(f"adaptation must be an AdaptiveLaw, got "
                             f"{type(self.adaptation).__name__}")
        if design is not None and not isinstance(design, MRCDesign):
            raise InputError(f"design must be an MRCDesign (from design_mrc), got "
                             f"{type(design).__name__}")
        self.design = (
            design
            if design is not None
            else design_mrc(plant, reference_model=reference_model, filter=filter)
        )
        d = self.design
        al, bl, _ = companion(np.array([1.0]), d.filter)
        self._al, self._bl = al, bl
        self._ald, self._bld = zoh_discretize(al, bl, self.ts)
        am, bm, self._cm = companion(np.array([1.0]), d.reference_model)
        self._amd, self._bmd = zoh_discretize(am, bm, self.ts)
        ah, bh, self._ch = companion(d.h_num, d.h_den)
        self._ahd, self._bhd = zoh_discretize(ah, bh, self.ts)
        adapted = np.array(self.inverse.adapted)
        self._gamma = self.adaptation.gamma_diag * adapted
        self._th0 = np.where(adapted > 0, self.adaptation.theta_b0_array, 0.0)
        self.reset()

    def __repr__(self) -> str:
        th = ", ".join(f"{x:.4g}" for x in self.theta_b)
        return (f"DiscreteAdaptiveController(ts={self.ts:g}, inverse={self.inverse!r}, "
                f"theta_b=[{th}])")

    def reset(self) -> None:
        """Return to the initial state (filters at rest, ``theta_b = theta_b0``)."""
        n, q, nh = self._al.shape[0], self._amd.shape[0], self._ahd.shape[0]
        self._x1 = np.zeros(n)
        self._x2 = np.zeros(n)
        self._xm = np.zeros(q)
        self._z = np.zeros((nh, 4))
        self.theta_b = self._th0.copy()
        self._memory: InverseMemory | None = None  # set by the first sample's u_d slope
        self._r_prev: float | None = None
        self.u_d = 0.0
        self.y_m = 0.0

    @property
    def y_m_next(self) -> float:
        """Reference-model output at the next sample (the current one is :attr:`y_m`)."""
        return float(self._cm @ self._xm)

    def step(self, y: float, r: float, r_dot: float | None = None) -> float:
        """Advance one sample: read ``y`` and ``r``, return ``v`` to hold until the next call.

        Parameters
        ----------
        y : float
            Measured plant output at this sample.
        r : float
            Reference at this sample.
        r_dot : float, optional
            ``dr/dt`` at this sample; when omitted a backward difference of ``r``
            (zero at the first call) is used.

        Returns
        -------
        float
            Backlash input ``v`` for this sample.

        Raises
        ------
        InputError
            If ``y``, ``r`` or ``r_dot`` is not a finite real number (a NaN read once
            would carry into every later sample through the adaptive law); the
            controller's state is left as it was.
        """
        p = self.design
        y = v.finite_scalar("y", y)
        r = v.finite_scalar("r", r)
        if r_dot is not None:
            r_dot = v.finite_scalar("r_dot", r_dot)
        if r_dot is None:
            r_dot = 0.0 if self._r_prev is None else (r - self._r_prev) / self.ts
        self._r_prev = r
        x1, x2 = self._x1, self._x2
        ud = float(p.theta_1 @ x1 + p.theta_2 @ x2 + p.theta_3 * r)
        udd = float(
            p.theta_1 @ (self._al @ x1 + self._bl * ud)
            + p.theta_2 @ (self._al @ x2 + self._bl * y)
            + p.theta_3 * r_dot
        )
        mem = self._memory
        if mem is None:
            mem = self._memory = InverseMemory(rising=udd >= 0, locked_right=udd >= 0)
        elif (mem.rising and udd < 0) or (not mem.rising and udd > 0):
            mem.rising = not mem.rising
        th = self.theta_b
        inv = self.inverse
        out = inv.sample(ud, udd, th, mem, self.ts)
        # adaptive law (3.11), forward Euler
        y_m = float(self._cm @ self._xm)
        chi = float(mem.rising)
        wb = np.array([chi, -out, 1.0 - chi])
        zeta_all = self._ch @ self._z
        if inv.adapts:
            rate = adaptive_rate(
                self.adaptation, th, zeta_all[:3], float(zeta_all[3]), y - y_m, gamma=self._gamma
            )
            th = th + self.ts * rate
            th[1] = max(th[1], self.adaptation.m0)
            th[0] = max(th[0], 0.0)
            th[2] = min(th[2], 0.0)
        tw = float(self.theta_b @ wb)
        self._z = self._ahd @ self._z + np.outer(self._bhd, np.append(wb, tw))
        self._x1 = self._ald @ x1 + self._bld * ud
        self._x2 = self._ald @ x2 + self._bld * y
        self._xm = self._amd @ self._xm + self._bmd * r
        self.theta_b = th
        self.u_d = ud
        self.y_m = y_m
        return float(out)


def simulate_discrete_loop(
    plant: Any,
    backlash: Backlash,
    controller: DiscreteAdaptiveController,
    *,
    reference: Any,
    duration: float,
    use_r_dot: bool = True,
) -> ClosedLoopResponse:
    """Run a sampled loop: exact ZOH plant with input backlash + the discrete controller.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        The linear part (as for :func:`simulate_closed_loop`).
    backlash : Backlash
        The true backlash.
    controller : DiscreteAdaptiveController
        The controller (it is reset first); its ``ts`` is the loop's sample time.
    reference : SumOfSines or TableReference
        Reference ``r(t)``.
    duration : float
        Length of the run in s.
    use_r_dot : bool
        Pass the exact ``dr/dt`` to the controller (default) or let it difference ``r``.

    Returns
    -------
    ClosedLoopResponse
        One row per sample.

    Raises
    ------
    InputError
        If an argument is not of its kind, the plant has a direct feedthrough, or the
        loop diverges (a non-finite value, or an output beyond :data:`RUNAWAY` times
        the reference's largest value).
    """
    use_r_dot = v.flag("use_r_dot", use_r_dot)
    if not isinstance(controller, DiscreteAdaptiveController):
        raise InputError(f"controller must be a DiscreteAdaptiveController, got "
                         f"{type(controller).__name__}")
    if not isinstance(backlash, Backlash):
        raise InputError(f"backlash must be a Backlash, got {type(backlash).__name__}")
    if not callable(getattr(reference, "derivative", None)):  # dr/dt is passed on
        raise InputError(f"reference must be a SumOfSines or a TableReference, got "
                         f"{type(reference).__name__}")
    controller.reset()
    ts = controller.ts
    n = _n_samples(duration, ts)
    check_covers = getattr(reference, "check_covers", None)  # a user's own reference: none
    if check_covers is not None:
        check_covers(duration)
    a, b, c, dd = as_state_space(plant)
    if dd != 0.0:
        raise InputError("plant must be strictly proper (no direct feedthrough)")
    ad, bd = zoh_discretize(a, b, ts)
    t = np.arange(n) * ts
    r = reference(t)
    rd = reference.derivative(t)
    out = {k: np.empty(n) for k in ("y", "ym", "ud", "v", "u")}
    thb = np.empty((n, 3))
    x = np.zeros(a.shape[0])
    u = 0.0
    m, c_r, c_l = backlash.m, backlash.c_r, backlash.c_l
    # the loop starts at rest, so a plant output this far beyond the reference is a
    # runaway however the adaptive law's transient goes (refused where it appears)
    runaway = RUNAWAY * float(np.max(np.abs(r), initial=0.0))
    # an overflow ends in a non-finite output or input, refused where it appears
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(n):
            y = float(c @ x)
            if math.isfinite(y):
                thb[k] = controller.theta_b
                vk = controller.step(y, r[k], rd[k] if use_r_dot else None)
            if not (math.isfinite(y) and math.isfinite(vk)) or abs(y) > runaway:
                which = "controller output v" if math.isfinite(y) else "plant output y"
                what = (f"the plant output reached {y:.3g}, over {RUNAWAY:g} times the "
                        "reference's largest value" if math.isfinite(y) and math.isfinite(vk)
                        else f"non-finite {which}")
                raise InputError(
                    f"the simulation diverged ({what}) at t = {t[k]:.6g} s; the "
                    f"controller's sample time ts = {ts:g} s may be too long for the plant, "
                    "or check the parameters' units and magnitudes")
            u = min(max(u, m * (vk - c_r)), m * (vk - c_l))
            out["y"][k], out["ym"][k], out["ud"][k] = y, controller.y_m, controller.u_d
            out["v"][k], out["u"][k] = vk, u
            x = ad @ x + bd * u
    return ClosedLoopResponse(
        t=t,
        r=r,
        y=out["y"],
        y_m=out["ym"],
        e=out["y"] - out["ym"],
        u_d=out["ud"],
        v=out["v"],
        u=out["u"],
        theta_b=thb,
        design=controller.design,
        inverse=controller.inverse,
        step=ts,
    )


def _n_samples(duration: float, ts: float) -> int:
    """Samples of a run of ``duration`` s at ``ts`` s, both ends included."""
    duration = v.positive("duration", duration)
    if ts > duration:
        raise InputError(f"duration must be >= the controller's ts = {ts!r} s, got "
                         f"{duration!r}")
    return check_rows(duration, ts) + 1
