"""The ``urdaemon`` command: serve, check, urdf, echo, move, teleop, cancel, stop, service, dashboard,
lease, view.

Client commands that command a robot (``move``, ``teleop``, ``cancel``, ``service``, ``dashboard``)
acquire its command lease first and release it when they exit; ``stop`` never needs it; ``lease``
shows or takes it over. Each connects with ``--connect`` and, for TLS, ``--zenoh-config``. The exit
codes are exit_codes.py's.

Files by job: ``entry.py`` the console script (``main``: parse, log, dispatch); ``parser.py`` every
command's arguments and help texts (and ``TOOL_MODULES``, the packages that add commands of their
own); ``cell_commands.py`` serve, check, urdf and fake-robot; ``connect.py`` what a client command
connects to, checked; ``client_commands.py`` echo, service, dashboard, cancel, stop, lease and
teleop; ``move_command.py`` move; ``calibration_command.py`` calibration. How a command that runs
until stopped is stopped by signals is stop_signals.py's, shared with the fake robot and the router.
"""

from __future__ import annotations

from urdaemon.cli.entry import main

__all__ = ["main"]
