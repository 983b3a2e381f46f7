"""The kinematics hash of docs/protocols.md §2.6 against the worked example and the shipped model files."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import yaml

from urdaemon.paths import resource_path
from urdaemon.protocols.kinematics_hash import (
    kinematics_hash,
    kinematics_hash_text,
    libstdcxx_hash_bytes,
)

UR5E_THETA = [0.0] * 6
UR5E_A = [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0]
UR5E_D = [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996]
UR5E_ALPHA = [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0]

MODEL_FILES = sorted(p for p in resource_path("ur").glob("*.yaml"))


def _load(path: Path) -> dict[str, Any]:
    data = yaml.safe_load(path.read_text())
    assert isinstance(data, dict)
    return data


def test_ur5e_worked_example_text_matches_the_reference() -> None:
    text = kinematics_hash_text(UR5E_THETA, UR5E_A, UR5E_D, UR5E_ALPHA)
    assert text == "00.162501.570800-0.425000-0.3922000.133301.570800.09970-1.570800.099600"


def test_ur5e_worked_example_hash_matches_the_reference() -> None:
    assert kinematics_hash(UR5E_THETA, UR5E_A, UR5E_D, UR5E_ALPHA) == "calib_12788084448423163542"


def test_nine_model_files_are_shipped() -> None:
    assert [p.stem for p in MODEL_FILES] == [
        "ur10",
        "ur10e",
        "ur16e",
        "ur20",
        "ur3",
        "ur30",
        "ur3e",
        "ur5",
        "ur5e",
    ]


@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.stem)
def test_default_hash_of_every_model_file_is_reproduced(path: Path) -> None:
    model = _load(path)
    dh = model["dh"]
    assert kinematics_hash(dh["theta"], dh["a"], dh["d"], dh["alpha"]) == model["kinematics_hash"]


def test_numbers_are_printed_like_a_default_cxx_ostream() -> None:
    theta = [-0.0, 1e-05, 123456789.0, 0.000123456789, 2.5, -1.0]
    zeros = [0.0] * 6
    text = kinematics_hash_text(theta, zeros, zeros, zeros)
    # each joint: theta, then d, a, alpha as "0"
    assert text == "-0000" + "1e-05000" + "1.23457e+08000" + "0.000123457000" + "2.5000" + "-1000"


def test_parameters_are_interleaved_theta_d_a_alpha_per_joint() -> None:
    theta = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    a = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
    d = [0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625]
    alpha = [-1.0, -2.0, -3.0, -4.0, -5.0, -6.0]
    text = kinematics_hash_text(theta, a, d, alpha)
    assert text.startswith("10.510-1" + "20.2520-2")
    assert text.endswith("60.01562560-6")


@pytest.mark.parametrize("bad", ["theta", "a", "d", "alpha"])
def test_a_list_that_is_not_six_long_is_refused(bad: str) -> None:
    params = {"theta": [0.0] * 6, "a": [0.0] * 6, "d": [0.0] * 6, "alpha": [0.0] * 6}
    params[bad] = [0.0] * 5
    with pytest.raises(ValueError, match=bad):
        kinematics_hash(**params)


def test_hash_differs_when_any_digit_differs() -> None:
    d = list(UR5E_D)
    d[0] = 0.16251
    assert kinematics_hash(UR5E_THETA, UR5E_A, d, UR5E_ALPHA) != "calib_12788084448423163542"


@pytest.mark.parametrize("length", range(17))
def test_hash_bytes_is_a_64_bit_value_for_every_tail_length(length: int) -> None:
    data = bytes(range(length))
    value = libstdcxx_hash_bytes(data)
    assert 0 <= value < 2**64
    # every byte takes part, including those of a partial last block
    if length:
        assert libstdcxx_hash_bytes(data[:-1] + bytes([data[-1] ^ 1])) != value
