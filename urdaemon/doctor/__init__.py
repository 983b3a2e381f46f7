"""``urdaemon doctor``: everything that decides whether a cell runs well, each check with a verdict
and what to do (docs/doctor.md).

``checks.py`` decides (pure: facts in, checks out); ``host.py`` and ``report.py`` gather on the
daemon's side, answered as the robot service ``doctor`` (publish/services.py), with the controller's
facts from the backend (``Backend.doctor_facts``; backends/ur/diagnosis.py). The command, which asks
every robot and prints the table, is a client: introspect/doctor_command.py (the daemon's side never
reaches the client's).
"""

__all__: list[str] = []
