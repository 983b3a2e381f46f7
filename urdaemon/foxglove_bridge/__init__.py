"""``urdaemon foxglove``: the cell live over Foxglove's WebSocket protocol (foxglove-sdk, the optional
``foxglove`` extra; nothing the daemon imports). By job: ``channel_plan.py`` which channels a cell gets and
the Zenoh key behind each (from the recorder's table, ``recording/channels.py``); ``recording/tf_tree.py`` the
cell's tf as one transform per URDF joint; ``bridge.py`` the running bridge (Zenoh samples handed to
a converter thread, Foxglove subscriptions turned into Zenoh ones); ``command.py`` the command.
"""

__all__: list[str] = []
