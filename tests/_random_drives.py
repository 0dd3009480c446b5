"""Random drives of the sensitivity tests, drawn by hypothesis: each parameter of paper
A's drive (and its backlash) within a factor 2 of its value, stepped down to 0 at 1 s
from a random torque level held from rest, 2 s at 1 ms."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

import backlashkit as bk
from backlashkit.papers.ravanbod2002 import P_TRUE, THETA

#: Log-factors of the seven parameters (order of ``P_TRUE`` then ``theta``): e^0.7 ~ 2.
LOG_FACTORS = st.lists(st.floats(-0.7, 0.7), min_size=len(P_TRUE) + 1,
                       max_size=len(P_TRUE) + 1)
#: Held torque level in N m (paper A's two levels are 0.157 and 0.942).
LEVELS = st.floats(0.2, 1.0)


def drive_record(logs, level):
    """``(drive, t, u)`` of one draw."""
    values = {n: x * np.exp(g) for (n, x), g in
              zip({**P_TRUE, "theta": THETA}.items(), logs, strict=True)}
    t = bk.signals.time_grid(2.0, 1e-3)
    return bk.TwoMassDrive(**values), t, bk.signals.step_down(t, level, t_s=1.0)
