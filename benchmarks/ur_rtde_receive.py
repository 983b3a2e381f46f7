"""SDU's ur_rtde receiving one robot at 500 Hz in its own process, for benchmarks/control_loop.py.

    python benchmarks/ur_rtde_receive.py ADDRESS [VARIABLE ...]

``RTDEReceiveInterface(ADDRESS, 500.0, VARIABLES)`` (all of ur_rtde's default variables when none
are given); its own thread receives every package. Prints ``receiving`` once the first package is in,
reads ``actual_q`` once a second to show it keeps receiving, and ends on SIGINT or SIGTERM.
"""

from __future__ import annotations

import signal
import sys
import threading

import rtde_receive


def main() -> None:
    """Receive until told to stop."""
    address, *variables = sys.argv[1:]
    receiver = rtde_receive.RTDEReceiveInterface(address, 500.0, variables)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    receiver.getActualQ()
    print("receiving", flush=True)
    while not stop.wait(1.0):
        if not receiver.isConnected():
            print("ur_rtde lost the connection", file=sys.stderr, flush=True)
            sys.exit(1)
        receiver.getActualQ()
    receiver.disconnect()


if __name__ == "__main__":
    main()
