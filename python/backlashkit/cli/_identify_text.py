"""The text output of ``backlashkit identify``: the result as a reader sees it."""

from __future__ import annotations

import argparse
import math
from typing import Any

from ..identify.record import Record

__all__ = ["print_result"]


#: Units of the estimated parameters (SI).
UNITS = {"J_M": "kg m^2", "J_L": "kg m^2", "k_sh": "N m/rad", "f_M": "N m s/rad",
         "f_L": "N m s/rad", "f_sh": "N m s/rad", "fc_M": "N m", "fc_L": "N m", "tau_i": "s"}


def _to_prior(est: Any, name: str) -> str:
    """The ratio of an estimate to the prior's value, or that the prior has none."""
    prior = getattr(est.prior, name, None)
    if not prior:
        return "not in the prior"
    return f"x{est.params_[name] / prior:.3g} the prior"


def print_result(args: argparse.Namespace, est: Any, out: dict[str, Any], notes: list[str],
                  everything: list[Record]) -> None:
    """Print the result as text on stdout.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed arguments (``method``).
    est : object
        The fitted estimator.
    out : dict
        What the method's fit returned (``theta_ini``, ``std``, ``ci95``, ``bounds``,
        ``per_record``).
    notes : list of str
        The notes, printed after theta.
    everything : list of Record
        Every record fitted, in order.
    """
    theta_ini, std, ci95, bounds = out["theta_ini"], out.get("std"), out.get("ci95"), \
        out["bounds"]
    print(f"method {args.method}; theta is the backlash HALF-width")
    print(f"{'file':<30} {'t_s (s)':>10} {'t_c (s)':>10} {'t_b (s)':>10} {'theta_ini (rad)':>16}")
    for row in out["per_record"]:
        cells = [f"{row[k]:10.4f}" if row[k] is not None else f"{'-':>10}"
                 for k in ("t_s", "t_c", "t_b")]
        ini = f"{row['theta_ini']:16.5g}" if row["theta_ini"] is not None else f"{'-':>16}"
        print(f"{row['file'][-30:]:<30} {' '.join(cells)} {ini}")
    if theta_ini is not None:
        print(f"theta_ini = {theta_ini:.5g} rad ({math.degrees(theta_ini):.4g} deg)")
    if std is None:
        print(f"theta     = {est.theta_:.5g} rad ({math.degrees(est.theta_):.4g} deg), "
              f"searched in [{bounds[0]:.4g}, {bounds[1]:.4g}] rad; no uncertainty for this "
              "method")
        for note in notes:
            print(f"note: {note}")
        return
    how = {"fisher": " (Fisher)", "profile": " (profile likelihood)"}.get(est.interval_, "")
    if est.interval_ == "bootstrap":
        how = f" (parametric bootstrap, {est.bootstrap_thetas_.size} refits)"
    if est.search.final_horizon is not None:
        how += f" (fitted on {est.search.final_horizon:g} s after each torque jump)"
    print(f"theta     = {est.theta_:.5g} rad ({math.degrees(est.theta_):.4g} deg), "
          f"std {std:.3g} rad, 95% interval [{ci95[0]:.5g}, {ci95[1]:.5g}] rad{how}")
    for note in notes:
        print(f"note: {note}")
    for name in est.estimated_[1:]:
        print(f"{name:<9} = {est.params_[name]:.5g} {UNITS[name]} (std "
              f"{est.param_std_[name]:.3g}; {_to_prior(est, name)})")
    for choice in est.choices_:
        print(f"model: {choice.reason()}")
    for rec, (a, b), (sm, sl) in zip(everything, est.fit_percent_, est.noise_std_,
                                      strict=True):
        print(f"{rec.name[-30:]:<30} fit % (w_M, w_L) = ({a:.1f}, {b:.1f}); noise std = "
              f"({sm:.3g}, {sl:.3g}) rad/s")
