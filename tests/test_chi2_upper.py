"""The terms' likelihood-ratio thresholds without importing scipy.special (about 0.2 s
by ``python -X importtime``): the closed forms for one and two degrees of freedom
against scipy's chi-square."""

from __future__ import annotations

import subprocess
import sys

import pytest
from scipy.stats import chi2

from backlashkit.identify.terms import KEEP_LEVEL, actuator_term, chi2_upper, friction_term


@pytest.mark.parametrize("dof", [1, 2, 3, 5])
@pytest.mark.parametrize("alpha", [0.5, 0.05, 0.01, 1e-3])
def test_chi2_upper_is_scipys(dof, alpha):
    assert chi2_upper(dof, alpha) == pytest.approx(chi2.isf(alpha, dof), rel=1e-13)


def test_the_terms_thresholds_are_the_99_percent_points():
    """The loop's one parameter and the Coulomb torques' two: 6.63 and 9.21, as the
    command line prints them."""
    assert actuator_term("auto").threshold == pytest.approx(chi2.isf(1 - KEEP_LEVEL, 1),
                                                            rel=1e-14)
    assert friction_term("auto").threshold == pytest.approx(chi2.isf(1 - KEEP_LEVEL, 2),
                                                            rel=1e-14)
    assert f"{actuator_term('auto').threshold:.3g}" == "6.63"
    assert f"{friction_term('auto').threshold:.3g}" == "9.21"


def test_importing_backlashkit_leaves_scipy_out():
    """scipy costs its import where it is used (a fit's AR noise, the delay margins,
    the reference simulator), not on every command."""
    code = ("import sys, backlashkit, backlashkit.cli; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
