"""URScript text on the primary interface (§2.4, §5.8): programs and commands as the daemon sends them.

``def_program`` / ``sec_program`` / ``headless_program`` build the text, ``encode_script`` the bytes sent;
``BLOCK_START`` / ``BLOCK_END`` are how the robot side finds a top-level block in the lines it reads.
"""

from __future__ import annotations

import enum
import re
from typing import Final

from urdaemon.errors import LocalProtocolError
from urdaemon.protocols.primary._wire import MAX_SCRIPT_BYTES, MAX_SCRIPT_NAME_LENGTH, PROTOCOL, local_error

__all__ = [
    "BLOCK_END",
    "BLOCK_START",
    "ControllerCommand",
    "def_program",
    "encode_script",
    "headless_program",
    "sec_program",
]

_NAME_PATTERN: Final = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # §2.4 step 5
# a top-level block opens with `def NAME():` / `sec NAME():` at column 0 and closes with `end` at column 0
BLOCK_START: Final = re.compile(r"(def|sec)[ \t]+([A-Za-z_]\w*)[ \t]*\([ \t]*\)[ \t]*:[ \t]*(#.*)?", re.ASCII)
BLOCK_END: Final = re.compile(r"end[ \t]*(#.*)?")


class ControllerCommand(enum.StrEnum):
    """Single-line controller commands, sent like a script (GUI-internal, undocumented); §2.4 step 6."""

    POWER_ON = "power on"
    POWER_OFF = "power off"
    BRAKE_RELEASE = "set robotmode run"
    UNLOCK_PROTECTIVE_STOP = "set unlock protective stop"
    STOP_PROGRAM = "stop program"


def _check_name(name: str) -> None:
    if not _NAME_PATTERN.fullmatch(name) or len(name) > MAX_SCRIPT_NAME_LENGTH:
        raise LocalProtocolError(
            f"primary: program name {name!r} is not [A-Za-z_][A-Za-z0-9_]* of at most "
            f"{MAX_SCRIPT_NAME_LENGTH} characters",
            protocol=PROTOCOL,
        )


def _indented(body: str, indent: str) -> str:
    lines = body.removesuffix("\n").split("\n") if body else []
    return "".join(f"{indent}{line}\n" for line in lines)


def def_program(name: str, body: str, indent: str = "  ") -> str:
    """``def NAME():``, the body indented, ``end``: a program replacing the running one (§2.4 step 2)."""
    _check_name(name)
    return f"def {name}():\n{_indented(body, indent)}end\n"


def sec_program(name: str, body: str, indent: str = "  ") -> str:
    """``sec NAME():``, the body indented, ``end``: a secondary program, no motion (§2.4 step 3)."""
    _check_name(name)
    return f"sec {name}():\n{_indented(body, indent)}end\n"


def headless_program(script: str, name: str = "externalControl") -> str:
    """Headless wrapping of the External Control script (§5.8): ``stop program``, ``def`` tab-indented."""
    return f"{ControllerCommand.STOP_PROGRAM}\n" + def_program(name, script, indent="\t")


def encode_script(text: str) -> bytes:
    """The bytes of ``text`` as the daemon sends it: ASCII, newline-terminated; LocalProtocolError if not."""
    if not text.endswith("\n"):
        text += "\n"  # §2.4 step 1: the controller runs only newline-terminated text
    try:
        data = text.encode("ascii")
    except UnicodeEncodeError as err:
        raise local_error(f"script is not ASCII at {err.start} (§2.4)") from err
    if len(data) > MAX_SCRIPT_BYTES:
        raise local_error(f"script of {len(data)} bytes > {MAX_SCRIPT_BYTES}")
    return data
