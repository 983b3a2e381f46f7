"""``urdaemon replay``: a recording driven through a cell again, or published again (docs/replay.md).

``goal_plan.py`` turns recorded joint states into goals (pure), ``source.py`` reads what a replay needs of
a recording, ``drive.py`` sends the goals, ``publish.py`` publishes the recording, ``command.py`` is
the command.
"""
