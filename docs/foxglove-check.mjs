// Decode a merged humanpt run as Foxglove does (@mcap/core + protobufjs), and compare
// every foxglove.* schema in it with Foxglove's own .proto files, parsed by protobufjs.
//
//   mkdir /tmp/fx && cd /tmp/fx && npm install @mcap/core protobufjs @foxglove/wasm-zstd @foxglove/wasm-lz4
//   humanpt demo --lockstep --scenario arc --duration 4 --run-dir /tmp/run
//   humanpt runs merge /tmp/run /tmp/run.mcap
//   NODE_PATH=/tmp/fx/node_modules node docs/foxglove-check.mjs /tmp/run.mcap schemas
//
// Prints one JSON line per channel (topic, schema, messages decoded) and exits 1 if a message
// does not decode or a foxglove.* schema differs from the .proto files (field name, number,
// type, repeated), 0 otherwise.
import { createRequire } from "node:module";
import { readFileSync, readdirSync } from "node:fs";
import { join } from "node:path";

const require = createRequire(join(process.env.NODE_PATH ?? ".", "x.js"));
const { McapStreamReader } = require("@mcap/core");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");
const zstd = require("@foxglove/wasm-zstd");
const lz4 = require("@foxglove/wasm-lz4");

const [file, protoDir] = process.argv.slice(2);
if (!file || !protoDir) {
  console.error("usage: node foxglove-check.mjs MERGED.mcap PROTO_DIR (the folder holding foxglove/*.proto)");
  process.exit(2);
}
await zstd.isLoaded;
await lz4.isLoaded;

// Foxglove's .proto files, parsed by protobufjs (not protoc).
const reference = new protobuf.Root();
reference.resolvePath = (_origin, target) => (target.startsWith("google/") ? target : join(protoDir, target));
const files = readdirSync(join(protoDir, "foxglove")).filter((f) => f.endsWith(".proto"));
reference.loadSync(files.map((f) => `foxglove/${f}`), { keepCase: true });
reference.resolveAll();

function fields(type) {
  return Object.values(type.fields)
    .map((f) => `${f.name}=${f.id}:${f.resolvedType ? f.resolvedType.fullName.replace(/^\./, "") : f.type}${f.repeated ? "[]" : ""}`)
    .sort()
    .join(",");
}

const reader = new McapStreamReader({
  decompressHandlers: {
    zstd: (data, size) => zstd.decompress(data, Number(size)),
    lz4: (data, size) => lz4(data, Number(size)),
  },
});
reader.append(readFileSync(file));
const schemas = new Map();
const channels = new Map();
const counts = new Map();
const checked = new Set();
let failures = 0;
for (let record; (record = reader.nextRecord()); ) {
  if (record.type === "Schema") {
    const set = descriptor.FileDescriptorSet.decode(record.data);
    const root = protobuf.Root.fromDescriptor(set);
    root.resolveAll();
    const type = root.lookupType(record.name);
    schemas.set(record.id, { name: record.name, type });
    if (record.name.startsWith("foxglove.") && !checked.has(record.name)) {
      checked.add(record.name);
      // The message and every foxglove type it uses.
      const todo = [type];
      const seen = new Set();
      while (todo.length) {
        const t = todo.pop();
        const name = t.fullName.replace(/^\./, "");
        if (seen.has(name)) continue;
        seen.add(name);
        let ref;
        try {
          ref = reference.lookupType(name);
        } catch {
          console.log(JSON.stringify({ schema: record.name, error: `${name} is not in ${protoDir}` }));
          failures++;
          continue;
        }
        if (fields(t) !== fields(ref)) {
          console.log(JSON.stringify({ schema: record.name, type: name, recorded: fields(t), foxglove: fields(ref) }));
          failures++;
        }
        for (const f of Object.values(t.fields)) {
          if (f.resolvedType instanceof protobuf.Type && f.resolvedType.fullName.startsWith(".foxglove.")) {
            todo.push(f.resolvedType);
          }
        }
      }
    }
  } else if (record.type === "Channel") {
    channels.set(record.id, record);
  } else if (record.type === "Message") {
    const channel = channels.get(record.channelId);
    const schema = schemas.get(channel.schemaId);
    try {
      schema.type.toObject(schema.type.decode(record.data), { longs: String });
      counts.set(record.channelId, (counts.get(record.channelId) ?? 0) + 1);
    } catch (e) {
      console.log(JSON.stringify({ topic: channel.topic, error: String(e) }));
      failures++;
    }
  }
}
for (const [id, channel] of channels) {
  const schema = schemas.get(channel.schemaId);
  console.log(JSON.stringify({ topic: channel.topic, schema: schema.name, messages: counts.get(id) ?? 0 }));
}
console.log(JSON.stringify({ foxglove_schemas_checked: [...checked].sort(), failures }));
process.exit(failures ? 1 : 0);
