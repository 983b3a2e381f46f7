"""The asyncio Python API for programs that talk to a running urdaemon over Zenoh.

::

    async with await Client.connect("tcp/127.0.0.1:7447") as client:
        alice = await client.robot("alice")
        goal = await alice.move([0, -1.57, 1.57, -1.57, -1.57, 0], duration=3.0)
        async for feedback in goal.feedback():
            print(feedback["progress"])
        result = await goal.result()

Commanding a robot needs its command lease (docs/security.md): the first goal, cancel or commanding
service call of a ``RobotClient`` acquires it transparently (``LeaseHeld`` when another client holds
it), and ``Client.close()`` releases it. Once the lease ended without this client's release (another
client took it over, or it was lost), commands raise ``LeaseHeld`` until the program calls
``ensure_lease()`` again; an event saying so ends it only once the daemon confirms it. Stream commands
(``stream_positions``, ``stream_velocities``, ``freedrive``) are plain publications that never wait:
call ``await robot.ensure_lease()`` once before the first, as a ur_rtde program opens its control
interface before ``servoJ``. ``stop`` never needs the lease.

A goal's feedback and result are taken only when they carry the signature, under the key the accepting
reply gave this client, of the message and of the key it arrived on: another session can publish on a
goal's keys (or re-publish the daemon's signed feedback as a result), but what it publishes is dropped
and counted (``GoalHandle.forged``).

The package by job: ``session.py`` (the Zenoh session: queries, subscriptions, what ends with it),
``cell_connection.py`` (``Client``: connecting, finding robots, the cell's stop and URDF, the leases),
``robot_client.py`` (``RobotClient``, ``GoalHandle``), ``goal_messages.py`` (each goal's signed
messages routed to it), ``command_lease.py`` (``Lease``), ``cell_trajectory.py`` (a cell goal:
``send_cell_trajectory``, ``CellGoalHandle``).
"""

from __future__ import annotations

from urdaemon.client.cell_connection import DEFAULT_ENDPOINT, Client, NoSuchRobot
from urdaemon.client.cell_trajectory import CellGoalHandle, send_cell_trajectory
from urdaemon.client.command_lease import Lease, LeaseHeld, default_holder
from urdaemon.client.robot_client import GoalHandle, RobotClient
from urdaemon.client.session import NoSuchService, Received, Subscription, zenoh_message

__all__ = [
    "DEFAULT_ENDPOINT",
    "CellGoalHandle",
    "Client",
    "GoalHandle",
    "Lease",
    "LeaseHeld",
    "NoSuchRobot",
    "NoSuchService",
    "Received",
    "RobotClient",
    "Subscription",
    "default_holder",
    "send_cell_trajectory",
    "zenoh_message",
]
