"""The 3-D cell in viser's scene: every link of the cell URDF at its world pose, whatever ``<visual>``
geometry the URDF gives drawn on it, the world frame, each robot's TCP frame, and a label plus a colour
over a robot that is disconnected or stopped.

Link poses come from the cell's forward kinematics of the robots' newest ``joint_states``
(``KinematicTree``, the daemon's own model of ``tf``), computed here at display rate: the daemon
computes no ``tf`` for a viewer. The TCP frame is the robot's tool link composed with its TCP offset
(the status's ``tcp``), so the view needs no ``tcp_pose``: that stream would cost the daemon the
TCP's kinematics, an encoding and a put every cycle. Every link is one scene node ``/cell/<link>``
placed in the world frame; its geometry hangs under it (with the visual's origin baked in), so
moving a link is one update.
A link without geometry shows small axes, so a URDF without any still shows every robot.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from urdaemon.description.frames import frame_of_pose
from urdaemon.description.kinematics import KinematicTree, quaternion_of

__all__ = ["PROBLEM_COLOR", "CellScene", "robot_of_link"]

PROBLEM_COLOR = (220, 40, 40)
"""The colour of a disconnected or stopped robot's links."""
DEFAULT_COLOR = (170, 180, 195)
"""Geometry without a material colour."""
LABEL_HEIGHT_M = 1.1
"""A robot's label floats this far above its base link."""
CAMERA_POSITION = (1.1, -1.8, 1.2)
CAMERA_LOOK_AT = (0.0, 0.0, 0.35)
"""Where a new page's camera starts: the cell seen from the front right, above the robots' bases."""


def robot_of_link(link: str, robots: Iterable[str]) -> str | None:
    """The robot whose link ``link`` is (its name is the link's prefix, ``<robot>_``), the longest such
    name when several match; None for the cell's own links (``world``)."""
    owners = [r for r in robots if link.startswith(f"{r}_")]
    return max(owners, key=len) if owners else None


