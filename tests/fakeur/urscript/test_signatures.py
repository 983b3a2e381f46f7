"""The builtin table of facts (functions.yaml) and its loader (signatures.py)."""

from __future__ import annotations

import re

import pytest

from urdaemon.fakeur.urscript import signatures
from urdaemon.fakeur.urscript.runtime import UrList, UrPose
from urdaemon.fakeur.urscript.signatures import (
    ACTIVE_TCP,
    CURRENT_JOINT_POSITIONS,
    REQUIRED,
    Computed,
    Param,
    Signature,
    all_signatures,
    load_signatures,
)
from urdaemon.urscript import ScriptParameters, render_control_script

E_SERIES = ("e", (5, 15))
CB3 = ("cb3", (3, 15))

# Every builtin SDU's ur_rtde 1.6.5 rtde_control script calls (read from the script it sends to an
# e-Series controller; the script itself is not ours to keep).
UR_RTDE_CALLS = [
    "enable_external_ft_sensor",
    "end_force_mode",
    "end_freedrive_mode",
    "end_teach_mode",
    "force_mode",
    "force_mode_set_damping",
    "force_mode_set_gain_scaling",
    "freedrive_mode",
    "ft_rtde_input_enable",
    "get_actual_joint_positions_history",
    "get_actual_tcp_pose",
    "get_actual_tool_flange_pose",
    "get_forward_kin",
    "get_freedrive_status",
    "get_inverse_kin",
    "get_inverse_kin_has_solution",
    "get_joint_torques",
    "get_steptime",
    "get_target_payload",
    "get_target_payload_cog",
    "get_target_payload_inertia",
    "get_target_tcp_speed",
    "get_target_waypoint",
    "get_tcp_offset",
    "is_steady",
    "is_within_safety_limits",
    "movej",
    "movel",
    "norm",
    "pose_sub",
    "pose_trans",
    "protective_stop",
    "read_input_float_register",
    "read_input_integer_register",
    "rtde_set_watchdog",
    "servoc",
    "servoj",
    "set_gravity",
    "set_payload",
    "set_target_payload",
    "set_tcp",
    "speedj",
    "speedl",
    "stopj",
    "stopl",
    "sync",
    "teach_mode",
    "textmsg",
    "tool_contact",
    "write_output_float_register",
    "write_output_integer_register",
    "zero_ftsensor",
]

# The builtins python-urx 0.11 (urx/urrobot.py, urx/robot.py) sends as script lines.
URX_CALLS = [
    "movej",
    "movel",
    "movep",
    "movec",
    "servoc",
    "set_digital_out",
    "set_analog_out",
    "set_tcp",
    "set_payload",
    "set_gravity",
    "textmsg",
    "set_tool_voltage",
    "stopj",
    "stopl",
    "speedj",
    "speedl",
]

_KEYWORDS = {"if", "elif", "while", "def", "thread", "sec", "return", "run", "not", "and", "or", "p"}


def _called_builtins(text: str) -> set[str]:
    """The names a script calls that it does not define itself."""
    text = re.sub(r"#[^\n]*", "", text)
    text = re.sub(r"\"[^\"]*\"|'[^']*'", '""', text)
    defined = set(re.findall(r"\b(?:def|thread)\s+(\w+)\s*\(", text))
    called = set(re.findall(r"(?<![\w.])([A-Za-z_]\w*)\s*\(", text))
    return called - defined - _KEYWORDS


def _our_script(version: tuple[int, int, int]) -> str:
    return render_control_script(ScriptParameters("127.0.0.1", controller_version=version))


def test_table_loads_for_every_series_and_checks_itself() -> None:
    e = load_signatures(*E_SERIES)
    cb3 = load_signatures(*CB3)
    table = all_signatures()
    assert len(e) > 200
    assert len(cb3) > 150
    assert set(e) | set(cb3) <= set(table)
    for name, signature in table.items():
        assert isinstance(signature, Signature)
        assert signature.name == name
        assert signature.since, name
        names = signature.param_names
        assert len(set(names)) == len(names), name
        required = [p.required for p in signature.params]
        assert required == sorted(required, reverse=True), f"{name}: a required parameter after a default"


def test_loading_is_cached_and_read_only() -> None:
    e = load_signatures(*E_SERIES)
    assert load_signatures(*E_SERIES) is e
    with pytest.raises(TypeError):
        e["movej"] = e["movel"]  # type: ignore[index]


def test_unknown_series_is_refused() -> None:
    with pytest.raises(ValueError, match="series"):
        load_signatures("cb2", (1, 8))


def test_every_builtin_of_our_e_series_script_is_in_the_table() -> None:
    called = _called_builtins(_our_script((5, 15, 0)))
    assert {"servoj", "speedj", "socket_read_binary_integer", "set_target_payload"} <= called
    assert sorted(called - set(load_signatures(*E_SERIES))) == []


