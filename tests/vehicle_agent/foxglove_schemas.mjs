// What the Foxglove tests check a message with, in Node as Foxglove reads it: the JSON Schemas of
// @foxglove/schemas (the well-known ones) or the channel's own, a protobuf message as plain
// fields, and a JPEG's size from its header.
import * as foxgloveSchemas from '@foxglove/schemas/jsonschema.js';
import protobuf from 'protobufjs';
import descriptor from 'protobufjs/ext/descriptor/index.js';

// The JSON Schema of a well-known schema name ("foxglove.CompressedImage"), or undefined.
export function wellKnown(name) {
  return name.startsWith('foxglove.') ? foxgloveSchemas[name.slice(9)] : undefined;
}

const TYPES = {
  object: (v) => v !== null && typeof v === 'object' && !Array.isArray(v) && !isBytes(v),
  array: (v) => Array.isArray(v),
  string: (v) => typeof v === 'string' || isBytes(v),
  number: (v) => typeof v === 'number' && Number.isFinite(v),
  integer: (v) => Number.isInteger(v),
  boolean: (v) => typeof v === 'boolean',
  null: (v) => v === null,
};

function isBytes(v) {
  return v instanceof Uint8Array;
}

// The problems of `value` against `schema` (the keywords Foxglove's schemas and ours use), each
// "path: what"; empty when it conforms.
export function validate(schema, value, path = '$') {
  const problems = [];
  if (schema.type !== undefined) {
    const types = [].concat(schema.type);
    if (!types.some((t) => TYPES[t](value))) {
      return [`${path}: ${JSON.stringify(value)?.slice(0, 60)} is not ${types.join(' or ')}`];
    }
  }
  if (schema.enum !== undefined && !schema.enum.includes(value)) {
    problems.push(`${path}: ${value} is not one of ${schema.enum.join(', ')}`);
  }
  if (schema.const !== undefined && value !== schema.const) {
    problems.push(`${path}: ${value} is not ${schema.const}`);
  }
  if (schema.oneOf !== undefined) {
    const matching = schema.oneOf.filter((s) => validate(s, value, path).length === 0);
    if (matching.length !== 1)
      problems.push(`${path}: ${value} matches ${matching.length} of oneOf`);
  }
  if (typeof value === 'number') {
    if (schema.minimum !== undefined && value < schema.minimum) problems.push(`${path} < min`);
    if (schema.maximum !== undefined && value > schema.maximum) problems.push(`${path} > max`);
  }
  if (TYPES.object(value)) {
    for (const key of schema.required ?? []) {
      if (!(key in value)) problems.push(`${path}.${key}: missing`);
    }
    for (const [key, sub] of Object.entries(schema.properties ?? {})) {
      if (key in value) problems.push(...validate(sub, value[key], `${path}.${key}`));
    }
  }
  if (Array.isArray(value)) {
    if (schema.minItems !== undefined && value.length < schema.minItems) {
      problems.push(`${path}: fewer than ${schema.minItems} items`);
    }
    if (schema.maxItems !== undefined && value.length > schema.maxItems) {
      problems.push(`${path}: more than ${schema.maxItems} items`);
    }
    if (schema.items !== undefined) {
      value.forEach((item, i) => problems.push(...validate(schema.items, item, `${path}[${i}]`)));
    }
  }
  return problems;
}

// A decoder of a channel's messages into plain fields, by its encoding and schema: JSON parsed,
// protobuf through the advertised FileDescriptorSet, with google.protobuf.Timestamp as
// Foxglove's {sec, nsec} and enums as numbers.
export function decoderFor(encoding, schemaName, schemaBytes) {
  if (encoding === 'json') {
    const text = new TextDecoder();
    return (bytes) => JSON.parse(text.decode(bytes));
  }
  if (encoding !== 'protobuf') throw new Error(`unexpected encoding ${encoding}`);
  const set = descriptor.FileDescriptorSet.decode(schemaBytes);
  const type = protobuf.Root.fromDescriptor(set).lookupType(schemaName);
  return (bytes) =>
    plain(type.toObject(type.decode(bytes), { longs: Number, enums: Number, defaults: true }));
}

function plain(value) {
  if (Array.isArray(value)) return value.map(plain);
  if (value === null || typeof value !== 'object' || isBytes(value)) return value;
  const keys = Object.keys(value);
  if (keys.length === 2 && 'seconds' in value && 'nanos' in value) {
    return { sec: value.seconds, nsec: value.nanos };
  }
  // protobufjs names fields in camelCase; Foxglove's schemas in snake_case.
  return Object.fromEntries(
    keys.map((k) => [
      k.replace(/([a-z0-9])([A-Z])/g, (_, a, b) => `${a}_${b.toLowerCase()}`),
      plain(value[k]),
    ]),
  );
}

// A JPEG's width and height from its start-of-frame marker; null when there is none.
export function jpegSize(bytes) {
  if (bytes[0] !== 0xff || bytes[1] !== 0xd8) return null;
  let at = 2;
  while (at + 9 < bytes.length) {
    if (bytes[at] !== 0xff) return null;
    const marker = bytes[at + 1];
    const length = (bytes[at + 2] << 8) | bytes[at + 3];
    // SOF0 to SOF15, less DHT (c4), JPG (c8) and DAC (cc).
    if (marker >= 0xc0 && marker <= 0xcf && ![0xc4, 0xc8, 0xcc].includes(marker)) {
      return {
        height: (bytes[at + 5] << 8) | bytes[at + 6],
        width: (bytes[at + 7] << 8) | bytes[at + 8],
      };
    }
    at += 2 + length;
  }
  return null;
}
