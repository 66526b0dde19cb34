// An outside reader of the flight recorder's files: @mcap/core (Foxglove's own MCAP library)
// reads each file, and every message is checked against @foxglove/schemas for a well-known
// schema or its channel's own JSON Schema. Prints one JSON line: per topic, the schema, the
// encoding, the message count and the problems found.
//
//   node mcap_reader.mjs FILE...
import { readFileSync } from 'node:fs';

import { McapStreamReader } from '@mcap/core';
import { decompress } from 'fzstd';

import { decoderFor, validate, wellKnown } from './foxglove_schemas.mjs';

const topics = {};
for (const path of process.argv.slice(2)) {
  const reader = new McapStreamReader({
    decompressHandlers: { zstd: (data) => decompress(data) },
    validateCrcs: true,
  });
  reader.append(readFileSync(path));
  const schemas = new Map();
  const channels = new Map();
  for (let record; (record = reader.nextRecord()) !== undefined;) {
    if (record.type === 'Schema') schemas.set(record.id, record);
    else if (record.type === 'Channel') {
      const schema = schemas.get(record.schemaId);
      const jsonSchema =
        wellKnown(schema.name) ??
        (schema.encoding === 'jsonschema'
          ? JSON.parse(new TextDecoder().decode(schema.data))
          : undefined);
      channels.set(record.id, {
        topic: record.topic,
        decode: decoderFor(record.messageEncoding, schema.name, schema.data),
        jsonSchema,
      });
      topics[record.topic] ??= {
        schema: schema.name,
        encoding: record.messageEncoding,
        messages: 0,
        problems: [],
      };
    } else if (record.type === 'Message') {
      const channel = channels.get(record.channelId);
      const entry = topics[channel.topic];
      entry.messages += 1;
      if (entry.problems.length >= 5) continue;
      if (channel.jsonSchema === undefined) entry.problems.push(`no schema for ${entry.schema}`);
      else entry.problems.push(...validate(channel.jsonSchema, channel.decode(record.data)));
    }
  }
  if (!reader.done()) throw new Error(`${path}: the file ends mid-record`);
}
process.stdout.write(JSON.stringify(topics) + '\n');
