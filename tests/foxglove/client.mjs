// A Foxglove WebSocket protocol client for the end-to-end test of
// `deog view --foxglove`: connects with @foxglove/ws-protocol's
// FoxgloveClient over `ws`, subscribes to every channel the server
// advertises, decodes each message with the protobuf schema its
// advertisement carries (a base64 FileDescriptorSet, read by protobufjs),
// and prints one JSON object on stdout:
//
//   { channels: [{ topic, schemaName, encoding, schemaEncoding }],
//     counts: { topic: messages }, bytes: { topic: bytes },
//     times: { topic: [seconds after connecting each message arrived] }
//       (the first 500), latest: { topic: a summary of the newest
//       message }, missing: [...], errors: [...] }
//
// Usage: node client.mjs --url ws://127.0.0.1:8765 [--seconds 5]
//          [--want /map,/tf] [--timeout 60]
// It listens at least --seconds, then until every --want topic has
// decoded a message, or --timeout passes. It exits 0 once the JSON is
// printed (the caller judges it), 2 on bad arguments or a failed
// connection.

import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

function parseArgs(argv) {
  const args = { url: null, seconds: 5, timeout: 60, want: [] };
  for (let i = 0; i < argv.length; i += 2) {
    const [flag, value] = [argv[i], argv[i + 1]];
    if (value === undefined) throw new Error(`${flag} needs a value`);
    switch (flag) {
      case "--url":
        args.url = value;
        break;
      case "--seconds":
      case "--timeout": {
        const n = Number(value);
        if (!Number.isFinite(n) || n <= 0) throw new Error(`${flag} must be a positive number, got ${value}`);
        args[flag.slice(2)] = n;
        break;
      }
      case "--want":
        args.want = value.split(",").filter((t) => t.length > 0);
        break;
      default:
        throw new Error(`unknown argument ${flag}`);
    }
  }
  if (!args.url) throw new Error("--url is required");
  return args;
}

/// protobufjs keeps the schema's snake_case field names; the summaries
/// read camelCase.
function camelize(value) {
  if (Array.isArray(value)) return value.map(camelize);
  if (value === null || typeof value !== "object" || ArrayBuffer.isView(value)) return value;
  return Object.fromEntries(
    Object.entries(value).map(([key, v]) => [key.replace(/_([a-z])/g, (_, c) => c.toUpperCase()), camelize(v)]),
  );
}

