"""The ROS 2 message definitions the recorder's CDR channels name, as ``ros2msg`` schema text.

Facts, not code: the field lists of the standard interfaces as ROS 2 (Humble and later) defines them
in ``sensor_msgs``, ``geometry_msgs``, ``tf2_msgs``, ``std_msgs`` and ``builtin_interfaces`` (Apache
2.0; comments left out). A schema is the message's own definition followed by each type it uses, each
after a line of 80 ``=`` and ``MSG: <package>/<Type>``, the layout rosbag2's MCAP storage writes and
Foxglove and rosbags read.
"""

from __future__ import annotations

__all__ = ["JOINT_STATE", "POSE_STAMPED", "STRING", "TF_MESSAGE", "schema_text"]

_DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
    ),
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
}

_USES: dict[str, tuple[str, ...]] = {
    "std_msgs/Header": ("builtin_interfaces/Time",),
    "sensor_msgs/JointState": ("std_msgs/Header",),
    "geometry_msgs/Pose": ("geometry_msgs/Point", "geometry_msgs/Quaternion"),
    "geometry_msgs/PoseStamped": ("std_msgs/Header", "geometry_msgs/Pose"),
    "geometry_msgs/Transform": ("geometry_msgs/Vector3", "geometry_msgs/Quaternion"),
    "geometry_msgs/TransformStamped": ("std_msgs/Header", "geometry_msgs/Transform"),
    "tf2_msgs/TFMessage": ("geometry_msgs/TransformStamped",),
}

_SEPARATOR = "=" * 80


def _dependencies(name: str) -> list[str]:
    """Every type ``name`` uses, depth first, each once."""
    found: list[str] = []
    for used in _USES.get(name, ()):
        for dep in [used, *_dependencies(used)]:
            if dep not in found:
                found.append(dep)
    return found


def schema_text(name: str) -> str:
    """The ``ros2msg`` schema of ``package/Type``: its definition, then each type it uses."""
    name = name.replace("/msg/", "/")
    parts = [_DEFINITIONS[name]]
    for dep in _dependencies(name):
        parts.append(f"{_SEPARATOR}\nMSG: {dep}\n{_DEFINITIONS[dep]}")
    return "".join(parts)


JOINT_STATE = "sensor_msgs/msg/JointState"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STRING = "std_msgs/msg/String"
