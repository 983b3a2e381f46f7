"""What the page shows: its camera set from the server, world points projected through the camera the
page reports back, and a screenshot's pixels at those points (drawn or background).

The camera is set on the page's viser client (``ClientHandle.camera``); the page answers every
camera change with its own camera message (pose, vertical field of view, canvas size), and the
projection uses that answer, so it is the camera the page draws with. viser's camera follows
OpenCV's convention: x right, y down, z forward; the field of view is vertical.
"""

from __future__ import annotations

import asyncio
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["Camera", "Picture", "SeenCamera", "connected_client", "set_camera"]

Point = tuple[float, float, float]

CAMERA_REPORTS = 200
"""At most this many camera messages from the page while waiting for the one with our camera."""
REPORT_TIMEOUT_S = 30.0
"""...each of which must come within this long (a page under software WebGL on a busy machine)."""
DIFFERENT = 40
"""A pixel is not background when a colour channel differs from the background's by more than this."""
WINDOW = 3
"""Pixels are looked at in a (2·WINDOW+1)² square around a projected point."""


@dataclass(frozen=True)
class Camera:
    """A camera to set: where it is, the point it looks at, its up direction and vertical field of
    view (rad), in the world frame."""

    position: Point
    look_at: Point
    up: Point = (0.0, 0.0, 1.0)
    fov: float = math.radians(45.0)


@dataclass(frozen=True)
class SeenCamera:
    """The camera as the page reported it: ``wxyz`` and ``position`` of the camera in the world
    (``P_world = R·p_camera + t``), the vertical ``fov`` and the canvas size in pixels."""

    wxyz: npt.NDArray[np.float64]
    position: npt.NDArray[np.float64]
    look_at: npt.NDArray[np.float64]
    fov: float
    width: int
    height: int

    @classmethod
    def of(cls, camera: Any) -> SeenCamera:
        """A copy of a viser ``CameraHandle``'s state (it is replaced by the page's next message)."""
        return cls(
            np.array(camera.wxyz, dtype=np.float64),
            np.array(camera.position, dtype=np.float64),
            np.array(camera.look_at, dtype=np.float64),
            float(camera.fov),
            int(camera.image_width),
            int(camera.image_height),
        )

    def matches(self, camera: Camera, tol: float = 1e-3) -> bool:
        """Whether this is ``camera`` (position, look-at point, field of view)."""
        return (
            np.allclose(self.position, camera.position, atol=tol)
            and np.allclose(self.look_at, camera.look_at, atol=tol)
            and math.isclose(self.fov, camera.fov, abs_tol=tol)
        )

    def pixel(self, point: Sequence[float]) -> tuple[float, float]:
        """The canvas pixel (column, row) where world point ``point`` is drawn (it must be in front)."""
        w, x, y, z = self.wxyz
        rotation = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
        right, down, ahead = rotation.T @ (np.asarray(point, dtype=np.float64) - self.position)
        assert ahead > 0, f"{tuple(point)} is behind the camera"
        focal = 0.5 * self.height / math.tan(0.5 * self.fov)
        return 0.5 * self.width + focal * right / ahead, 0.5 * self.height + focal * down / ahead


async def connected_client(server: Any, timeout: float) -> Any:
    """The first page connected to viser ``server`` (a ``ClientHandle``; viser counts a page as
    connected once its first camera message came)."""
    loop = asyncio.get_running_loop()
    connected: asyncio.Future[Any] = loop.create_future()

    def connect(client: Any) -> None:
        if not connected.done():
            connected.set_result(client)

    server.on_client_connect(lambda client: loop.call_soon_threadsafe(connect, client))  # viser's thread
    return await asyncio.wait_for(connected, timeout)


async def set_camera(client: Any, camera: Camera) -> SeenCamera:
    """Set the page's camera to ``camera`` from the server; the camera the page then reports having
    (after at most ``CAMERA_REPORTS`` camera messages)."""
    loop = asyncio.get_running_loop()
    reports: asyncio.Queue[SeenCamera] = asyncio.Queue()
    handle = client.camera
    handle.on_update(lambda state: loop.call_soon_threadsafe(reports.put_nowait, SeenCamera.of(state)))
    handle.position = camera.position  # moves the look-at point along; set it next
    handle.look_at = camera.look_at
    handle.up_direction = camera.up
    handle.fov = camera.fov
    for _ in range(CAMERA_REPORTS):
        seen = await asyncio.wait_for(reports.get(), REPORT_TIMEOUT_S)
        if seen.matches(camera):
            return seen
    raise AssertionError(f"the page did not report the camera {camera} in {CAMERA_REPORTS} messages")


class Picture:
    """A screenshot (PNG bytes) of the page; ``background`` is its most common colour (the empty
    scene's), unless given."""

    def __init__(self, png: bytes, background: Sequence[int] | None = None) -> None:
        from PIL import Image

        with Image.open(io.BytesIO(png)) as image:
            self.rgb = np.asarray(image.convert("RGB"), dtype=np.int16)
        if background is None:
            colours, counts = np.unique(self.rgb.reshape(-1, 3), axis=0, return_counts=True)
            background = colours[int(np.argmax(counts))]
        self.background = np.asarray(background, dtype=np.int16)

    def drawn(self, pixel: tuple[float, float]) -> float:
        """The share of the pixels around ``pixel`` (column, row) that are not background."""
        height, width, _ = self.rgb.shape
        column, row = round(pixel[0]), round(pixel[1])
        assert WINDOW <= column < width - WINDOW, f"{pixel} is off the page"
        assert WINDOW <= row < height - WINDOW, f"{pixel} is off the page"
        window = self.rgb[row - WINDOW : row + WINDOW + 1, column - WINDOW : column + WINDOW + 1]
        differs = np.abs(window - self.background).max(axis=2) > DIFFERENT
        return float(differs.mean())
