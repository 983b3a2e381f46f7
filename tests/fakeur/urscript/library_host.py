"""What the URScript library tests share: a script host on a powered fake arm, small scripts run on it
cycle by cycle as the controller runs them, and builtins called as a compiled program calls them."""

from __future__ import annotations

from typing import Any, Final

from urdaemon.description.urmodels import load_ur_model
from urdaemon.fakeur.fake_arm import FakeArm
from urdaemon.fakeur.urscript import ScriptRun, compile_program
from urdaemon.fakeur.urscript.runtime import BUILTINS
from urdaemon.fakeur.urscript.script_host import ScriptHost

__all__ = ["DT", "call_builtin", "make_host", "run_script"]

DT: Final = 0.002
"""s: the e-Series controller cycle."""


def make_host(model_name: str = "ur10e", *, playing: bool = False, **kwargs: Any) -> ScriptHost:
    """A script host (``kwargs`` to ``ScriptHost``) on a powered ``model_name`` arm, its program playing
    if ``playing``."""
    model = load_ur_model(model_name)
    arm = FakeArm(model, model.dh, powered=True)
    if playing:
        arm.start_program()
    return ScriptHost(arm, step_time=DT, **kwargs)


def run_script(host: ScriptHost, text: str, cycles: int = 50) -> ScriptRun:
    """Run ``text``, compiled for the host's controller version, to its end: each cycle the program
    steps, then the arm. Fails unless it ends within ``cycles`` cycles."""
    run = compile_program(text, series="e", version=host.version).start(host)
    for _ in range(cycles):
        if run.done:
            break
        run.step()
        host.arm.step(DT)
    assert run.done
    return run


def call_builtin(name: str, host: ScriptHost, *args: Any) -> Any:
    """Call builtin ``name`` as a compiled program does: the host, then the manual's arguments in order."""
    return BUILTINS[name].function(host, *args)
