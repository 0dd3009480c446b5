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
    # a loop's lag is not a drive parameter: a known loop's is the prior's
    prior = getattr(est.prior, name, None) or getattr(est.actuator, name, None)
    if not prior:
        return "not in the prior"
    return f"x{est.params_[name] / prior:.3g} the prior"


#: Columns of the per-file table: key, heading, width, format.
COLUMNS = (("t_s", "t_s (s)", 10, ".4f"), ("t_c", "t_c (s)", 10, ".4f"),
           ("t_b", "t_b (s)", 10, ".4f"), ("theta_ini", "theta_ini (rad)", 16, ".5g"))


def _record_table(per_record: list[dict[str, Any]]) -> list[str]:
    """The per-file table's lines, with the columns that hold a value for some file (the
    regression has no t_c, t_b; the joint method's one theta_ini, for all files
    together, is printed under the table). A "-" is a file without that value (the
    joint model's shaft leaves its flank after no step-down)."""
    shown = [c for c in COLUMNS if any(row[c[0]] is not None for row in per_record)]
    cells = [[format(row[k], f) if row[k] is not None else "-" for k, _, _, f in shown]
             for row in per_record]
    # a column as wide as its widest cell (a record's Unix time stamps: 1.7e9 s)
    widths = [max(w, *(len(c[j]) for c in cells)) for j, (_, _, w, _) in enumerate(shown)]
    lines = [" ".join([f"{'file':<30}", *(f"{head:>{w}}" for (_, head, _, _), w
                                          in zip(shown, widths, strict=True))])]
    for row, texts in zip(per_record, cells, strict=True):
        lines.append(" ".join([f"{row['file'][-30:]:<30}",
                               *(f"{x:>{w}}" for x, w in zip(texts, widths, strict=True))]))
    return lines


def _model_line(est) -> str:
    """The joint fit's model in one line: its friction and current loop, each fitted
    or held (the ``model:`` lines after the parameters say why)."""
    fitted = set(est.estimated_)
    friction = "viscous friction"
    if est.friction_ == "coulomb":
        how = "fitted" if fitted & {"fc_M", "fc_L"} else "held at the prior's"
        friction += f" and Coulomb torques ({how})"
    if "tau_i" in fitted:
        loop = "a current loop (its lag fitted)"
    elif est.tau_i_ > 0:
        loop = f"a current loop (its lag held at {est.tau_i_:.3g} s)"
    else:
        loop = "no current loop (torque applied as recorded)"
    return f"model     = two-mass drive with backlash, {friction}, {loop}"


def _friction_line(extra: dict[str, Any]) -> str:
    """Paper A's methods' friction model: viscous, or its fitted Coulomb torques."""
    if extra["friction"] != "coulomb":
        return "friction  = viscous (no Coulomb torques)"
    return (f"friction  = coulomb: fc_M = {extra['fc_M']:.4g} N m, fc_L = "
            f"{extra['fc_L']:.4g} N m (no standard errors for this method)")


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
    for line in _record_table(out["per_record"]):
        print(line)
    if theta_ini is not None:
        # the joint method only starts from it: without a word it reads as a second answer
        start = ("; the area pre-estimate, one start of the search" if args.method == "joint"
                 else "")
        print(f"theta_ini = {theta_ini:.5g} rad ({math.degrees(theta_ini):.4g} deg{start})")
    if std is None:
        print(f"theta     = {est.theta_:.5g} rad ({math.degrees(est.theta_):.4g} deg), "
              f"searched in [{bounds[0]:.4g}, {bounds[1]:.4g}] rad; no uncertainty for this "
              "method")
        print(_friction_line(out["extra"]))
        for note in notes:
            print(f"note: {note}")
        return
    how = {"fisher": " (Fisher)", "profile": " (profile likelihood)",
           "quantisation": " (spread over the encoders' offsets)"}.get(est.interval_, "")
    if est.interval_ == "bootstrap":
        how = f" (parametric bootstrap, {est.bootstrap_thetas_.size} refits)"
    if est.search.final_horizon is not None:
        how += f" (fitted on {est.search.final_horizon:g} s after each torque jump)"
    print(f"theta     = {est.theta_:.5g} rad ({math.degrees(est.theta_):.4g} deg), "
          f"std {std:.3g} rad, 95% interval [{ci95[0]:.5g}, {ci95[1]:.5g}] rad{how}")
    for note in notes:
        print(f"note: {note}")
    print(_model_line(est))
    for name in est.estimated_[1:]:
        print(f"{name:<9} = {est.params_[name]:.5g} {UNITS[name]} (std "
              f"{est.param_std_[name]:.3g}; {_to_prior(est, name)})")
    for choice in est.choices_:
        print(f"model: {choice.reason()}")
    for rec, (a, b), (sm, sl), what in zip(everything, est.fit_percent_, est.noise_std_,
                                            est.measured_, strict=True):
        angles = what == "angles"
        unit = "rad (of the encoder angles fitted)" if angles else "rad/s"
        # speeds recognised as an encoder's differenced counts are fitted as its angles
        counts = "; its speeds are differenced encoder counts" if (
            angles and not rec.has_positions) else ""
        channels = "phi_M, phi_L" if angles else "w_M, w_L"
        print(f"{rec.name[-30:]:<30} fit % ({channels}) = ({a:.1f}, {b:.1f}); noise std = "
              f"({sm:.3g}, {sl:.3g}) {unit}{counts}")