def test_every_builtin_of_our_cb3_script_compiles_on_cb3() -> None:
    called = _called_builtins(_our_script((3, 15, 0)))
    cb3 = load_signatures(*CB3)
    assert sorted(called - set(cb3)) == []
    # behind `if UD_STEP < 0.008`: CB3 knows the name (it compiles urcl's script that does the same)
    # but does not have the function
    assert not cb3["force_mode_set_gain_scaling"].supported
    assert sorted(name for name in called if not cb3[name].supported) == ["force_mode_set_gain_scaling"]


def _our_names_unknown_to(series: str, version: tuple[int, int]) -> list[str]:
    rendered = _called_builtins(_our_script((*version, 0)))
    return sorted(rendered - set(load_signatures(series, version)))


@pytest.mark.parametrize("version", [(5, 4), (5, 9), (5, 10), (5, 15), (5, 25)])
def test_our_script_compiles_name_wise_on_e_series_from_5_4(version: tuple[int, int]) -> None:
    assert _our_names_unknown_to("e", version) == []


def test_our_script_compiles_name_wise_on_e_series_before_5_4() -> None:
    """Reproduction: render the control script for controller_version (5, 3, 0); it calls tool_contact."""
    assert _our_names_unknown_to("e", (5, 3)) == []


@pytest.mark.parametrize("version", [(3, 14), (3, 15)])
def test_our_script_compiles_name_wise_on_cb3_from_3_14(version: tuple[int, int]) -> None:
    assert _our_names_unknown_to("cb3", version) == []


def test_every_builtin_ur_rtde_calls_is_there_on_e_series() -> None:
    assert sorted(set(UR_RTDE_CALLS) - set(load_signatures(*E_SERIES))) == []


def test_every_builtin_python_urx_calls_is_there_on_both_series() -> None:
    for series in (E_SERIES, CB3):
        assert sorted(set(URX_CALLS) - set(load_signatures(*series))) == [], series


@pytest.mark.parametrize(
    ("name", "absent", "present"),
    [
        ("tool_contact", [("cb3", (3, 15)), ("e", (5, 3))], [("e", (5, 4)), ("e", (5, 25))]),
        ("set_target_payload", [("e", (5, 9)), ("cb3", (3, 14))], [("e", (5, 10)), ("cb3", (3, 15))]),
        ("get_target_payload_inertia", [("e", (5, 9)), ("cb3", (3, 14))], [("e", (5, 10)), ("cb3", (3, 15))]),
        ("force_mode_set_gain_scaling", [("cb3", (3, 15))], [("e", (5, 0))]),
        ("force_mode_set_damping", [("cb3", (3, 4))], [("cb3", (3, 5)), ("e", (5, 0))]),
        ("get_freedrive_status", [("e", (5, 9)), ("cb3", (3, 15))], [("e", (5, 10))]),
        ("ft_rtde_input_enable", [("e", (5, 8)), ("cb3", (3, 13))], [("e", (5, 9)), ("cb3", (3, 14))]),
        ("movej", [], [("e", (5, 0)), ("cb3", (3, 0))]),
    ],
)
def test_availability_follows_series_and_version(
    name: str, absent: list[tuple[str, tuple[int, int]]], present: list[tuple[str, tuple[int, int]]]
) -> None:
    for series, version in absent:
        loaded = load_signatures(series, version)
        assert name not in loaded or not loaded[name].supported, (series, version)
        assert not all_signatures()[name].available(series, version)
    for series, version in present:
        assert load_signatures(series, version)[name].supported, (series, version)
        assert all_signatures()[name].available(series, version)


@pytest.mark.parametrize("name", ["tool_contact", "force_mode_set_gain_scaling"])
def test_cb3_from_3_14_knows_some_e_series_names_without_having_them(name: str) -> None:
    assert name not in load_signatures("cb3", (3, 13))
    known = load_signatures("cb3", (3, 14))[name]
    assert not known.supported
    signature = all_signatures()[name]
    assert signature.known("cb3", (3, 14))
    assert not signature.known("cb3", (3, 13))
    assert not signature.available("cb3", (3, 15))
    assert signature.supported  # all_signatures gives the series that has it


def _defaults(series: tuple[str, tuple[int, int]], name: str) -> dict[str, object]:
    return {p.name: p.default for p in load_signatures(*series)[name].params}


def test_motion_defaults_are_the_manuals() -> None:
    assert _defaults(E_SERIES, "movej") == {"q": REQUIRED, "a": 1.4, "v": 1.05, "t": 0, "r": 0}
    assert _defaults(E_SERIES, "movel") == {"pose": REQUIRED, "a": 1.2, "v": 0.25, "t": 0, "r": 0}
    assert _defaults(E_SERIES, "movep") == {"pose": REQUIRED, "a": 1.2, "v": 0.25, "r": 0}
    servoj = _defaults(E_SERIES, "servoj")
    assert list(servoj) == ["q", "a", "v", "t", "lookahead_time", "gain"]
    assert (servoj["t"], servoj["lookahead_time"], servoj["gain"]) == (0.002, 0.1, 300)
    # a and v are unused by the controller and omitted by urcl's and ur_rtde's scripts
    assert servoj["a"] is not REQUIRED
    assert servoj["v"] is not REQUIRED
    # one controller step by default: 8 ms on CB3
    assert _defaults(CB3, "servoj")["t"] == 0.008
    # speedj/speedl: t optional (ur_rtde calls speedj(qd, a=...)); aRot copies a
    assert _defaults(E_SERIES, "speedj") == {"qd": REQUIRED, "a": REQUIRED, "t": 0}
    speedl = _defaults(E_SERIES, "speedl")
    assert speedl["aRot"] == Computed("param:a")
    assert isinstance(speedl["aRot"], Computed)
    assert speedl["aRot"].param == "a"
    assert _defaults(E_SERIES, "stopj") == {"a": REQUIRED}


