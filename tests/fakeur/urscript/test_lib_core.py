"""lib_core builtins: messages, math, strings, lists and pose maths (checked against independent maths)."""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from urdaemon.description.frames import frame_of_pose, pose_of_frame
from urdaemon.fakeur.urscript.runtime import BUILTINS, ScriptRuntimeError, UrList, UrPose


class Host:
    step_time = 0.008

    def __init__(self) -> None:
        self.messages: list[tuple[str, str]] = []

    def message(self, kind: str, text: str) -> None:
        self.messages.append((kind, text))


HOST = cast(Any, Host())


def call(name: str, *args: Any) -> Any:
    return BUILTINS[name].function(HOST, *args)


def _rotation(rotvec: Any) -> np.ndarray:
    """Rodrigues with numpy: the independent check of lib_core's matrices."""
    v = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(v))
    if angle < 1e-15:
        return np.eye(3)
    k = v / angle
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    rotation: np.ndarray = np.eye(3) + math.sin(angle) * skew + (1 - math.cos(angle)) * skew @ skew
    return rotation


def _matrix(pose: Any) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = _rotation(pose[3:])
    m[:3, 3] = pose[:3]
    return m


def _same_pose(a: Any, b_matrix: np.ndarray) -> None:
    assert isinstance(a, UrPose)
    np.testing.assert_allclose(_matrix(a), b_matrix, atol=1e-9)


coordinate = st.floats(-2, 2)
angle_vector = st.tuples(st.floats(-2, 2), st.floats(-2, 2), st.floats(-2, 2)).filter(
    lambda v: math.hypot(*v) < 3.1
)
poses = st.builds(lambda p, r: UrPose((*p, *r)), st.tuples(coordinate, coordinate, coordinate), angle_vector)


