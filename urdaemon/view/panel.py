"""One robot's controls in the page, as rqt_joint_trajectory_controller has them: a folder named after
the robot with an ``enable`` switch, one slider per joint (labelled with the joint's name, within its
URDF limits), a ``stop`` button, jog buttons, the robot's status and last events, and its plots.

viser calls the widgets' callbacks on its own threads; every command goes to the asyncio loop
(``run_coroutine_threadsafe`` / ``call_soon_threadsafe``) where ``RobotControl`` acts. The display
task calls ``show`` on the loop. While disabled the sliders follow the robot and cannot be moved;
while enabled they are the joint stream's targets.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Iterator, Sequence
from concurrent.futures import Future
from typing import Any

from urdaemon.view.control import RobotControl, jog_twist
from urdaemon.view.feed import RobotFeed
from urdaemon.view.plots import JointPlots

__all__ = ["JOG_ROTATE", "JOG_TRANSLATE", "RobotPanel", "status_markdown"]

JOG_TRANSLATE = ("+x", "-x", "+y", "-y", "+z", "-z")
JOG_ROTATE = ("+rx", "-rx", "+ry", "-ry", "+rz", "-rz")
JOG_SPEEDS = (0.01, 0.25, 0.01, 0.05)
"""The jog speed slider: min, max, step, initial (m/s; rotations turn 5 rad/s per m/s)."""
TEXT_S = 0.25
"""The status and events texts are sent to the page at most this often (4 Hz): on a loaded machine
they change with every stream sample the daemon replaces, and each change re-renders markdown in the
page."""
SLIDER_STEP = 0.001


class RobotPanel:
    """The controls of robot ``feed.name`` in ``gui`` (a viser ``GuiApi``)."""

    def __init__(
        self,
        gui: Any,
        loop: asyncio.AbstractEventLoop,
        feed: RobotFeed,
        control: RobotControl,
        joints: Sequence[tuple[str, float, float]],
    ) -> None:
        self.loop = loop
        self.feed = feed
        self.control = control
        self.joint_names = tuple(name for name, _, _ in joints)
        self._following = False
        self._text_at = float("-inf")
        self.pending: list[Future[Any]] = []
        """Commands handed to the loop from the page (a test may wait on them)."""
        with gui.add_folder(feed.name):
            self.status = gui.add_markdown("waiting for the robot...")
            self.enable = gui.add_checkbox("enable", False, hint="take the lease and stream the sliders")
            self.stop = gui.add_button("stop", color="red", hint="stop the robot (always works)")
            self.sliders = {
                label: gui.add_slider(label, low, high, SLIDER_STEP, _within(0.0, low, high), disabled=True)
                for label, low, high in ((_short(name, feed.name), lo, hi) for name, lo, hi in joints)
            }
            # viser's button groups cannot be disabled: they are shown only while enabled
            self.jog_translate = gui.add_button_group("jog", JOG_TRANSLATE, visible=False)
            self.jog_rotate = gui.add_button_group("turn", JOG_ROTATE, visible=False)
            self.jog_frame = gui.add_dropdown("jog frame", ("base", "tool"), initial_value="base")
            low, high, step, initial = JOG_SPEEDS
            self.jog_speed = gui.add_slider("jog speed (m/s)", low, high, step, initial)
            self.events = gui.add_markdown("")
            self.plots = JointPlots(gui, tuple(self.sliders))
        self._wire()
        control.on_change = self.show_control

    def _wire(self) -> None:
        self.enable.on_update(self._on_enable)
        self.stop.on_click(lambda _: self._submit(self.control.stop()))
        for index, slider in enumerate(self.sliders.values()):
            slider.on_update(lambda event, i=index: self._on_slider(i, event.target.value))
        self.jog_translate.on_click(lambda event: self._on_jog(event.target.value))
        self.jog_rotate.on_click(lambda event: self._on_jog(event.target.value))

    # ------------------------------------------------------------------ from viser's threads

    def _on_enable(self, _: Any) -> None:
        if self._following:
            return
        wanted = bool(self.enable.value)
        if wanted and not self.control.enabled:
            self._submit(self.control.enable())
        elif not wanted and self.control.enabled:
            self._submit(self.control.disable())

    def _on_slider(self, index: int, value: float) -> None:
        if not self._following:
            self.loop.call_soon_threadsafe(self.control.set_target, index, float(value))

    def _on_jog(self, option: str) -> None:
        axis, sign = option[1:], 1 if option.startswith("+") else -1
        linear, angular = jog_twist(axis, sign, float(self.jog_speed.value))
        self._submit(self.control.jog(linear, angular, str(self.jog_frame.value)))

    def _submit(self, command: Any) -> None:
        future = asyncio.run_coroutine_threadsafe(command, self.loop)
        self.pending = [f for f in self.pending if not f.done()]
        self.pending.append(future)

    # ------------------------------------------------------------------ on the loop

    @contextlib.contextmanager
    def _setting(self) -> Iterator[None]:
        """Widgets set from here, not by a user: their callbacks (run at once) do nothing."""
        self._following = True
        try:
            yield
        finally:
            self._following = False

    def show_control(self) -> None:
        """Show whether the robot is enabled: the sliders at the targets (movable) or read-only."""
        control = self.control
        enabled = control.enabled
        with self._setting():
            self.enable.value = enabled
            if enabled and control.targets is not None:
                for slider, target in zip(self.sliders.values(), control.targets, strict=False):
                    slider.value = _within(target, slider.min, slider.max)
            for slider in self.sliders.values():
                slider.disabled = not enabled
            self.jog_translate.visible = self.jog_rotate.visible = enabled

    def show(self, now: float) -> None:
        """The display task's update: status and events (every ``TEXT_S``), plots, and sliders following
        a disabled robot."""
        sample = self.feed.joints()
        self.plots.record(sample)
        self.plots.redraw(now)
        if now - self._text_at >= TEXT_S:
            self._text_at = now
            _set_content(
                self.status,
                status_markdown(
                    self.feed.status(), self.feed.stale(now), self.control.refusal, self.feed.replaced
                ),
            )
            _set_content(
                self.events, "\n".join(f"- {line}" for line in self.feed.last_events()) or "(no events yet)"
            )
        if sample is not None and not self.control.enabled:
            with self._setting():
                for slider, position in zip(self.sliders.values(), sample.positions, strict=False):
                    if math.isfinite(position):
                        slider.value = _within(position, slider.min, slider.max)


def status_markdown(status: dict[str, Any] | None, stale: bool, refusal: str, replaced: int = 0) -> str:
    """The robot's state in a few lines of markdown (``replaced``: stream samples the daemon replaced
    by newer ones before reading them)."""
    lines = []
    if stale:
        lines.append("**disconnected** (no joint_states)")
    if status is not None:
        reason = f" ({status['reason']})" if status.get("reason") else ""
        lines.append(f"lifecycle: **{status.get('lifecycle', '?')}**{reason}")
        scaling = status.get("speed_scaling")
        shown = f"{100 * scaling:.0f} %" if isinstance(scaling, int | float) else "?"
        lines.append(f"speed scaling: {shown}; active goal: {status.get('active_goal') or 'none'}")
        lease = status.get("lease")
        holder = lease.get("holder") if isinstance(lease, dict) else None
        lines.append(f"lease: {holder or 'free'}")
    if replaced:
        lines.append(f"stream samples replaced by newer ones: {replaced}")
    if refusal:
        lines.append(f"refused: {refusal}")
    return "  \n".join(lines) or "waiting for the robot..."


def problem_of(status: dict[str, Any] | None, stale: bool) -> str | None:
    """What the scene shows over a robot: ``disconnected``, a stop, or None when it is fine."""
    if stale:
        return "disconnected"
    lifecycle = None if status is None else status.get("lifecycle")
    if lifecycle in ("disconnected", "connecting", "recovering", "protective_stop", "emergency_stop"):
        return str(lifecycle).replace("_", " ")
    return None


def _short(joint: str, robot: str) -> str:
    """The joint's name without the robot's prefix (``alice_shoulder_pan_joint``: ``shoulder_pan_joint``)."""
    prefix = f"{robot}_"
    return joint[len(prefix) :] if joint.startswith(prefix) else joint


def _set_content(markdown: Any, content: str) -> None:
    """Send markdown to the page only when it changed."""
    if markdown.content != content:
        markdown.content = content


def _within(value: float, low: float, high: float) -> float:
    return min(max(float(value), float(low)), float(high))
