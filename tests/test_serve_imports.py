"""The serve process carries only what serving needs (issue 15): its imports, its Zenoh session.

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

from urdaemon.cell.zenoh_options import ZenohOptions
from urdaemon.publish.session_config import serve_config

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


SHM_PROBE = """
import asyncio, json, socket, sys
import zenoh
from urdaemon.cell.zenoh_options import ZenohOptions
from urdaemon.publish.node import ZenohNode
from urdaemon.publish.session_config import zenoh_config

def shm_resident_kib():  # KiB resident in Zenoh's shared-memory mappings (/dev/shm/*.zenoh)
    found, name = {}, None
    with open("/proc/self/smaps") as smaps:
        for line in smaps:
            fields = line.split()
            if fields[0].endswith(":"):
                if name is not None and fields[0] == "Rss:":
                    found[name] = found.get(name, 0) + int(fields[1])
            else:
                name = fields[-1] if fields[-1].endswith(".zenoh") else None
    return found

async def main():
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{sock.getsockname()[1]}"
    loop = asyncio.get_running_loop()
    node = ZenohNode(ZenohOptions(listen=(endpoint,)), loop)
    node.queryable("probe/big", lambda query: query.reply("probe/big", bytes(64 * 1024)), max_bytes=None)
    client = zenoh.open(zenoh_config("peer", [], [endpoint]))  # a client as any: shared memory on
    try:
        replies = await loop.run_in_executor(None, lambda: list(client.get("probe/big", timeout=10.0)))
        sizes = [len(reply.ok.payload.to_bytes()) for reply in replies if reply.ok is not None]
    finally:
        client.close()
        node.close()
    print(json.dumps({"sizes": sizes, "shm": shm_resident_kib()}))

asyncio.run(main())
"""


def test_serving_a_large_reply_maps_no_shared_memory_pool() -> None:
    """Reproduction: with Zenoh's default shared memory, the daemon's first reply of 3 KiB or more
    to a peer on this host (a client asking for the URDF) mapped a 16 MiB pool, resident from
    then on (86.6 -> 70 MiB VmRSS of serve without it). A fresh interpreter opens the daemon's
    session, answers one 64 KiB query from a default client, and sums what is resident in its
    ``*.zenoh`` mappings (the client's own probing segments are 12 KiB each)."""
    done = subprocess.run(
        [sys.executable, "-c", SHM_PROBE], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["sizes"] == [64 * 1024]  # the reply really went through
    assert sum(result["shm"].values()) < 1024, result["shm"]


def test_the_daemon_session_keeps_what_the_cell_file_sets() -> None:
    """Shared memory off must leave the cell's mode, endpoints, scouting and transport as given."""
    options = ZenohOptions(
        mode="router",  # a mode that both listens and dials (a client daemon listens nowhere)
        connect=("tcp/127.0.0.1:7448",),
        multicast_scouting=True,
        low_latency=True,
    )
    conf = serve_config(options, ("tcp/127.0.0.1:7449",))
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7448"]
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7449"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is True
    assert json.loads(conf.get_json("transport/unicast/lowlatency")) is True
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is False


def test_the_daemon_session_queues_batches_a_busy_send_thread_needs() -> None:
    """Zenoh's 2 queued batches dropped 1-2 % of the state streams under CPU load (docs/operating.md,
    "Busy PCs"): the daemon's session queues 16 for the priorities it publishes at, and only those."""
    conf = serve_config(ZenohOptions(), ("tcp/127.0.0.1:7449",))
    sizes = json.loads(conf.get_json("transport/link/tx/queue/size"))
    assert {name: sizes[name] for name in ("real_time", "data")} == {"real_time": 16, "data": 16}
    assert sizes["background"] == 2
