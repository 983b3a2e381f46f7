"""One robot's runtime, by job: ``robot.py`` keeps supervision and the cycle and composes these.

- ``motion.py``: the robot's motion, owned once: whether motion may start (shutting down, freedrive,
  tool contact, a goal planned from rest), what ends it (``end``: one table of how), and stepped work
  planned in slices under the gate (``plan``);
- ``slicing.py``: stepped work (generators) in slices between robot cycles, one budget per loop;
- ``queries.py``: answering a query once, and the request tasks the runtime cancels at shutdown;
- ``status.py``: the status, IO and events messages;
- ``goal_events.py``: each goal's signing key, its feedback and result published, kept results;
- ``goals.py``: every kind of goal (trajectory, move, pose, linear) taken, planned, started, cancelled;
- ``pose_goals.py``: a pose goal's IK and a linear goal's plan, in steps;
- ``passthrough.py``: goals the robot interpolates itself;
- ``cell_goals.py``: trajectories started together on several robots;
- ``streaming.py``: streaming and freedrive commands;
- ``service_runner.py``: the service table's runner (publish/services.py declares the services);
- ``lease.py``, ``lease_keeper.py``: the command lease, decided and served.
"""
