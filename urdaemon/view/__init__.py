"""``urdaemon view``: a live 3-D view of a cell in the browser (viser), with per-robot joint sliders,
jog buttons, a stop button and plots.

Files by job: ``feed.py`` the newest messages of each robot as Zenoh delivers them; ``control.py``
what the view sends a robot (enable, lease, joint stream, jog, disable), free of any GUI;
``scene.py`` the 3-D cell; ``panel.py`` one robot's controls; ``plots.py`` its joint plots;
``app.py`` the view's loops and ``running_view``; ``command.py`` the ``urdaemon view`` command;
``mockcell.py`` the mock cell ``--config`` starts in a child process.

Importing this package imports neither viser nor numpy: ``app.py`` and the GUI files do.
"""
