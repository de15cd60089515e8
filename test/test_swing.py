"""The swing scene against the exact heavy chain (fidelity.swing, `cloth-mg run --scene swing`)."""

from __future__ import annotations

import cmath
import json
import math

import numpy as np
import pytest

from cloth_mg_ros.cli.main import main
from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.fidelity.swing import (
    SwingSpec,
    chain_frequency,
    chain_mode,
    chain_mode_slope,
    run_swing,
)
from cloth_mg_ros.physics.materials import get_material
from cloth_mg_ros.sim.schemes import SCHEMES

SMALL = 120  # particles: the swing is one-dimensional (150 and 800 agree to 0.02 %)


def test_chain_frequencies_are_the_known_numbers():
    # j0_1 = 2.404826, j0_2 = 5.520078 (Abramowitz and Stegun, table 9.5)
    assert chain_frequency(0.5) == pytest.approx(2.404826 / (4 * math.pi) * math.sqrt(9.81 / 0.5),
                                                 rel=1e-6)
    assert chain_frequency(0.5) == pytest.approx(0.8477, abs=5e-5)
    assert chain_frequency(2.0) == pytest.approx(0.8477 / 2.0, abs=5e-5)
    assert chain_frequency(0.5, 2) / chain_frequency(0.5) == pytest.approx(5.520078 / 2.404826,
                                                                         rel=1e-6)
    # the mode is 1 at the free end and 0 at the clamp; its slope the derivative's
    s = np.array([0.0, 0.5])
    assert chain_mode(s, 0.5) == pytest.approx([1.0, 0.0], abs=1e-6)
    grid = np.linspace(0.01, 0.49, 7)
    numeric = (chain_mode(grid + 1e-6, 0.5) - chain_mode(grid - 1e-6, 0.5)) / 2e-6
    assert chain_mode_slope(grid, 0.5) == pytest.approx(numeric, rel=1e-5)
    with pytest.raises(ClothInputError, match="length must be a positive"):
        chain_frequency(-1.0)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_first_mode_within_two_percent_of_the_chain(scheme):
    # a length the defaults do not use, at the node's step
    block, scene, _ = run_swing(SwingSpec(length=0.37, scheme=scheme, dt=1.0 / 60.0,
                                          particles=SMALL), fabric_split=False)
    assert scene.settle.settled
    assert block["exact_frequency_hz"] == pytest.approx(chain_frequency(0.37))
    assert abs(block["frequency_hz"] / block["exact_frequency_hz"] - 1.0) < 0.02
    # one decaying mode: the damped cosine fits the record to a small share of its size
    assert block["fit_rms_rel"] < 0.01
    assert 0.0 < block["energy_left"] < 1.0
    assert block["hanging_length_m"] == pytest.approx(0.37, rel=1e-3)


def _euler_damping_ratio(omega_h: float) -> float:
    """Implicit Euler's damping ratio on an undamped oscillator at omega h: its step
    multiplies by lambda = 1 / (1 - i omega h), and lambda = exp(s h) gives
    zeta = -Re s / |s| (omega h / 2 to leading order)."""
    s = cmath.log(1.0 / (1.0 - 1j * omega_h))
    return -s.real / abs(s)


def test_implicit_euler_damps_by_omega_h_over_two_and_the_fabric_by_beta_omega_over_two():
    dt = 1.0 / 60.0
    block, scene, _ = run_swing(SwingSpec(scheme="euler", dt=dt, particles=SMALL))
    omega = 2.0 * math.pi * block["exact_frequency_hz"]
    expected = _euler_damping_ratio(omega * dt)
    assert expected == pytest.approx(omega * dt / 2.0, rel=0.01)
    # Tolerance 5 %: besides Euler's own 0.0443, the one linearised step per step damps the
    # swing by 1.2e-3 at this amplitude and step (BDF2's measured ratio, 2.8 % of Euler's;
    # BDF2's own is 1.7e-4) and the model's first mode is 0.3 % off the chain's (the
    # frequency tests)
    assert block["damping_ratio_fabric_off"] == pytest.approx(expected, rel=0.05)
    # stiffness-proportional damping D = -beta H acts on the chain's tension stiffness, whose
    # swing mode has H phi = omega^2 M phi: beta omega / 2 (measured +1 %; 10 % allows for
    # the strip's bending and stretch, which H also holds)
    beta = get_material(scene.spec.material).damping
    assert block["fabric_damping_s"] == beta
    assert block["fabric_damping_ratio"] == pytest.approx(beta * omega / 2.0, rel=0.10)
    assert block["damping_ratio"] > block["damping_ratio_fabric_off"]


@pytest.mark.parametrize("change, message", [
    ({"length": -0.5}, "--length must be a positive"),
    ({"width": 0.0}, "--width must be a positive"),
    ({"amplitude": 0.2}, "--amplitude 0.2 m is not a small displacement"),
    ({"scheme": "rk4"}, "--scheme must be one of"),
    ({"dt": 0.5}, "--dt 0.5 s is more than a quarter"),
    ({"duration": 1.0}, "--duration 1 s is under 2 periods"),
    ({"particles": 3}, "--particles must be an integer"),
    ({"spectral_radius": 1.5}, "--spectral-radius must be in"),
    ({"material": "tweed"}, "unknown material 'tweed'"),
])
def test_bad_swing_options_are_named(change, message):
    with pytest.raises(ClothInputError, match=message):
        SwingSpec(**change)


def test_swing_command_writes_its_block(tmp_path, capsys):
    out = tmp_path / "swing"
    assert main(["run", "--scene", "swing", "--length", "0.3", "--scheme", "bdf2", "--dt",
                 str(1.0 / 30.0), "--particles", str(SMALL), "--out", str(out)]) == 0
    block = json.loads((out / "summary.json").read_text())["swing"]
    for key in ("length_m", "scheme", "dt_s", "frequency_hz", "exact_frequency_hz",
                "damping_ratio", "energy_left", "damping_ratio_fabric_off"):
        assert key in block
    assert block["length_m"] == 0.3 and block["scheme"] == "bdf2"
    assert abs(block["frequency_hz"] / block["exact_frequency_hz"] - 1.0) < 0.02
    assert (out / "frames.png").stat().st_size > 0
    assert "exact chain" in capsys.readouterr().out
    assert main(["run", "--scene", "swing", "--overhang", "0.1", "--out", str(out)]) == 2
    assert "--overhang is not an option of the swing scene" in capsys.readouterr().err
    assert main(["run", "--scene", "swing", "--length", "0", "--out", str(out)]) == 2
    assert "--length must be a positive" in capsys.readouterr().err
