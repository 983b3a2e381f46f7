"""Builtins that need no controller: time and messages, math, strings, lists and pose maths.

Registered into :data:`~urdaemon.fakeur.urscript.runtime.BUILTINS` on import; arguments arrive in the
order of ``functions.yaml`` (the URScript manual's), defaults filled in by the compiler.
"""

from __future__ import annotations

import math
import random as _random
from collections.abc import Sequence
from typing import Any

from urdaemon.description.frames import (
    Frame,
    compose,
    frame_of_pose,
    inverse,
    pose_of_frame,
    rotate,
    rotation_vector,
)
from urdaemon.fakeur.urscript.runtime import ScriptRuntimeError, UrList, UrPose, builtin, copy_value
from urdaemon.fakeur.urscript.script_host import ScriptHost
from urdaemon.fakeur.urscript.signatures import Computed

__all__ = ["text"]


# -- time and messages ----------------------------------------------------------------------------------


@builtin("sync", blocking=True)
def sync(host: ScriptHost) -> Any:
    """Waits for the next controller cycle."""
    yield


@builtin("sleep", blocking=True)
def sleep(host: ScriptHost, t: float) -> Any:
    """Waits ``ceil(t / step_time)`` controller cycles (none for ``t <= 0``)."""
    cycles = math.ceil(t / host.step_time - 1e-9)
    for _ in range(cycles):
        yield


@builtin("get_steptime")
def get_steptime(host: ScriptHost) -> float:
    return host.step_time


def text(value: Any) -> str:
    """A value as the controller prints it (``textmsg``, ``to_str``, ``str_cat``)."""
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "True" if value else "False"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)) and not isinstance(value, UrList):
        return repr(UrList(value))
    return repr(value) if not isinstance(value, int) else str(value)


@builtin("textmsg")
def textmsg(host: ScriptHost, s1: Any, s2: Any) -> None:
    host.message("text", text(s1) + text(s2))


@builtin("popup")
def popup(host: ScriptHost, s: Any, title: Any, warning: bool, error: bool, blocking: bool) -> None:
    kind = "error" if error else "warning" if warning else "message"
    host.message("popup", f"{text(title)} ({kind}): {text(s)}")


# -- strings --------------------------------------------------------------------------------------------