def test_value_kinds_of_defaults() -> None:
    freedrive = _defaults(("e", (5, 10)), "freedrive_mode")
    assert type(freedrive["feature"]) is UrPose
    assert freedrive["feature"] == [0.0] * 6
    assert type(freedrive["freeAxes"]) is UrList
    assert freedrive["freeAxes"] == [1] * 6
    assert _defaults(("e", (5, 9)), "freedrive_mode") == {}  # no parameters before 5.10
    payload = _defaults(E_SERIES, "set_target_payload")
    assert payload == {"m": REQUIRED, "cog": REQUIRED, "inertia": [0] * 6, "transition_time": 0}
    assert type(payload["inertia"]) is UrList
    kin = _defaults(E_SERIES, "get_inverse_kin")
    assert kin["qnear"] is CURRENT_JOINT_POSITIONS
    assert kin["tcp"] is ACTIVE_TCP
    assert kin["maxPositionError"] == 1e-10
    assert _defaults(E_SERIES, "popup") == {
        "s": REQUIRED,
        "title": "Popup",
        "warning": False,
        "error": False,
        "blocking": False,
    }
    assert _defaults(E_SERIES, "socket_read_binary_integer") == {
        "number": REQUIRED,
        "socket_name": "socket_0",
        "timeout": 2,
    }
    assert _defaults(E_SERIES, "textmsg") == {"s1": REQUIRED, "s2": ""}


def test_revisions_change_a_signature_from_their_version_on() -> None:
    assert _defaults(("e", (5, 24)), "tool_contact") == {"direction": REQUIRED}
    newer = _defaults(("e", (5, 25)), "tool_contact")
    assert newer == {"direction": [0.0] * 6, "force_threshold": 0.0}
    # all_signatures shows the newest form
    assert all_signatures()["tool_contact"].param_names == ("direction", "force_threshold")


def test_physical_builtins_are_the_ones_that_take_controller_time() -> None:
    e = load_signatures(*E_SERIES)
    physical = {name for name, s in e.items() if s.physical}
    assert {
        "movej",
        "movel",
        "movep",
        "servoj",
        "speedj",
        "speedl",
        "stopj",
        "stopl",
        "sleep",
        "sync",
    } <= physical
    assert {"socket_read_binary_integer", "socket_read_string", "socket_open"} <= physical
    for name in ("textmsg", "get_actual_joint_positions", "set_digital_out", "socket_send_int", "pose_trans"):
        assert not e[name].physical, name


def test_undocumented_builtins_real_controllers_accept_are_marked() -> None:
    signature = load_signatures(*CB3)["get_joint_positions"]
    assert signature.params == ()
    assert not signature.documented
    assert load_signatures(*E_SERIES)["movej"].documented


def test_required_count_and_param_lookup() -> None:
    movej = load_signatures(*E_SERIES)["movej"]
    assert sum(1 for p in movej.params if p.required) == 1
    assert movej.params[0] == Param("q")
    assert movej.params[0].required
    assert not movej.params[1].required


def test_a_name_written_twice_is_refused() -> None:
    text = "functions:\n  movej:\n    params: [q]\n  movej:\n    params: [q, a]\n"
    with pytest.raises(ValueError, match="written twice"):
        signatures._parse_table(text)


@pytest.mark.parametrize(
    ("entry", "error"),
    [
        ("{params: [a, a]}", "distinct"),
        ("{params: [{a: 1}, b]}", "required parameter b after"),
        ("{params: [a], since: {e: 5.4}}", "bad entry"),
        ("{params: [a], since: {cb2: '1.8'}}", "bad entry"),
        ("{params: [a], physical: 'yes'}", "booleans"),
        ("{params: [a], deprecated: '5.1'}", "booleans"),
        ("{params: [{a: {pose: [1, 2]}}]}", "unsupported default"),
        ("{params: [{a: {computed: 'param:b'}}]}", "copies unknown"),
        ("{params: [a], typo: 1}", "unknown keys"),
        ("{params: [a], names_only: {e: '5.1'}}", "names_only names a series"),
    ],
)
def test_malformed_entries_are_refused(entry: str, error: str) -> None:
    table = signatures._parse_table(
        f"defaults:\n  since: {{e: '5.0', cb3: '3.0'}}\nfunctions:\n  f: {entry}\n"
    )
    with pytest.raises(ValueError, match=error):
        signatures._signatures(table, "e", (5, 15))
