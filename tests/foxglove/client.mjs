// An independent Foxglove WebSocket client (@foxglove/ws-protocol, `ws`) that judges `urdaemon
// foxglove`: it checks the channels advertised and their schema names, decodes CDR with
// @foxglove/rosmsg + @foxglove/rosmsg2-serialization (never urdaemon's own decoder), and follows one
// robot's joint states through a move that the Python test sends.
//
// Usage: node client.mjs '<json>' with {url, cell, robot, target: [rad...], tolerance, timeoutMs}.
// Standard output, one line each: "ready <json>" once it has the robot's joint states (the test
// then sends the move), then "ok <json>" (exit 0) or "fail <reason>" (exit 1).

import wsProtocol from "@foxglove/ws-protocol";
import rosmsg from "@foxglove/rosmsg";
import serialization from "@foxglove/rosmsg2-serialization";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol; // CommonJS packages: their exports come as one object
const { parse } = rosmsg;
const { MessageReader } = serialization;

const args = JSON.parse(process.argv[2]);
const { url, cell, robot, target, tolerance, timeoutMs } = args;
const JOINTS = `/${cell}/${robot}/joint_states`;
const TF = `/${cell}/tf`;
const DESCRIPTION = "/robot_description";
const EXPECTED = {
  [JOINTS]: "sensor_msgs/msg/JointState",
  [TF]: "tf2_msgs/msg/TFMessage",
  [DESCRIPTION]: "std_msgs/msg/String",
};
const SLACK = 1e-3; // rad: how far the distance to the target may grow back between two samples

function finish(ok, detail) {
  console.log(ok ? `ok ${JSON.stringify(detail)}` : `fail ${detail}`);
  process.exit(ok ? 0 : 1);
}
setTimeout(() => finish(false, `not done within ${timeoutMs} ms: ${JSON.stringify(summary())}`), timeoutMs);

// foxglove-sdk's server accepts only the protocol's new name, "foxglove.sdk.v1" (the same protocol as
// "foxglove.websocket.v1", which ws-protocol names): the client offers both and leaves the choice to
// the handshake.
const client = new FoxgloveClient({
  ws: new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const readers = new Map(); // subscription id -> [topic, MessageReader]
const advertised = new Map(); // topic -> schemaName
const state = {
  samples: 0,
  start: undefined, // distance to the target when the test was told "ready"
  distances: [],
  tfMessages: 0,
  parents: new Set(),
  children: new Set(),
  description: undefined,
  parameter: undefined,
  names: undefined,
};

function summary() {
  return {
    advertised: Object.fromEntries(advertised),
    samples: state.samples,
    start: state.start,
    last: state.distances.at(-1),
    moving: state.distances.filter((d) => d < state.start - 0.01 && d > tolerance).length,
    tfMessages: state.tfMessages,
    parents: [...state.parents].sort(),
    descriptionBytes: state.description?.length,
    parameterBytes: state.parameter?.length,
  };
}

function distance(position) {
  let worst = 0;
  for (let i = 0; i < target.length; i++) worst = Math.max(worst, Math.abs(position[i] - target[i]));
  return worst;
}

client.on("error", (err) => finish(false, `client error: ${err}`));
client.on("close", () => finish(false, "the server closed the connection"));
client.on("serverInfo", (info) => {
  if (!info.capabilities.includes("parameters")) finish(false, `no parameters capability: ${info.capabilities}`);
  client.getParameters(["/robot_description"], "urdf");
});
client.on("parameterValues", ({ parameters }) => {
  for (const p of parameters) if (p.name === "/robot_description") state.parameter = p.value;
});
client.on("advertise", (channels) => {
  for (const channel of channels) {
    advertised.set(channel.topic, channel.schemaName);
    const expected = EXPECTED[channel.topic];
    if (expected === undefined) continue;
    if (channel.schemaName !== expected) finish(false, `${channel.topic}: schema ${channel.schemaName}, not ${expected}`);
    if (channel.encoding !== "cdr" || channel.schemaEncoding !== "ros2msg")
      finish(false, `${channel.topic}: ${channel.encoding}/${channel.schemaEncoding}, not cdr/ros2msg`);
    const reader = new MessageReader(parse(channel.schema, { ros2: true }));
    readers.set(client.subscribe(channel.id), [channel.topic, reader]);
  }
});

client.on("message", ({ subscriptionId, data }) => {
  const [topic, reader] = readers.get(subscriptionId);
  const message = reader.readMessage(data);
  if (topic === JOINTS) onJointState(message);
  else if (topic === TF) {
    state.tfMessages += 1;
    for (const t of message.transforms) {
      state.parents.add(t.header.frame_id);
      state.children.add(t.child_frame_id);
    }
  } else if (topic === DESCRIPTION) state.description = message.data;
  check();
});

function onJointState(message) {
  state.samples += 1;
  state.names = message.name;
  const d = distance(message.position);
  if (state.start === undefined) {
    if (message.name.length !== target.length) finish(false, `${message.name.length} joints, not ${target.length}`);
    state.start = d;
    console.log(`ready ${JSON.stringify({ names: message.name, position: Array.from(message.position), distance: d })}`);
    return;
  }
  const previous = state.distances.at(-1) ?? state.start;
  if (d > previous + SLACK) finish(false, `moving away from the target: ${previous} then ${d}`);
  state.distances.push(d);
}

function check() {
  const s = summary();
  const arrived = s.last !== undefined && s.last <= tolerance;
  const urdf = state.description !== undefined && state.description.includes("<robot");
  const tfTree = state.tfMessages > 0 && state.parents.size > 1; // parent → child per URDF joint
  if (arrived && s.moving >= 3 && urdf && state.parameter === state.description && tfTree) {
    client.close();
    finish(true, s);
  }
}
