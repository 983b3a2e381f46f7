"""The bridge's channels are the recorder's table read for a cell's robots: every recorded key
expression made concrete per robot, each with the topic and schema ``kind_of`` gives, and the URDF."""

from __future__ import annotations

import pytest

from urdaemon.foxglove_bridge.channel_plan import channel_plan
from urdaemon.recording.channels import DESCRIPTION_TOPIC, KINDS, ROBOT_DESCRIPTION, kind_of, recorded_keys

ROBOT_KINDS = ("joint_states", "tcp_pose", "status", "io", "events", "servo_command")


@pytest.mark.parametrize(
    ("topic", "key_expr", "schema"),
    [
        ("/c/alice/joint_states", "c/alice/joint_states", "sensor_msgs/msg/JointState"),
        ("/c/bob/tcp_pose", "c/bob/tcp_pose", "geometry_msgs/msg/PoseStamped"),
        ("/c/alice/goal/feedback", "c/alice/goal/*/feedback", KINDS["goal_feedback"].schema.name),
        ("/c/bob/goal/result", "c/bob/goal/*/result", KINDS["goal_result"].schema.name),
        ("/c/goal/result", "c/goal/*/result", KINDS["cell_goal_result"].schema.name),
        ("/c/tf", "c/tf", "tf2_msgs/msg/TFMessage"),
        ("/robot_description", None, "std_msgs/msg/String"),
    ],
)
def test_a_channel_of_the_plan(topic: str, key_expr: str | None, schema: str) -> None:
    plans = {p.topic: p for p in channel_plan("c", ["alice", "bob"])}
    plan = plans[topic]
    assert plan.key_expr == key_expr
    assert plan.schema.name == schema


def test_the_plan_covers_every_recorded_key_for_every_robot_once() -> None:
    robots = ["alice", "bob", "carol"]
    plans = channel_plan("c", robots)
    topics = [p.topic for p in plans]
    assert len(topics) == len(set(topics))
    per_robot = len(ROBOT_KINDS) + 2  # and the goal feedback and result
    cell_wide = len(recorded_keys("c")) - len(ROBOT_KINDS) - 2  # the cell goal's result, tf
    assert len(plans) == per_robot * len(robots) + cell_wide + 1  # and the URDF
    for plan in plans:
        if plan.key_expr is None:
            assert plan.topic == DESCRIPTION_TOPIC
            assert plan.schema == ROBOT_DESCRIPTION
            continue
        where = kind_of(plan.key_expr.replace("*", "g1"))
        assert where is not None
        assert (where.topic, where.kind) == (plan.topic, plan.kind)
        assert plan.schema == where.kind.schema
        assert plan.message_encoding == where.kind.message_encoding


def test_a_cell_without_robots_still_has_its_tf_goal_result_and_urdf() -> None:
    assert [p.topic for p in channel_plan("c", [])] == ["/c/goal/result", "/c/tf", "/robot_description"]
