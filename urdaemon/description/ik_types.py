"""What inverse kinematics takes and gives, for UR arms (ik.py) and URDF chains (chain.py): six joint
values, any six numbers, and work done in bounded steps."""

from __future__ import annotations

from collections.abc import Generator, Sequence
from typing import TYPE_CHECKING, TypeAlias, TypeVar

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

__all__ = ["Joints", "Steps", "Vector", "run_steps"]

Joints = tuple[float, float, float, float, float, float]
if TYPE_CHECKING:
    Vector: TypeAlias = Sequence[float] | NDArray[np.float64]
else:
    Vector = Sequence[float]
"""What ``UrKinematics``' public methods accept for joints, poses and twists: any 6 numbers (list,
tuple, array).

numpy is imported only by its ``jacobian`` and ``joint_velocity`` (the fake's numpy results): the serve
process uses the rest and must not load it."""

_T = TypeVar("_T")
Steps: TypeAlias = Generator[None, None, _T]
"""Work in bounded chunks: a generator that yields between them and returns the answer."""


def run_steps(steps: Generator[None, None, _T]) -> _T:
    """Run ``steps`` (``nearest_steps`` and the like) to the end at once; what it returns."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value  # type: ignore[no-any-return]
