// A Foxglove viewer made of the official client (@foxglove/ws-protocol), as Foxglove connects:
// it subscribes to every channel the agent advertises and checks each message against its
// schema, then prints one JSON line of what it saw (tests/vehicle_agent/test_foxglove.py).
//
//   node foxglove_viewer.mjs '{"url": "ws://127.0.0.1:8765", "topics": [...], "timeoutS": 20,
//                              "twists": 3, "flood": 0}'
//
// It ends when every topic in `topics` has a message and `twists` Twists were compared with
// their goals, or at the timeout. `flood`: subscribe and unsubscribe every channel that many
// times first, as a hostile viewer might. `ca`: a PEM file to trust for a wss:// URL (a token
// rides in the URL's query: wss://host:port/?token=T, as Foxglove passes it).
import { readFileSync } from 'node:fs';

import wsProtocol from '@foxglove/ws-protocol';
import WebSocket from 'ws';

import { decoderFor, jpegSize, validate, wellKnown } from './foxglove_schemas.mjs';

const { FoxgloveClient } = wsProtocol;

const options = JSON.parse(process.argv[2]);
// The goal's pixel must be this far from the centre (a share of the width) for its side to be
// clear: nearer, the law's dead zone or the limiter's ramp from the last command may decide.
const CLEAR_SIDE = 0.15;

const seen = {}; // topic -> {schema, encoding, messages, problems: [...]}
const channels = new Map(); // channel id -> {topic, decode, schema}
const subscriptions = new Map(); // subscription id -> channel id
const imageSizes = new Set();
const annotationPoints = [];
const parents = {}; // child frame -> parent frame
const goals = new Map(); // seq -> {x, w}
const twists = new Map(); // seq -> angular.z
let serverInfo = null;

const tls = options.ca === undefined ? {} : { ca: readFileSync(options.ca) };
const ws = new WebSocket(
  options.url,
  [FoxgloveClient.SUPPORTED_SUBPROTOCOL, 'foxglove.sdk.v1'],
  tls,
);
const client = new FoxgloveClient({ ws });

client.on('serverInfo', (info) => {
  serverInfo = info;
});
client.on('error', (error) => finish(`client error: ${error}`));
client.on('close', (event) => finish(`closed by the server: ${event.code} ${event.reason}`));
client.on('advertise', (advertised) => {
  for (const channel of advertised) {
    const schemaBytes =
      channel.schemaEncoding === 'protobuf'
        ? Buffer.from(channel.schema, 'base64')
        : new TextEncoder().encode(channel.schema);
    const schema =
      wellKnown(channel.schemaName) ??
      (channel.encoding === 'json' ? JSON.parse(channel.schema) : undefined);
    channels.set(channel.id, {
      topic: channel.topic,
      decode: decoderFor(channel.encoding, channel.schemaName, schemaBytes),
      schema,
    });
    seen[channel.topic] = {
      schema: channel.schemaName,
      encoding: channel.encoding,
      messages: 0,
      problems: [],
    };
    for (let i = 0; i < (options.flood ?? 0); i++) client.unsubscribe(client.subscribe(channel.id));
    subscriptions.set(client.subscribe(channel.id), channel.id);
  }
});
client.on('message', ({ subscriptionId, data }) => {
  const channel = channels.get(subscriptions.get(subscriptionId));
  if (channel === undefined) return;
  const entry = seen[channel.topic];
  entry.messages += 1;
  let message;
  try {
    message = channel.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
  } catch (error) {
    entry.problems.push(`undecodable: ${error}`);
    return;
  }
  if (channel.schema === undefined) entry.problems.push(`no schema to check ${entry.schema}`);
  else if (entry.problems.length < 5) entry.problems.push(...validate(channel.schema, message));
  inspect(entry.schema, channel.topic, message);
  if (done()) finish(null);
});

function inspect(schemaName, topic, message) {
  if (schemaName === 'foxglove.CompressedImage') {
    const size = jpegSize(message.data);
    imageSizes.add(size === null ? 'not a JPEG' : `${size.width}x${size.height}`);
  } else if (schemaName === 'foxglove.ImageAnnotations') {
    for (const c of message.circles) annotationPoints.push(c.position);
    for (const p of message.points) annotationPoints.push(...p.points);
    for (const t of message.texts) annotationPoints.push(t.position);
  } else if (schemaName === 'foxglove.FrameTransforms') {
    for (const t of message.transforms) parents[t.child_frame_id] = t.parent_frame_id;
  } else if (topic === options.goalTopic) {
    goals.set(message.seq, { x: message.x, w: message.w });
  } else if (topic === options.twistTopic && message.seq !== null) {
    // The turn where Foxglove's Plot reads it (geometry_msgs/Twist's `angular.z`).
    twists.set(message.seq, message.angular.z);
  }
}

// The side of goal `seq` (-1 left, 1 right), 0 when it is too near the centre or unknown.
function side(seq) {
  const goal = goals.get(seq);
  if (goal === undefined || Math.abs(goal.x - goal.w / 2) < CLEAR_SIDE * goal.w) return 0;
  return goal.x < goal.w / 2 ? -1 : 1;
}

// Each Twist that answered a goal well off centre, after goals on that side for a while (the
// robot's accelerations ramp a turn from the other side): does it turn toward the goal's side
// (left of centre: counter-clockwise, angular.z > 0)? Not every one must: the law steers to
// where the target was when its frame was captured, so a robot that has turned past it since
// (the synthetic face does not move with the robot, and a loaded machine adds latency) turns
// back, rightly. The test asks most of them to.
function twistSides() {
  const compared = [];
  for (const [seq, angular] of twists) {
    const s = side(seq);
    const steady = [1, 2, 3, 4, 5].every((back) => side(seq - back) === s);
    if (s === 0 || !steady || angular === 0) continue;
    compared.push({ seq, left: s < 0, angular });
  }
  return compared;
}

function chain(frame) {
  const frames = [frame];
  while (parents[frames.at(-1)] !== undefined && frames.length < 10) {
    frames.push(parents[frames.at(-1)]);
  }
  return frames;
}

function done() {
  const topicsSeen = options.topics.every((t) => seen[t]?.messages > 0);
  return topicsSeen && twistSides().length >= options.twists;
}

let finished = false;
function finish(error) {
  if (finished) return;
  finished = true;
  clearTimeout(timer);
  const result = {
    error,
    capabilities: serverInfo?.capabilities ?? null,
    topics: seen,
    imageSizes: [...imageSizes],
    annotationPoints,
    cameraChain: chain('camera'),
    twistSides: twistSides(),
  };
  client.close();
  // Exit once the line is out: a pipe takes it in pieces.
  process.stdout.write(JSON.stringify(result) + '\n', () => process.exit(0));
}

const timer = setTimeout(() => finish('timed out'), options.timeoutS * 1000);
