"""The serve process imports only what serving needs (issue 15).

Reproduction: before the ElementTree reader, ``urdaemon.daemon`` imported yourdfpy at module load
and ``describe_cell`` parsed the cell with it, pulling trimesh, scipy and networkx (~110 MiB RSS,
~0.5 s) into every serve process. Before the plain-float origins, ``urdaemon.description`` imported
the IK (numpy) at package load and built the URDF's joint origins with numpy 4x4 products, so
numpy (~12 MiB RSS) was loaded too. A fresh interpreter builds the dual_robot_mock cell's
description, backends and forward kinematics the way serve does and reports which heavy modules
got loaded.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("yourdfpy", "trimesh", "scipy", "networkx", "numpy")

PROBE = """
import json, sys
from urdaemon.cell import load_cell
from urdaemon.daemon import describe_cell, make_backend
from urdaemon.description import DhKinematics, robot_dh
import urdaemon.cli, urdaemon.robot
cell = load_cell(sys.argv[1])
description = describe_cell(cell)
assert description.limits and description.tree.links
for robot in cell.robots:
    make_backend(robot, description.limits[robot.name], None, cell.cell)
    DhKinematics(robot_dh(robot)).tool_pose([0.0] * 6)
description.tree.link_poses({})
print(json.dumps([m for m in sys.argv[2:] if m in sys.modules]))
"""


def test_building_the_cell_loads_no_geometry_libraries_nor_numpy() -> None:
    config = ROOT / "configs" / "dual_robot_mock.yaml"
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(config), *HEAVY],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