@settings(max_examples=50, deadline=None)
@given(poses, poses)
def test_pose_trans_inv_add_sub_match_homogeneous_matrices(a: UrPose, b: UrPose) -> None:
    _same_pose(call("pose_trans", a, b), _matrix(a) @ _matrix(b))
    _same_pose(call("pose_inv", a), np.linalg.inv(_matrix(a)))
    added = call("pose_add", a, b)
    np.testing.assert_allclose(list(added[:3]), np.add(a[:3], b[:3]), atol=1e-12)
    np.testing.assert_allclose(_rotation(added[3:]), _rotation(b[3:]) @ _rotation(a[3:]), atol=1e-9)
    back = call("pose_sub", added, b)
    np.testing.assert_allclose(_matrix(back), _matrix(a), atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(angle_vector)
def test_rotation_vector_and_rpy_round_trip(rotvec: tuple[float, float, float]) -> None:
    rpy = call("rotvec2rpy", UrList(rotvec))
    roll, pitch, yaw = rpy
    rz, ry, rx = (_rotation([0, 0, yaw]), _rotation([0, pitch, 0]), _rotation([roll, 0, 0]))
    np.testing.assert_allclose(rz @ ry @ rx, _rotation(rotvec), atol=1e-9)
    np.testing.assert_allclose(_rotation(call("rpy2rotvec", rpy)), _rotation(rotvec), atol=1e-9)


def test_rotation_of_half_a_turn_keeps_its_axis() -> None:
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    rotvec = pose_of_frame(frame_of_pose((0.0, 0.0, 0.0, *(axis * math.pi))))[3:]
    assert math.isclose(float(np.linalg.norm(rotvec)), math.pi, rel_tol=1e-9)
    np.testing.assert_allclose(_rotation(rotvec), _rotation(axis * math.pi), atol=1e-9)


def test_distances_and_interpolation() -> None:
    a = UrPose([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    b = UrPose([0.3, 0.4, 0.0, 0.0, 0.0, math.pi / 2])
    assert call("point_dist", a, b) == pytest.approx(0.5)
    middle = call("interpolate_pose", a, b, 0.5)
    np.testing.assert_allclose(list(middle), [0.15, 0.2, 0.0, 0.0, 0.0, math.pi / 4], atol=1e-12)
    np.testing.assert_allclose(list(call("interpolate_pose", a, b, 1.0)), list(b), atol=1e-12)


def test_wrench_trans_moves_the_torque_reference() -> None:
    """A 10 N force along z at A's origin, seen from B one metre along x: 10 Nm about y."""
    wrench = call("wrench_trans", UrPose([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]), [0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(list(wrench), [0.0, 0.0, 10.0, 0.0, 10.0, 0.0], atol=1e-12)


def test_math() -> None:
    assert call("floor", 2.7) == 2
    assert isinstance(call("floor", 2.7), int)
    assert call("ceil", 2.1) == 3
    assert call("sqrt", 9.0) == 3.0
    assert call("pow", 2, 10) == 1024.0
    assert call("log", 10, 1000) == pytest.approx(3.0)
    assert call("atan2", 1.0, 0.0) == pytest.approx(math.pi / 2)
    assert call("d2r", 180) == pytest.approx(math.pi)
    assert call("norm", -3) == 3
    assert call("norm", [3, 4]) == 5.0
    assert list(call("normalize", [3, 4])) == [0.6, 0.8]
    assert call("length", [1, 2, 3]) == 3
    assert 0.0 <= call("random") < 1.0
    bits = call("integer_to_binary_list", 37)
    assert len(bits) == 32
    assert call("binary_list_to_integer", bits) == 37
    with pytest.raises(ScriptRuntimeError, match="sqrt: argument out of range"):
        call("sqrt", -1.0)
    with pytest.raises(ScriptRuntimeError, match="zero vector"):
        call("normalize", [0, 0])


def test_strings() -> None:
    assert call("str_cat", "a", 1) == "a1"
    assert call("str_cat", "q=", [1.5, True]) == "q=[1.5, True]"
    assert call("str_cat", "", UrPose([1, 2, 3, 0, 0, 0])) == "p[1, 2, 3, 0, 0, 0]"
    assert call("str_len", "hello") == 5
    assert call("str_empty", "") is True
    assert call("str_at", "hello", 1) == "e"
    assert call("str_at", "hello", 9) == ""
    assert call("str_find", "hello", "l", 0) == 2
    assert call("str_find", "hello", "l", 3) == 3
    assert call("str_sub", "hello", 1, 3) == "ell"
    assert call("str_sub", "hello", 2, -1) == "llo"
    assert call("to_num", "42") == 42
    assert call("to_num", "-1.5") == -1.5
    assert call("to_str", 0.1) == "0.1"
    with pytest.raises(ScriptRuntimeError, match="not a number"):
        call("to_num", "x1")
    with pytest.raises(ScriptRuntimeError, match="expected a string"):
        call("str_len", 5)


def test_messages_go_to_the_host() -> None:
    host = Host()
    BUILTINS["textmsg"].function(host, "value: ", 2.5)
    BUILTINS["popup"].function(host, "careful", "Title", True, False, False)
    assert host.messages == [("text", "value: 2.5"), ("popup", "Title (warning): careful")]


def test_time_builtins() -> None:
    assert call("get_steptime") == 0.008
    assert BUILTINS["sync"].blocking
    assert BUILTINS["sleep"].blocking
    assert len(list(BUILTINS["sleep"].function(HOST, 0.02))) == 3  # 2.5 cycles of 8 ms -> 3
    assert len(list(BUILTINS["sleep"].function(HOST, 0.016))) == 2
    assert list(BUILTINS["sleep"].function(HOST, 0)) == []
    assert len(list(BUILTINS["sync"].function(HOST))) == 1


def test_str_cat_refuses_a_string_longer_than_the_fake_keeps() -> None:
    """A loop doubling a string would otherwise fill the fake's memory."""
    from urdaemon.fakeur.urscript.lib_core import MAX_STRING_CHARS, str_cat

    half = "x" * (MAX_STRING_CHARS // 2)
    assert len(str_cat(cast(Any, None), half, half)) == MAX_STRING_CHARS
    with pytest.raises(ScriptRuntimeError, match="at most"):
        str_cat(cast(Any, None), half, half + "x")


def test_inv_inverts_a_square_matrix_and_refuses_singular_or_non_square_ones() -> None:
    """On f5f0e26 ``inv`` and ``transpose`` stopped every program with "not simulated"."""
    from urdaemon.fakeur.urscript import lib_core

    m = UrList([UrList([4.0, 7.0, 2.0]), UrList([3.0, 6.0, 1.0]), UrList([2.0, 5.0, 3.0])])
    inverse = lib_core.inv(None, m)
    product = [[sum(m[i][k] * inverse[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    assert product == [[pytest.approx(1.0 if i == j else 0.0, abs=1e-12) for j in range(3)] for i in range(3)]
    assert isinstance(inverse, UrList)
    assert isinstance(inverse[0], UrList)
    with pytest.raises(ScriptRuntimeError, match="singular"):
        lib_core.inv(None, [[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(ScriptRuntimeError, match="not square"):
        lib_core.inv(None, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    with pytest.raises(ScriptRuntimeError, match="different lengths"):
        lib_core.inv(None, [[1.0, 2.0], [3.0]])
    pose = UrPose([0.1, -0.2, 0.3, 0.2, -0.4, 1.0])
    assert list(lib_core.inv(None, pose)) == pytest.approx(list(lib_core.pose_inv(None, pose)))


def test_transpose_swaps_rows_and_columns() -> None:
    from urdaemon.fakeur.urscript import lib_core

    assert lib_core.transpose(None, [[1, 2, 3], [4, 5, 6]]) == [[1, 4], [2, 5], [3, 6]]
    assert lib_core.transpose(None, [1, 2, 3]) == [1, 2, 3]
    assert lib_core.transpose(None, lib_core.transpose(None, [[1, 2]])) == [[1, 2]]
