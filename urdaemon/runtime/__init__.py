"""One robot's runtime, by job: ``robot.py`` keeps supervision and the cycle and composes these.

- ``gate.py``: whether motion may start (shutting down, freedrive, tool contact, planning interrupted);
- ``queries.py``: answering a query once, and the request tasks the runtime cancels at shutdown;
- ``slicing.py``: long work (decode, check, plan, encode, free) in slices between robot cycles;
- ``status.py``: the status, IO and events messages;
- ``goals.py``: trajectory and move goals, cancel, goal events and results;
- ``passthrough.py``: goals the robot interpolates itself;
- ``commands.py``: streaming and freedrive commands;
- ``services.py``: the service table's runner (publish/services.py declares the services).
"""
