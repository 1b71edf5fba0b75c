// An operator's session on humanpt's Foxglove bridge, driven by a client no one in the
// project wrote: @foxglove/ws-protocol's FoxgloveClient over the `ws` package's WebSocket,
// offering the subprotocol foxglove-sdk's server speaks (foxglove.sdk.v1; ws-protocol 0.8
// names foxglove.websocket.v1, which that server refuses: checked first and reported).
// Messages are decoded with protobufjs from the schemas the channels advertise.
//
//   node client.mjs ws://127.0.0.1:PORT CELL  ->  one JSON object on stdout (what it saw)
//
// Every wait is bounded (a hang fails with what was awaited); the checks are the test's.
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const [url, cell] = process.argv.slice(2);
const SUBPROTOCOL = "foxglove.sdk.v1";
const LIMIT_MS = 90_000;
const out = { steps: [] };

function step(name, value) {
  out.steps.push(name);
  out[name] = value;
}

async function waitFor(pred, what, ms = LIMIT_MS) {
  const end = Date.now() + ms;
  for (;;) {
    const got = pred();
    if (got) return got;
    if (Date.now() > end) throw new Error(`timed out waiting for ${what}`);
    await new Promise((r) => setTimeout(r, 20));
  }
}

// Only ws-protocol's own subprotocol offered: what the server answers.
function tryConnect(protocols) {
  return new Promise((resolve) => {
    const w = new WebSocket(url, protocols);
    w.on("open", () => {
      resolve(`open (${w.protocol})`);
      w.close();
    });
    w.on("unexpected-response", (_req, res) => {
      resolve(`HTTP ${res.statusCode}`);
      w.terminate();
    });
    w.on("error", (e) => resolve(`error: ${e.message}`));
  });
}
step("websocket_v1_only", await tryConnect([FoxgloveClient.SUPPORTED_SUBPROTOCOL]));