function yaw(q) {
  if (!q) return 0;
  const { x = 0, y = 0, z = 0, w = 1 } = q;
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

function vec(v) {
  return { x: v?.x ?? 0, y: v?.y ?? 0, z: v?.z ?? 0 };
}

/// What the test needs of each message type.
function summarize(schemaName, m, raw) {
  switch (schemaName) {
    case "foxglove.Grid": {
      const data = raw.data;
      const rows = m.rowStride > 0 ? Math.floor(data.length / m.rowStride) : 0;
      const occupancy = m.fields.find((f) => f.name === "occupancy");
      let unknown = 0;
      let free = 0;
      let occupied = 0;
      if (occupancy && m.cellStride > 0) {
        for (let row = 0; row < rows; row++) {
          for (let col = 0; col < m.columnCount; col++) {
            const at = row * m.rowStride + col * m.cellStride + occupancy.offset;
            const value = (data[at] << 24) >> 24; // int8
            if (value < 0) unknown++;
            else if (value >= 65) occupied++;
            else if (value <= 35) free++;
          }
        }
      }
      return {
        frameId: m.frameId,
        columnCount: m.columnCount,
        rows,
        rowStride: m.rowStride,
        cellStride: m.cellStride,
        cellSize: { x: m.cellSize?.x ?? 0, y: m.cellSize?.y ?? 0 },
        origin: vec(m.pose?.position),
        fields: m.fields.map((f) => ({ name: f.name, offset: f.offset, type: f.type })),
        dataLength: data.length,
        unknown,
        free,
        occupied,
      };
    }
    case "foxglove.PoseInFrame":
      return { frameId: m.frameId, ...vec(m.pose?.position), yaw: yaw(m.pose?.orientation) };
    case "foxglove.PosesInFrame":
      return { frameId: m.frameId, poses: m.poses.length };
    case "foxglove.FrameTransforms":
      return {
        transforms: m.transforms.map((t) => ({
          parent: t.parentFrameId,
          child: t.childFrameId,
          ...vec(t.translation),
          yaw: yaw(t.rotation),
        })),
      };
    case "foxglove.LaserScan": {
      const finite = m.ranges.filter((r) => Number.isFinite(r));
      return {
        frameId: m.frameId,
        origin: vec(m.pose?.position),
        startAngle: m.startAngle,
        endAngle: m.endAngle,
        ranges: m.ranges.length,
        finite: finite.length,
        maxFinite: finite.length ? Math.max(...finite) : null,
      };
    }
    case "foxglove.SceneUpdate":
      return {
        entities: m.entities.map((e) => ({
          id: e.id,
          frameId: e.frameId,
          triangles: e.triangles.reduce((n, t) => n + Math.floor(t.points.length / 3), 0),
          spheres: e.spheres.map((s) => ({ ...vec(s.pose?.position), size: vec(s.size) })),
          metadata: Object.fromEntries(e.metadata.map((kv) => [kv.key, kv.value])),
        })),
      };
    default:
      return { fields: Object.keys(m) };
  }
}

async function main() {
  let args;
  try {
    args = parseArgs(process.argv.slice(2));
  } catch (error) {
    console.error(`client.mjs: ${error.message}`);
    process.exit(2);
  }
  const channels = new Map(); // id -> { topic, schemaName, encoding, schemaEncoding, type }
  const bySubscription = new Map();
  const counts = {};
  const bytes = {};
  const latest = {};
  const times = {};
  let connectedAt = Date.now();
  const errors = [];
  let nextSubscription = 0;

  // The SDK's server speaks the protocol FoxgloveClient implements under
  // the subprotocol name foxglove.sdk.v1 (and v1.1, whose advertisements
  // carry schemas by reference, which this client does not read). Each
  // attempt's client gets its handlers before any message can arrive; a
  // refused attempt is dropped and another made (for 30 s), so the script
  // may start before the server listens.
  const attempt = () => {
    const client = new FoxgloveClient({ ws: new WebSocket(args.url, ["foxglove.sdk.v1"]) });
    listen(client);
    return new Promise((resolve, reject) => {
      client.on("open", () => resolve(client));
      client.on("error", reject);
    });
  };
  const listen = (client) => {
    client.on("advertise", (advertised) => {
      for (const channel of advertised) {
        let type = null;
        if (channel.encoding === "protobuf" && channel.schemaEncoding === "protobuf") {
          try {
            const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
            type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
          } catch (error) {
            errors.push(`${channel.topic}: schema ${channel.schemaName}: ${error.message}`);
          }
        }
        channels.set(channel.id, {
          topic: channel.topic,
          schemaName: channel.schemaName,
          encoding: channel.encoding,
          schemaEncoding: channel.schemaEncoding,
          type,
        });
        counts[channel.topic] ??= 0;
        bytes[channel.topic] ??= 0;
        bySubscription.set(client.subscribe(channel.id), channel.id);
        nextSubscription++;
      }
    });
    client.on("unadvertise", (ids) => {
      for (const id of ids) channels.delete(id);
    });
    client.on("message", ({ subscriptionId, data }) => {
      const channel = channels.get(bySubscription.get(subscriptionId));
      if (!channel) return;
      const view = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
      counts[channel.topic] += 1;
      bytes[channel.topic] += view.byteLength;
      times[channel.topic] ??= [];
      if (times[channel.topic].length < 500) times[channel.topic].push((Date.now() - connectedAt) / 1000);
      if (!channel.type) return;
      try {
        const raw = channel.type.decode(view);
        const m = camelize(channel.type.toObject(raw, { longs: Number, enums: Number, defaults: true, arrays: true }));
        latest[channel.topic] = summarize(channel.schemaName, m, raw);
      } catch (error) {
        errors.push(`${channel.topic}: decoding: ${error.message}`);
      }
    });
  };

  let client = null;
  const connectBy = Date.now() + 30_000;
  while (client === null) {
    try {
      connectedAt = Date.now();
      client = await attempt();
    } catch (error) {
      if (Date.now() > connectBy) {
        console.error(`client.mjs: connecting to ${args.url}: ${error?.message ?? error}`);
        process.exit(2);
      }
      await new Promise((resolve) => setTimeout(resolve, 200));
    }
  }
  const started = Date.now();
  const missing = () => args.want.filter((t) => latest[t] === undefined);
  await new Promise((resolve) => {
    const check = setInterval(() => {
      const elapsed = (Date.now() - started) / 1000;
      if ((elapsed >= args.seconds && missing().length === 0) || elapsed >= args.timeout) {
        clearInterval(check);
        resolve();
      }
    }, 50);
  });
  client.close();
  const report = {
    url: args.url,
    seconds: (Date.now() - started) / 1000,
    subscriptions: nextSubscription,
    channels: [...channels.values()].map(({ topic, schemaName, encoding, schemaEncoding }) => ({
      topic,
      schemaName,
      encoding,
      schemaEncoding,
    })),
    counts,
    bytes,
    times,
    latest,
    missing: missing(),
    errors,
  };
  process.stdout.write(`${JSON.stringify(report)}\n`);
  process.exit(0);
}

main();