def _string(name: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ScriptRuntimeError(f"{name}: expected a string, got {text(value)}")
    return value


MAX_STRING_CHARS = 65536
"""The longest string a program may build (the fake's own bound: memory and the primary interface's
message size)."""


@builtin("str_cat")
def str_cat(host: ScriptHost, op1: Any, op2: Any) -> str:
    joined = text(op1) + text(op2)
    if len(joined) > MAX_STRING_CHARS:
        raise ScriptRuntimeError(
            f"str_cat: a string of {len(joined)} characters; the fake keeps at most {MAX_STRING_CHARS}"
        )
    return joined


@builtin("str_len")
def str_len(host: ScriptHost, string: Any) -> int:
    return len(_string("str_len", string))


@builtin("str_empty")
def str_empty(host: ScriptHost, string: Any) -> bool:
    return _string("str_empty", string) == ""


@builtin("str_at")
def str_at(host: ScriptHost, src: Any, index: int) -> str:
    source = _string("str_at", src)
    return source[index] if 0 <= index < len(source) else ""


@builtin("str_find")
def str_find(host: ScriptHost, src: Any, target: Any, start_from: int) -> int:
    return _string("str_find", src).find(_string("str_find", target), max(int(start_from), 0))


@builtin("str_sub")
def str_sub(host: ScriptHost, src: Any, index: int, length: int) -> str:
    source = _string("str_sub", src)
    if index < 0 or index > len(source):
        return ""
    return source[index:] if length < 0 else source[index : index + length]


@builtin("to_str")
def to_str(host: ScriptHost, val: Any) -> str:
    return text(val)


@builtin("to_num")
def to_num(host: ScriptHost, string: Any) -> int | float:
    source = _string("to_num", string).strip()
    try:
        return int(source)
    except ValueError:
        pass
    try:
        return float(source)
    except ValueError:
        raise ScriptRuntimeError(f'to_num: "{source}" is not a number') from None


# -- math -----------------------------------------------------------------------------------------------


def _checked(name: str, function: Any, *args: float) -> float:
    try:
        result: float = function(*args)
    except (ValueError, OverflowError):
        raise ScriptRuntimeError(f"{name}: argument out of range") from None
    return result


def _unary(name: str, function: Any) -> None:
    def implementation(host: ScriptHost, f: float) -> float:
        return _checked(name, function, f)

    implementation.__name__ = name
    builtin(name)(implementation)


for _name, _function in (
    ("sin", math.sin),
    ("cos", math.cos),
    ("tan", math.tan),
    ("asin", math.asin),
    ("acos", math.acos),
    ("atan", math.atan),
    ("sqrt", math.sqrt),
    ("d2r", math.radians),
    ("r2d", math.degrees),
):
    _unary(_name, _function)


@builtin("atan2")
def atan2(host: ScriptHost, y: float, x: float) -> float:
    """Arc tangent of first/second (the manual's ``atan2(y, x)``)."""
    return math.atan2(y, x)


@builtin("floor")
def floor(host: ScriptHost, f: float) -> int:
    return math.floor(f)


@builtin("ceil")
def ceil(host: ScriptHost, f: float) -> int:
    return math.ceil(f)


@builtin("pow")
def power(host: ScriptHost, base: float, exponent: float) -> float:
    return _checked("pow", math.pow, base, exponent)


@builtin("log")
def log(host: ScriptHost, b: float, f: float) -> float:
    return _checked("log", math.log, f, b)


@builtin("random")
def random(host: ScriptHost) -> float:
    return _random.random()


@builtin("norm")
def norm(host: ScriptHost, a: Any) -> float:
    if isinstance(a, list):
        return math.sqrt(sum(x * x for x in a))
    return abs(a)  # type: ignore[no-any-return]


@builtin("normalize")
def normalize(host: ScriptHost, v: Sequence[float]) -> UrList:
    length = math.sqrt(sum(x * x for x in v))
    if length == 0.0:
        raise ScriptRuntimeError("normalize: the zero vector has no direction")
    return UrList(x / length for x in v)


@builtin("length")
def length(host: ScriptHost, v: Any) -> int:
    return len(v)


@builtin("get_list_length")
def get_list_length(host: ScriptHost, v: Any) -> int:
    return len(v)


MAX_LIST_LENGTH = 100_000
"""The longest list ``make_list`` makes (the fake's own bound: memory)."""


@builtin("make_list")
def make_list(host: ScriptHost, length: Any, initial_value: Any, capacity: Any) -> UrList:
    """A list of ``length`` copies of ``initial_value``; ``capacity`` (default: ``length``) only bounds it."""
    count = _whole("make_list length", length)
    room = count if isinstance(capacity, Computed) else _whole("make_list capacity", capacity)
    if not 0 <= count <= room <= MAX_LIST_LENGTH:
        raise ScriptRuntimeError(
            f"make_list: length {count} and capacity {room} must satisfy 0 <= length <= capacity <= "
            f"{MAX_LIST_LENGTH}"
        )
    return UrList(copy_value(initial_value) for _ in range(count))


@builtin("size")
def size(host: ScriptHost, v: Any) -> int:
    """The number of elements of a list (or characters of a string)."""
    if not isinstance(v, (list, str)):
        raise ScriptRuntimeError(f"size: expected a list, got {text(v)}")
    return len(v)


def _whole(name: str, value: Any) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if value.__class__ is not int:
        raise ScriptRuntimeError(f"{name} must be a whole number, got {text(value)}")
    return int(value)


@builtin("binary_list_to_integer")
def binary_list_to_integer(host: ScriptHost, bits: Sequence[bool]) -> int:
    return sum(1 << i for i, bit in enumerate(bits) if bit)


@builtin("integer_to_binary_list")
def integer_to_binary_list(host: ScriptHost, x: int) -> UrList:
    value = int(x) & 0xFFFFFFFF
    return UrList(bool(value >> i & 1) for i in range(32))


# -- pose maths -----------------------------------------------------------------------------------------


def _pose(name: str, value: Any) -> Sequence[float]:
    if not isinstance(value, list) or len(value) != 6:
        raise ScriptRuntimeError(f"{name}: expected a pose p[x, y, z, rx, ry, rz], got {text(value)}")
    return value


def _frame(pose: Sequence[float]) -> Frame:
    return frame_of_pose(pose)


def _turn(pose: Sequence[float]) -> Frame:
    """The rotation of ``pose`` alone (no translation)."""
    return frame_of_pose((0.0, 0.0, 0.0, pose[3], pose[4], pose[5]))


def _with_rotation(position: Sequence[float], rotation: Frame) -> UrPose:
    return UrPose((*map(float, position), *rotation_vector(*rotation[:9])))


@builtin("pose_trans")
def pose_trans(host: ScriptHost, p_from: Any, p_from_to: Any) -> UrPose:
    a, b = _pose("pose_trans", p_from), _pose("pose_trans", p_from_to)
    return UrPose(pose_of_frame(compose(_frame(a), _frame(b))))


@builtin("pose_inv")
def pose_inv(host: ScriptHost, p_from: Any) -> UrPose:
    return UrPose(pose_of_frame(inverse(_frame(_pose("pose_inv", p_from)))))


@builtin("pose_add")
def pose_add(host: ScriptHost, p_1: Any, p_2: Any) -> UrPose:
    a, b = _pose("pose_add", p_1), _pose("pose_add", p_2)
    return _with_rotation((a[0] + b[0], a[1] + b[1], a[2] + b[2]), compose(_turn(b), _turn(a)))


@builtin("pose_sub")
def pose_sub(host: ScriptHost, p_to: Any, p_from: Any) -> UrPose:
    """The inverse of ``pose_add``: ``pose_add(pose_sub(p_to, p_from), p_from) == p_to``."""
    a, b = _pose("pose_sub", p_to), _pose("pose_sub", p_from)
    return _with_rotation((a[0] - b[0], a[1] - b[1], a[2] - b[2]), compose(inverse(_turn(b)), _turn(a)))


@builtin("point_dist")
def point_dist(host: ScriptHost, p_from: Any, p_to: Any) -> float:
    a, b = _pose("point_dist", p_from), _pose("point_dist", p_to)
    return math.dist(a[:3], b[:3])


@builtin("pose_dist")
def pose_dist(host: ScriptHost, p_from: Any, p_to: Any) -> float:
    """Position distance and rotation angle between the poses, combined as sqrt(d^2 + angle^2)."""
    a, b = _pose("pose_dist", p_from), _pose("pose_dist", p_to)
    relative = compose(inverse(_turn(a)), _turn(b))
    angle = math.sqrt(sum(x * x for x in rotation_vector(*relative[:9])))
    return math.sqrt(math.dist(a[:3], b[:3]) ** 2 + angle**2)


@builtin("interpolate_pose")
def interpolate_pose(host: ScriptHost, p_from: Any, p_to: Any, alpha: float) -> UrPose:
    a, b = _pose("interpolate_pose", p_from), _pose("interpolate_pose", p_to)
    start = _turn(a)
    rx, ry, rz = rotation_vector(*compose(inverse(start), _turn(b))[:9])
    partial = frame_of_pose((0.0, 0.0, 0.0, alpha * rx, alpha * ry, alpha * rz))
    position = tuple(a[i] + alpha * (b[i] - a[i]) for i in range(3))
    return _with_rotation(position, compose(start, partial))


@builtin("rotvec2rpy")
def rotvec2rpy(host: ScriptHost, rotation_vector: Sequence[float]) -> UrList:
    m = frame_of_pose((0.0, 0.0, 0.0, rotation_vector[0], rotation_vector[1], rotation_vector[2]))
    r00, r01, _, r10, r11, _, r20, r21, r22 = m[:9]
    pitch = math.atan2(-r20, math.hypot(r00, r10))
    if abs(math.cos(pitch)) < 1e-9:
        return UrList((0.0, pitch, math.atan2(-r01, r11)))
    return UrList((math.atan2(r21, r22), pitch, math.atan2(r10, r00)))


@builtin("rpy2rotvec")
def rpy2rotvec(host: ScriptHost, rpy_vector: Sequence[float]) -> UrList:
    roll, pitch, yaw = rpy_vector[0], rpy_vector[1], rpy_vector[2]
    rx = frame_of_pose((0.0, 0.0, 0.0, roll, 0.0, 0.0))
    ry = frame_of_pose((0.0, 0.0, 0.0, 0.0, pitch, 0.0))
    rz = frame_of_pose((0.0, 0.0, 0.0, 0.0, 0.0, yaw))
    return UrList(_rotvec(compose(rz, compose(ry, rx))))


@builtin("wrench_trans")
def wrench_trans(host: ScriptHost, T_from_to: Any, w_from: Sequence[float]) -> UrList:
    """The wrench ``w_from`` (in frame A) expressed in frame B, ``T_from_to`` being B in A."""
    pose = _pose("wrench_trans", T_from_to)
    back = inverse(_turn(pose))
    force = rotate(back, w_from[:3])
    # the torque about B's origin: the torque about A's minus (B's origin x force), in B's axes
    p = pose[:3]
    f = w_from[:3]
    moment = (p[1] * f[2] - p[2] * f[1], p[2] * f[0] - p[0] * f[2], p[0] * f[1] - p[1] * f[0])
    torque = rotate(back, [w_from[3 + i] - moment[i] for i in range(3)])
    return UrList((*force, *torque))


def _rotvec(frame: Frame) -> tuple[float, float, float]:
    return rotation_vector(*frame[:9])


# -- matrices -------------------------------------------------------------------------------------------
# A URScript matrix is a list of rows, each a list of numbers (``[[1, 2], [3, 4]]``); a flat list is an
# array (a vector, no orientation). A pose given to ``inv`` is inverted as a transform (``pose_inv``).

SINGULAR_PIVOT = 1e-12
"""A pivot below this share of the matrix's largest element makes ``inv`` call the matrix singular."""


def _matrix(name: str, m: Any) -> list[list[float]]:
    """The rows of matrix ``m``; a runtime error unless it is a non-empty list of equal-length number rows."""
    if not isinstance(m, list) or not m or not all(isinstance(row, list) and row for row in m):
        raise ScriptRuntimeError(f"{name}: expected a matrix (a list of rows), got {text(m)}")
    width = len(m[0])
    if any(len(row) != width for row in m):
        raise ScriptRuntimeError(f"{name}: the rows of {text(m)} have different lengths")
    for row in m:
        for value in row:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ScriptRuntimeError(f"{name}: {text(value)} in {text(m)} is not a number")
    return [[float(value) for value in row] for row in m]


def _rows(rows: list[list[float]]) -> UrList:
    return UrList(UrList(row) for row in rows)


@builtin("transpose")
def transpose(host: ScriptHost, m: Any) -> UrList:
    """The transpose of matrix ``m``; an array (a flat list) has no orientation and comes back as is."""
    if isinstance(m, list) and m and not any(isinstance(item, list) for item in m):
        return UrList(m)
    rows = _matrix("transpose", m)
    return _rows([list(column) for column in zip(*rows, strict=True)])


@builtin("inv")
def inv(host: ScriptHost, m: Any) -> Any:
    """The inverse of a square, non-singular matrix (Gauss-Jordan with partial pivoting), or of a pose.

    As the manual asks: a matrix that is not square, or is singular, is a runtime error."""
    if isinstance(m, UrPose):
        return pose_inv(host, m)
    rows = _matrix("inv", m)
    size = len(rows)
    if any(len(row) != size for row in rows):
        raise ScriptRuntimeError(f"inv: a {size}x{len(rows[0])} matrix is not square")
    scale = max(abs(value) for row in rows for value in row)
    work = [row + [1.0 if i == j else 0.0 for j in range(size)] for i, row in enumerate(rows)]
    for column in range(size):
        pivot = max(range(column, size), key=lambda r: abs(work[r][column]))
        if abs(work[pivot][column]) <= SINGULAR_PIVOT * scale:
            raise ScriptRuntimeError(f"inv: the matrix {text(m)} is singular")
        work[column], work[pivot] = work[pivot], work[column]
        lead = work[column][column]
        work[column] = [value / lead for value in work[column]]
        for r in range(size):
            if r != column and work[r][column] != 0.0:
                factor = work[r][column]
                work[r] = [a - factor * b for a, b in zip(work[r], work[column], strict=True)]
    return _rows([row[size:] for row in work])
