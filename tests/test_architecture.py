"""Layering rules, checked on the source: pure layers import no I/O, no loop, no clock."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "urdaemon"

# Pure layers: their behaviour depends only on their arguments (time is a parameter).
PURE = {
    "control": {
        "asyncio",
        "socket",
        "threading",
        "time",
        "zenoh",
        "logging",
        "pydantic",
        "yourdfpy",
        "xacro",
    },
    "cell": {"asyncio", "socket", "threading", "time", "zenoh"},
    # the servo boards' registers and command lines: numbers in, bytes out (boards/__init__.py)
    "boards": {"asyncio", "socket", "threading", "time", "zenoh", "logging", "pydantic", "os"},
    # description may lock: xacro keeps its state in module globals
    "description": {"asyncio", "socket", "time", "zenoh"},
    "model.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "errors.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    # the messages: the envelope, the fields' checks, the decoders and the state encoder (publish/envelope.py)
    "publish/envelope.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/fields.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/service_requests.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/stream_commands.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/goal_cancel.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/lease_request.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/move_goal.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/linear_goal.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/cell_goal.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/trajectory_goal.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/state_encoder.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    "publish/keys.py": {"asyncio", "socket", "threading", "time", "zenoh", "pydantic"},
    # the codecs: bytes in, events out (protocols/__init__.py)
    "protocols": {"asyncio", "socket", "selectors", "threading", "time", "zenoh", "logging", "pydantic"},
    # the UR backend's reverse channel: a state machine, time passed in (backends/ur/reverse_channel.py)
    "backends/ur/reverse_channel.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    # the fake's pure parts: the arm, its motions and surroundings, what it reports, program translation
    "fakeur/fake_arm.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/life.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/playback.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/pose.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/joint_motion.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/tcp_motion.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/contact.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/reports.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/faults.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/urp.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    # the URScript compiler: the controller's checks, then Python source (fakeur/urscript/compiler.py)
    "fakeur/urscript/compiler.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/urscript/checker.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    "fakeur/urscript/codegen.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging"},
    # what a recording holds and its CDR: messages in, bytes out (recording/channels.py)
    "recording/cdr.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging", "pydantic"},
    "recording/channels.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging", "pydantic"},
    # the doctor's checks: facts in, verdicts out (doctor/checks.py)
    "doctor/checks.py": {"asyncio", "socket", "threading", "time", "zenoh", "logging", "os"},
}


def _modules() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts.pop()
        if parts[-1] == "__main__":
            continue
        names.append(".".join(parts))
    return names


def _imports(path: Path) -> set[str]:
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module.split(".")[0])
    return found


@pytest.mark.parametrize("layer", sorted(PURE))
def test_pure_layers_import_no_io_loop_or_clock(layer: str) -> None:
    root = PACKAGE / layer
    files = [root] if root.suffix == ".py" else sorted(root.rglob("*.py"))
    assert files, f"{layer} has no files"
    for path in files:
        forbidden = _imports(path) & PURE[layer]
        assert not forbidden, f"{path.relative_to(PACKAGE)} imports {sorted(forbidden)}"


def test_the_hot_path_modules_do_not_import_pydantic_or_yourdfpy() -> None:
    for rel in (
        "robot.py",
        "backends/mock.py",
        "backends/base.py",
        "backends/clock.py",
        "description/kinematics.py",
        "publish/state_encoder.py",
        "publish/envelope.py",
    ):
        forbidden = _imports(PACKAGE / rel) & {"pydantic", "yourdfpy", "xacro"}
        assert not forbidden, f"{rel} imports {sorted(forbidden)}"


def test_every_module_imports_on_its_own_in_a_fresh_interpreter() -> None:
    modules = _modules()
    assert len(modules) > 20
    script = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module(name)\n"
    # one interpreter per module would catch order-dependent cycles best but costs seconds each;
    # importing in reverse order in one fresh interpreter still starts every package from a leaf
    for order in (modules, list(reversed(modules))):
        done = subprocess.run(
            [sys.executable, "-c", script, *order], capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 0, done.stderr


def test_public_names_are_listed_in_all() -> None:
    import urdaemon
    import urdaemon.control
    import urdaemon.description

    for module in (urdaemon, urdaemon.control, urdaemon.description):
        assert module.__all__, module.__name__
        for name in module.__all__:
            assert hasattr(module, name), f"{module.__name__}.__all__ lists missing {name}"