const ws = new WebSocket(url, [SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const state = {
  open: false, info: null, channels: new Map(), services: new Map(), subs: new Map(), messages: new Map(),
  statuses: [], params: [], replies: new Map(), errors: [],
};
client.on("open", () => (state.open = true));
client.on("error", (e) => state.errors.push(String(e?.message ?? e)));
client.on("serverInfo", (i) => (state.info = i));
client.on("status", (s) => state.statuses.push(s));
client.on("advertise", (chs) => chs.forEach((c) => state.channels.set(c.topic, c)));
client.on("advertiseServices", (svcs) => svcs.forEach((s) => state.services.set(s.name, s)));
client.on("parameterValues", (p) => state.params.push(p));
client.on("serviceCallResponse", (r) => state.replies.set(r.callId, { ok: true, text: new TextDecoder().decode(r.data) }));
client.on("serviceCallFailure", (f) => state.replies.set(f.callId, { ok: false, text: f.message }));
client.on("message", ({ subscriptionId, data }) => {
  const sub = state.subs.get(subscriptionId);
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  try {
    const msg = sub.type.toObject(sub.type.decode(bytes), { longs: Number, defaults: true });
    const list = state.messages.get(sub.topic) ?? [];
    list.push(msg);
    state.messages.set(sub.topic, list);
  } catch (e) {
    state.errors.push(`${sub.topic}: ${e.message}`);
  }
});

await waitFor(() => state.open && state.info, "the server's info");
step("server", { name: state.info.name, capabilities: state.info.capabilities, protocol: ws.protocol });

const key = (short) => `humanpt/${cell}/${short}`;
function subscribe(short) {
  const ch = state.channels.get(key(short));
  const set = descriptor.FileDescriptorSet.decode(Buffer.from(ch.schema, "base64"));
  const type = protobuf.Root.fromDescriptor(set).lookupType(ch.schemaName);
  state.subs.set(client.subscribe(ch.id), { topic: short, type });
}
const WANTED = ["camera/image", "robot_gateway/robot_state", "perception/events", "scene/transforms"];
await waitFor(() => WANTED.every((t) => state.channels.has(key(t))), "the channels advertised");
step("channels", [...state.channels.keys()].length);
step("schemas", Object.fromEntries(WANTED.map((t) => [t, state.channels.get(key(t)).schemaName])));
WANTED.forEach(subscribe);

const image = await waitFor(() => state.messages.get("camera/image")?.[0], "an image");
step("image", { width: image.width, height: image.height, encoding: image.encoding, step: image.step,
                bytes: image.data.length, frame_id: image.frame_id, max: Math.max(...image.data.subarray(0, 65536)) });
const rs = await waitFor(() => state.messages.get("robot_gateway/robot_state")?.[0], "a robot state");
step("robot_state", { translation: rs.world_T_flange.translation, rotation: rs.world_T_flange.rotation,
                      cycle: rs.cycle });
const tf = await waitFor(() => state.messages.get("scene/transforms")?.[0], "scene transforms");
step("transforms", tf.transforms.map((t) => `${t.parent_frame_id}->${t.child_frame_id}`));

// Parameters: set, refused out of range, unknown, read-only; read all.
const paramReply = (id) => waitFor(() => state.params.find((p) => p.id === id), `parameterValues ${id}`);
const statusWith = (text) => waitFor(() => state.statuses.find((s) => s.message.includes(text)), `a status with ${text}`);
client.setParameters([{ name: "perception.threshold", value: 70 }], "t70");
step("set_threshold", (await paramReply("t70")).parameters);
const changed = await waitFor(() => (state.messages.get("perception/events") ?? []).find(
  (e) => e.code === "param_changed" && e.text.includes("threshold")), "perception's param_changed");
step("param_changed", changed.text);
client.setParameters([{ name: "perception.threshold", value: 300 }], "t300");
step("set_threshold_300", (await paramReply("t300")).parameters);
step("refused_300", (await statusWith("perception.threshold = 300 refused")).message);
client.setParameters([{ name: "perception.nope", value: 1 }], "nope");
step("set_unknown", (await paramReply("nope")).parameters);
step("refused_unknown", (await statusWith("unknown parameter 'perception.nope'")).message);
client.setParameters([{ name: "robot_gateway.max_speed_mm_s", value: 1000 }], "ro");
await paramReply("ro");
step("refused_read_only", (await statusWith("read-only")).message);
client.getParameters([], "all");
step("all_parameters", Object.fromEntries((await paramReply("all")).parameters.map((p) => [p.name, p.value])));

// Services: the console's verbs, refusals with their reasons.
await waitFor(() => state.services.has("record_start") && state.services.has("reset_fault"), "the services");
step("services", [...state.services.keys()]);
let callId = 0;
async function call(name, body) {
  const id = ++callId;
  const serviceId = typeof name === "number" ? name : state.services.get(name).id;
  const data = new TextEncoder().encode(typeof body === "string" ? body : JSON.stringify(body));
  client.sendServiceCallRequest({ serviceId, callId: id, encoding: "json", data: new DataView(data.buffer) });
  return waitFor(() => state.replies.get(id), `the answer to ${name}`);
}
step("record_start", await call("record_start", {}));
step("record_stop", await call("record_stop", {}));
step("save", await call("save", { file: "fox-seam" }));
step("reset_fault", await call("reset_fault", { operator: "mallory" }));
step("malformed", await call("save", "not json{"));
step("unknown_field", await call("save", { file: "x", evil: 1 }));
step("wrong_type", await call("calibrate_tip", { samples: "many" }));
step("out_of_range", await call("playback", { speed_mm_s: 1000 }));
step("unknown_service", await call(987654, {}));

// Publishing (ClientPublish): a command on console/command's key, which must not reach the bus.
const pubId = client.advertise({ topic: key("console/command"), encoding: "json", schemaName: "humanpt.Command" });
client.sendMessage(pubId, new TextEncoder().encode(JSON.stringify({ component: "controller", verb: "return" })));
step("published", pubId);

// Garbage on a second connection; the server goes on (the first client still gets answers).
const junk = new WebSocket(url, [SUBPROTOCOL]);
await new Promise((r) => junk.on("open", r));
junk.send("{ this is not json");
junk.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: "x", channelId: -1 }] }));
junk.send(JSON.stringify({ op: "setParameters", parameters: [{ name: 7 }] }));
junk.send(Buffer.from([0x02, 0xff, 0xff]));
// After the garbage, a good request on the same socket: answered, or the socket closed.
let junkEnd = null;
junk.on("close", (code) => (junkEnd ??= `closed ${code}`));
junk.on("message", (data) => {
  if (typeof data !== "string" && !(data instanceof Buffer)) return;
  const text = data.toString();
  if (text.includes('"parameterValues"') && text.includes('"junk"')) junkEnd ??= "answered";
});
junk.send(JSON.stringify({ op: "getParameters", parameterNames: ["perception.threshold"], id: "junk" }));
step("garbage_connection", await waitFor(() => junkEnd, "the garbage connection's end"));
junk.terminate();
step("after_garbage", await call("hold", {}));
// The Parameters panel follows a change made elsewhere: subscribed, then the test runs
// `humanpt console set threshold=80` when it reads READY, and the new value is pushed.
client.subscribeParameterUpdates(["perception.threshold"]);
console.log("READY");
const pushed = await waitFor(() => state.params.find((p) => !p.id && p.parameters.some(
  (q) => q.name === "perception.threshold" && q.value === 80)), "the console's threshold pushed");
step("pushed", pushed.parameters);
step("client_errors", state.errors);
client.close();
console.log(JSON.stringify(out));
process.exit(0);
