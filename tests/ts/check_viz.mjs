// Reads an MCAP file with the TypeScript MCAP reader (@mcap/core) as Foxglove does and
// prints one JSON line: messages read, how many are not JSON (unparsable), how many
// channels' schemas differ from the published @foxglove/schemas of the same name.
// Usage: node check_viz.mjs FILE.mcap
import { readFile } from "node:fs/promises";
import { isDeepStrictEqual } from "node:util";
import { createRequire } from "node:module";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";

const require = createRequire(import.meta.url);
const zstd = require("@foxglove/wasm-zstd");
const published = require("@foxglove/schemas/jsonschema");

await zstd.isLoaded;
const decompressHandlers = { zstd: (data, size) => zstd.decompress(data, Number(size)) };
const bytes = new Uint8Array(await readFile(process.argv[2]));
const readable = {
  size: async () => BigInt(bytes.byteLength),
  read: async (offset, size) => bytes.subarray(Number(offset), Number(offset + size)),
};

// 1. Every record in file order (chunk CRCs and the data-section CRC checked).
const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(bytes);
let records = 0;
let streamed = 0;
for (let r; (r = stream.nextRecord()) !== undefined; ) {
  records += 1;
  if (r.type === "Message") streamed += 1;
}

// 2. Through the index, as a viewer opens a local file.
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
const decoder = new TextDecoder("utf-8", { fatal: true });
const schemaMismatch = [];
for (const schema of reader.schemasById.values()) {
  const name = schema.name.replace(/^foxglove\./, "");
  let ok = schema.encoding === "jsonschema" && name in published;
  try {
    ok = ok && isDeepStrictEqual(JSON.parse(decoder.decode(schema.data)), published[name]);
  } catch {
    ok = false;
  }
  if (!ok) schemaMismatch.push(schema.name);
}
let messages = 0;
let unparsable = 0;
const topics = {};
for await (const m of reader.readMessages()) {
  messages += 1;
  const channel = reader.channelsById.get(m.channelId);
  topics[channel.topic] = (topics[channel.topic] ?? 0) + 1;
  try {
    if (channel.messageEncoding !== "json") throw new Error("not json");
    JSON.parse(decoder.decode(m.data));
  } catch {
    unparsable += 1;
  }
}
console.log(
  JSON.stringify({ records, streamed, messages, unparsable, schemaMismatch, topics }),
);
