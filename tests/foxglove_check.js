// A stock Foxglove client against handblocks' live view: the npm client `@foxglove/ws-protocol`
// (over `ws`, offering the subprotocol it offers, foxglove.websocket.v1, or the one given as
// the second argument), decoding as the Foxglove app does: ROS 2 CDR messages with
// `@foxglove/rosmsg` + `@foxglove/rosmsg2-serialization`, protobuf ones with `protobufjs` from
// the schema's FileDescriptorSet. tests/remote.rs runs it (tests/run installs the packages into
// target/foxglove-node); by hand:
//
//   NODE_PATH=target/foxglove-node/node_modules node tests/foxglove_check.js ws://127.0.0.1:8765
//
// Prints one JSON line: {"subprotocol", "channels": [{topic, encoding, schemaName}], "world":
// {...decoded...}, "scene": {...decoded...}, "tf": {...decoded...}, "tfLogTime"} once it has a
// world, and a hand's frames (`/tf`, foxglove.FrameTransforms) with the scene sent just before
// them (the view sends the two together, so they show the same hand), or {"error"}.
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const url = process.argv[2];
const offer = process.argv[3] || FoxgloveClient.SUPPORTED_SUBPROTOCOL;
const out = { subprotocol: null, channels: [], world: null, scene: null, tf: null };
const done = (extra) => {
  console.log(JSON.stringify({ ...out, ...extra }));
  process.exit(extra && extra.error ? 1 : 0);
};
setTimeout(() => done({ error: "timed out" }), Number(process.env.HB_FOXGLOVE_TIMEOUT_MS || 8000));

const ws = new WebSocket(url, [offer]);
ws.on("unexpected-response", (_req, res) => {
  let body = "";
  res.on("data", (d) => (body += d));
  res.on("end", () => done({ error: `HTTP ${res.statusCode} ${body.trim()}` }));
});
ws.on("open", () => (out.subprotocol = ws.protocol));
const client = new FoxgloveClient({ ws });
client.on("error", (e) => done({ error: String(e && e.message ? e.message : e) }));
const decoders = new Map(); // subscription id -> (topic, decode)
client.on("advertise", (channels) => {
  for (const ch of channels) {
    out.channels.push({ topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName });
    let decode;
    if (ch.encoding === "cdr" && ch.schemaEncoding === "ros2msg") {
      const reader = new MessageReader(parse(ch.schema, { ros2: true }));
      decode = (bytes) => reader.readMessage(bytes);
    } else if (ch.encoding === "protobuf") {
      const set = descriptor.FileDescriptorSet.decode(Buffer.from(ch.schema, "base64"));
      const type = protobuf.Root.fromDescriptor(set).lookupType(ch.schemaName);
      decode = (bytes) => type.toObject(type.decode(bytes), { defaults: true, longs: Number });
    }
    if (decode && ["/world", "/scene", "/tf"].includes(ch.topic)) {
      decoders.set(client.subscribe(ch.id), { topic: ch.topic, decode });
    }
  }
});
const drawsHand = (scene) => scene.entities.some((e) => e.id === "hand" && e.lines.some((l) => l.points.length > 0));
let lastScene = null;
const plain = (v) => JSON.parse(JSON.stringify(v, (_k, x) => (typeof x === "bigint" ? Number(x) : ArrayBuffer.isView(x) ? Array.from(x) : x)));
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const d = decoders.get(subscriptionId);
  if (!d) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  try {
    const msg = plain(d.decode(bytes));
    if (d.topic === "/world" && !out.world) out.world = msg;
    // A scene with the hand drawn (the first may come before any hand sample), and the hand's
    // frames sent right after it.
    if (d.topic === "/scene") lastScene = msg;
    if (d.topic === "/tf" && !out.tf && msg.transforms.length > 0 && lastScene && drawsHand(lastScene)) {
      out.tf = msg;
      out.tfLogTime = String(timestamp); // nanoseconds, exact (a Number would round them)
      out.scene = lastScene;
    }
  } catch (e) {
    done({ error: `cannot decode ${d.topic}: ${e}` });
  }
  if (out.world && out.scene && out.tf) done();
});
