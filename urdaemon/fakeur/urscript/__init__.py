"""The fake controller's URScript interpreter: compile a program once, then step it once per cycle.

``compile_program(text, series, version)`` checks and compiles (raising :class:`ScriptCompileError`
with line and column); ``program.start(host)`` gives a :class:`ScriptRun` the controller steps.
Importing this package registers every builtin library into ``runtime.BUILTINS``.
"""

from __future__ import annotations

import importlib

from urdaemon.fakeur.urscript.compiler import Program, compile_program
from urdaemon.fakeur.urscript.runtime import ScriptCompileError, ScriptRun, ScriptRuntimeError

__all__ = ["Program", "ScriptCompileError", "ScriptRun", "ScriptRuntimeError", "compile_program"]

_LIBRARIES = (
    "lib_core",
    "lib_motion",
    "lib_state",
    "lib_dynamics",
    "lib_io",
    "lib_ports",
    "lib_settings",
    "lib_sockets",
    "lib_config",
    "lib_unsimulated",  # last: stands in only for what no library above implements
)

for _library in _LIBRARIES:
    try:
        importlib.import_module(f"{__name__}.{_library}")
    except ModuleNotFoundError as _missing:  # a library not written yet: its builtins are "not simulated"
        if _missing.name != f"{__name__}.{_library}":
            raise
