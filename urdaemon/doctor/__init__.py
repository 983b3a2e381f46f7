"""``urdaemon doctor``: everything that decides whether a cell runs well, each check with a verdict
and what to do (docs/doctor.md).

``checks.py`` decides (pure: facts in, checks out); ``host.py`` and ``report.py`` gather on the
daemon's side, answered as the robot service ``doctor`` (publish/services.py), with the controller's
facts from the backend (``Backend.doctor_facts``; backends/ur/diagnosis.py); ``command.py`` is the
command, which asks every robot and prints the table.
"""

__all__: list[str] = []
