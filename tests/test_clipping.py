"""Clipped (saturated) speeds are refused by every identifier, with a one-line reason.

Issue 3: "a record on which the method cannot work (no contact change found, saturated
signals) is reported as such, never answered with a number". The detector must not
fire on what the project's own records look like: noise-free simulations (which can
settle onto their fixed point to the last bit), records at rest (exact zeros), held
starts, and quantised encoder speeds.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import backlashkit as bk
from backlashkit import signals
from backlashkit.cli import main
from backlashkit.errors import InputError, SensitivityWarning
from backlashkit.identify import Record, RegressionIdentifier, TwoStepIdentifier
from backlashkit.identify.clipping import find_clipping
from backlashkit.identify.joint import JointIdentifier
from backlashkit.io import write_csv

P_TRUE = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
PRIOR = bk.TwoMassDrive(**P_TRUE)
#: three load inertias (J_L / J_M about 2, 14 and 51), as benchmarks/robustness_joint.py
DRIVES = [bk.TwoMassDrive(**{**P_TRUE, "J_L": j_l}, theta=np.deg2rad(deg))
          for j_l, deg in ((1e-2, 0.5), (6.8e-2, 2.0), (0.25, 5.0))]
RPM = 2 * np.pi / 60


@pytest.fixture(scope="module")
def responses():
    t = signals.time_grid(80.0, 1e-3)
    with warnings.catch_warnings():  # grazing contacts of the light load: irrelevant here
        warnings.simplefilter("ignore", SensitivityWarning)
        return [d.simulate(t, signals.step_down(t, a, t_s=40.0))
                for d in DRIVES for a in (0.157, 0.942)]


def _noisy(y, snr, seed):
    return signals.add_noise(y, snr, rng=seed)


def test_unclipped_channels_are_not_flagged(responses):
    for k, r in enumerate(responses):
        for y in (r.w_motor, r.w_load):
            assert find_clipping(y) is None  # noise-free, to the last bit
            assert find_clipping(_noisy(y, 20.0, k)) is None
            assert find_clipping(np.round(y / RPM) * RPM) is None  # 1 rpm encoder, no noise
            noisy_q = np.round(_noisy(y, 40.0, k) / (0.1 * RPM)) * (0.1 * RPM)
            assert find_clipping(noisy_q) is None


def test_rest_and_held_start_are_not_clipping():
    y = np.r_[np.zeros(500), np.linspace(0, 3, 500), 3 - np.linspace(0, 3, 500),
              np.zeros(500)]
    assert find_clipping(y) is None  # exact zeros at rest
    held = np.r_[np.full(1000, 7.0), 7.0 - np.linspace(0, 1, 1000) ** 2]
    assert find_clipping(held) is None  # a record that starts at a held speed


@pytest.mark.parametrize("quantum", [0.0, 0.1 * RPM])
def test_clipped_channels_are_flagged(responses, quantum):
    for k, r in enumerate(responses):
        y = _noisy(r.w_motor, 30.0, k)
        if quantum:
            y = np.round(y / quantum) * quantum
        top = np.quantile(y, 0.97)
        clip = find_clipping(np.minimum(y, top))
        assert clip is not None and clip.side == "maximum" and clip.value == top
        assert clip.count >= 0.03 * y.size - 1
        low = np.quantile(y, 0.02)
        clip = find_clipping(np.maximum(y, low))
        assert clip is not None and clip.side == "minimum"


def test_heavy_clipping_is_flagged(responses):
    """With half the samples or more at the limit, the second differences are mostly
    0: the noise is measured off the plateau, so the worst clipping is still found."""
    y = _noisy(responses[2].w_motor, 35.0, 3)
    for frac in (0.5, 0.7, 0.9):
        top = np.quantile(y, 1.0 - frac)
        clip = find_clipping(np.minimum(y, top))
        assert clip is not None and clip.value == top and clip.count >= frac * y.size - 1


#: the message quoted in the README ("Bad input")
README_MESSAGE = ("exp1.csv: w_load is clipped: 17587 samples between t = 20.192 s and "
                  "40.375 s (runs of up to 13060) sit exactly at its maximum 15 rad/s, ")


def _clipped_record(responses, name):
    r = responses[2]  # paper A's drive, first step
    w_m = _noisy(r.w_motor, 40.0, 1)
    w_l = np.minimum(_noisy(r.w_load, 40.0, 2), 15.0)  # a load sensor limited to 15 rad/s
    return Record(r.t, r.torque, w_m, w_l, name=name)


@pytest.mark.parametrize("method", [TwoStepIdentifier, RegressionIdentifier, JointIdentifier])
def test_identifiers_refuse_a_clipped_record(responses, method):
    rec = _clipped_record(responses, "exp1.csv")
    with pytest.raises(InputError, match=r"^exp1\.csv: w_load is clipped: \d+ samples between "
                       r"t = [\d.]+ s and [\d.]+ s .* at its maximum 15 rad/s"):
        method(PRIOR).fit(rec)


def test_readme_message(responses):
    with pytest.raises(InputError) as info:
        TwoStepIdentifier(PRIOR).fit(_clipped_record(responses, "exp1.csv"))
    assert str(info.value).startswith(README_MESSAGE)


def test_cli_reports_a_clipped_file(responses, tmp_path, capsys):
    rec = _clipped_record(responses, "x")
    path = tmp_path / "clipped.csv"
    write_csv(path, {"t": rec.t, "torque": rec.torque, "w_motor": rec.w_motor,
                     "w_load": rec.w_load})
    drive = tmp_path / "drive.toml"
    drive.write_text("[drive]\n" + "".join(f"{k} = {v!r}\n" for k, v in P_TRUE.items()))
    code = main(["identify", str(path), "--drive", str(drive), "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith(f"backlashkit: error: {path}: w_load is clipped")
    assert "sensor" in line