class CellScene:
    """The cell's scene nodes in ``server`` (a ``viser.ViserServer``), built from the cell URDF
    ``urdf`` (a yourdfpy ``URDF`` with its scene graph) for ``robots``."""

    def __init__(self, server: Any, urdf: Any, robots: Sequence[str]) -> None:
        self.server = server
        self.tree = KinematicTree.from_urdf(urdf)
        self.robots = tuple(robots)
        self.link_robot = {link: robot_of_link(link, robots) for link in self.tree.links}
        self.frames: dict[str, Any] = {}
        """Link name -> its viser frame handle (placed in the world frame)."""
        self.meshes: dict[str | None, list[tuple[Any, tuple[int, int, int]]]] = {}
        """Robot (None: the cell's) -> its mesh handles with their own colours."""
        self.tcp_frames: dict[str, Any] = {}
        """Robot -> its TCP frame handle (a child of its tool link's node), once a status came."""
        self._tcp_shown: dict[str, tuple[str, tuple[float, ...]]] = {}
        self.labels: dict[str, Any] = {}
        self.problems: dict[str, str | None] = dict.fromkeys(robots)
        self._last: dict[str, float] | None = None
        server.initial_camera.position = CAMERA_POSITION
        server.initial_camera.look_at = CAMERA_LOOK_AT
        server.scene.add_frame("/world", axes_length=0.3, axes_radius=0.01)
        drawn = self._add_geometry(urdf)
        for link in self.tree.links:
            self.frames[link] = server.scene.add_frame(
                f"/cell/{link}", show_axes=link not in drawn, axes_length=0.06, axes_radius=0.004
            )
        for robot in robots:
            self.labels[robot] = server.scene.add_label(
                f"/cell/{self.base_link(robot)}/label",
                robot,
                position=(0.0, 0.0, LABEL_HEIGHT_M),
                anchor="bottom-center",
                visible=False,
            )

    def base_link(self, robot: str) -> str:
        """The robot's base link (``<robot>_base``, else its first link; the root without any)."""
        if f"{robot}_base" in self.link_robot:
            return f"{robot}_base"
        return next((link for link, r in self.link_robot.items() if r == robot), self.tree.root)

    def _add_geometry(self, urdf: Any) -> set[str]:
        """Every visual of the URDF as a mesh under its link's node; the links that have one."""
        scene = getattr(urdf, "scene", None)
        if scene is None:
            return set()
        parents = scene.graph.transforms.parents
        drawn: set[str] = set()
        for index, (name, mesh) in enumerate(scene.geometry.items()):
            link = parents.get(name)
            if link not in self.link_robot or not hasattr(mesh, "faces") or len(mesh.faces) == 0:
                continue
            placed = mesh.copy()
            placed.apply_transform(urdf.get_transform(name, link))
            color = _color_of(placed)
            handle = self.server.scene.add_mesh_simple(
                f"/cell/{link}/visual_{index}",
                np.asarray(placed.vertices, dtype=np.float32),
                np.asarray(placed.faces, dtype=np.uint32),
                color=color,
            )
            self.meshes.setdefault(self.link_robot[link], []).append((handle, color))
            drawn.add(link)
        return drawn

    def place(self, positions: Mapping[str, float]) -> bool:
        """Every link at its pose for the joints ``positions`` (prefixed names); False when nothing
        changed since the last call (nothing sent)."""
        if positions == self._last:
            return False
        self._last = dict(positions)
        for link, (x, y, z, qx, qy, qz, qw) in self.tree.link_poses(positions):
            frame = self.frames[link]
            frame.position = (x, y, z)
            frame.wxyz = (qw, qx, qy, qz)
        return True

    def set_tcp(self, robot: str, tcp: object) -> None:
        """The robot's TCP frame at the status's ``tcp`` (``link``, and ``pose``: x, y, z, rx, ry, rz in
        that link's frame): a child of the link's node, so it follows the link's pose as drawn; no
        frame before a status names the link."""
        if not isinstance(tcp, Mapping):
            return
        link, pose = str(tcp.get("link", "")), tcp.get("pose")
        if link not in self.frames or not isinstance(pose, list) or len(pose) != 6:
            return
        key = (link, tuple(float(v) for v in pose))
        if self._tcp_shown.get(robot) == key:
            return
        handle = self.tcp_frames.get(robot)
        if handle is not None and self._tcp_shown[robot][0] != link:
            handle.remove()
            handle = None
        if handle is None:
            handle = self.tcp_frames[robot] = self.server.scene.add_frame(
                f"/cell/{link}/tcp", axes_length=0.1, axes_radius=0.006
            )
        r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z = frame_of_pose(key[1])
        qx, qy, qz, qw = quaternion_of(r00, r01, r02, r10, r11, r12, r20, r21, r22)
        handle.position = (x, y, z)
        handle.wxyz = (qw, qx, qy, qz)
        self._tcp_shown[robot] = key

    def set_problem(self, robot: str, problem: str | None) -> None:
        """Show ``problem`` (e.g. ``disconnected``) over the robot and colour it; None: clear both."""
        if self.problems.get(robot) == problem:
            return
        self.problems[robot] = problem
        label = self.labels[robot]
        if problem is not None:
            label.text = f"{robot}: {problem}"
        label.visible = problem is not None
        for handle, color in self.meshes.get(robot, ()):
            handle.color = color if problem is None else PROBLEM_COLOR


def _color_of(mesh: Any) -> tuple[int, int, int]:
    """The mesh's material colour (yourdfpy paints the URDF's ``<material>`` on its faces)."""
    visual = getattr(mesh, "visual", None)
    colors = getattr(visual, "face_colors", None) if getattr(visual, "kind", None) == "face" else None
    if colors is None or len(colors) == 0:
        return DEFAULT_COLOR
    red, green, blue = (int(c) for c in colors[0][:3])
    return (red, green, blue)
