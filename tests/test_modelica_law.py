"""Modelica's ElastoBacklash law (``law="modelica"``) against Modelica's own reference.

The Modelica Standard Library's example ``Modelica.Mechanics.Rotational.Examples.
Backlash`` (an inertia ``J = 5 kg m^2`` on a fixed flange through ``ElastoBacklash(c =
20e3 N m/rad, d = 50 N m s/rad, b = pi/4)``, released at a relative angle of ``pi/2``)
has published Dymola reference trajectories in ``../shared/peers/modelica-backlash/``
(read there, never copied). We simulate it as a two-mass drive whose load is so heavy
(``J_L = 1e12``) that it stays still to ~1e-9 rad/s, with ``theta = b/2 = pi/8``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import backlashkit as bk

PEERS = Path(__file__).resolve().parents[1].parent / "shared" / "peers" / "modelica-backlash"
TRACES = ["Backlash_v4.1.0.csv", "Backlash_v3.2.3.csv"]
#: The issue's bars: Modelica's own regression tube is 2e-3; an independent scipy
#: re-simulation of the law meets both traces within 2.1e-5 rad and 1.3e-3 rad/s.
ANGLE_TOL, SPEED_TOL = 1e-4, 5e-3
TS = 5e-4  # the traces' output interval

EXAMPLE = bk.TwoMassDrive(
    J_M=5.0, J_L=1e12, k_sh=20e3, f_M=0.0, f_L=0.0, f_sh=50.0, theta=math.pi / 8
)
X0 = [0.0, 0.0, math.pi / 2]


def read_trace(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, phi_rel and w_rel of the backlash element on the 5e-4 s grid (the rows
    duplicated at state events are dropped: they lie off the grid)."""
    if not PEERS.is_dir():
        pytest.skip(f"peer traces not found at {PEERS} (../shared/peers is absent)")
    data = np.genfromtxt(PEERS / name, delimiter=",", names=True)
    t = data["time"]
    on_grid = np.abs(t / TS - np.round(t / TS)) < 1e-6
    _, first = np.unique(np.round(t[on_grid] / TS), return_index=True)
    rows = np.flatnonzero(on_grid)[first]
    return t[rows], data["elastoBacklashphi_rel"][rows], data["elastoBacklashw_rel"][rows]


def simulate(law: str, t: np.ndarray, backend: str = "rust"):
    return bk.simulate_drive(
        EXAMPLE, t, np.zeros(t.size), law=law, initial_state=X0, backend=backend
    )


@pytest.mark.parametrize("name", TRACES)
def test_modelica_example_matches_dymola(name):
    t, phi_ref, w_ref = read_trace(name)
    assert t.size == 2001 and t[-1] == pytest.approx(1.0)
    resp = simulate("modelica", t)
    dphi = np.abs(resp.phi_d - phi_ref).max()
    dw = np.abs(resp.w_motor - w_ref).max()
    print(f"\n{name}: max |phi - phi_ref| = {dphi:.2e} rad, max |w - w_ref| = {dw:.2e} rad/s, "
          f"{len(resp.events)} contact changes")
    assert dphi <= ANGLE_TOL and dw <= SPEED_TOL
    # the load stays put, as the fixed flange of the example
    assert np.abs(resp.w_load).max() < 1e-6


def test_no_pull_is_not_modelicas_elastobacklash():
    # The finding: the no-pull law (ElastoBacklash2) ends 0.26 rad from the
    # trace and strays 12.5 rad/s from it, so the comparison above tells the laws apart.
    t, phi_ref, w_ref = read_trace(TRACES[0])
    resp = simulate("no-pull", t)
    assert abs(resp.phi_d[-1] - phi_ref[-1]) > 0.2
    assert np.abs(resp.w_motor - w_ref).max() > 10.0


def test_torque_follows_the_law():
    # On the positive flank: tau_c + min(tau_c, tau_d), 0 when tau_c + tau_d <= 0.
    t = np.arange(2001) * TS
    resp = simulate("modelica", t)
    phi, w = resp.phi_d, resp.w_motor - resp.w_load
    th, k, d = EXAMPLE.theta, EXAMPLE.k_sh, EXAMPLE.f_sh
    side = resp.modes[:, 0]
    tc = k * (phi - side * th)
    td = d * w
    pos = side == 1
    expect_pos = np.where(tc + td <= 0, 0.0, tc + np.minimum(tc, td))
    np.testing.assert_allclose(resp.shaft_torque[pos], expect_pos[pos], rtol=0, atol=1e-9)
    neg = side == -1
    expect_neg = np.where(tc + td >= 0, 0.0, tc + np.maximum(tc, td))
    np.testing.assert_allclose(resp.shaft_torque[neg], expect_neg[neg], rtol=0, atol=1e-9)
    assert pos.any() and neg.any()
    # the doubled-spring branch is visited (else the test would not check the min)
    assert np.any(pos & (td > tc)) and np.any(pos & (td < tc))


def test_numpy_twin_matches_kernel():
    t = np.arange(401) * TS
    a = simulate("modelica", t)
    b = simulate("modelica", t, backend="numpy")
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.modes, b.modes)
    np.testing.assert_allclose(a.event_array, b.event_array, rtol=0, atol=1e-12)
    chain = bk.DriveChain(J=[0.01, 0.03, 0.2], f=[0.01, 0.02, 0.05], k=[60.0, 150.0],
                          d=[0.8, 2.5], theta=[0.02, 0.01])
    t = np.arange(801) * 1e-3
    u = np.where((t // 0.1) % 2 == 0, 2.0, -2.0)
    a = bk.simulate_drive(chain, t, u, law="modelica")
    b = bk.simulate_drive(chain, t, u, law="modelica", backend="numpy")
    assert len(a.events) > 10
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.event_array, b.event_array, rtol=0, atol=1e-12)


def test_laws_agree_without_damping():
    drive = bk.TwoMassDrive(J_M=0.01, J_L=0.05, k_sh=100.0, f_M=0.01, f_L=0.02, f_sh=0.0,
                            theta=0.02)
    t = np.arange(2001) * 1e-3
    u = np.where(t < 1.0, 0.5, -0.2)
    ref = drive.simulate(t, u, law="paper")
    for law in ("no-pull", "modelica"):
        other = drive.simulate(t, u, law=law)
        np.testing.assert_allclose(other.states, ref.states, rtol=0, atol=1e-12)
