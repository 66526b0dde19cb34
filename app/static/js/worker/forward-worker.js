// The relay's pass-through forward, in a worker of its own (net/video-forward.js starts it):
// the vehicle's encoded frames, read by an RTCRtpScriptTransform on the relay's receiver, go on
// to the relay's own decoder (the analysis) and, copied, to every client's sender as they are,
// so nothing is decoded and encoded again for the clients. A client gets them only where they
// decode there (core/payload-types.js `passesThrough`); whether each client does is posted back
// as it changes (`{type: 'mode', name, passing}`), and the page then encodes for that client
// instead. Messages in:
//   {type: 'vehicleCodecs', codecs}  the codecs the vehicle sends with (the relay's answer's)
//   {type: 'addSink', name, readable, writable, codecs}  a client's sender's encoded streams
//     (createEncodedStreams) and the codecs it receives (its offer's)
//   {type: 'removeSink', name}
//   {type: 'keyFrame'}  ask the vehicle for a key frame (a client joined, or lost one)
import { passesThrough } from '../core/payload-types.js';
import { ContinuousTimestamps } from '../core/rtp-timestamps.js';

// The vehicle is asked for a key frame at most this often: a key frame is several times the
// size of a delta frame, and several clients asking at once need only one.
const KEY_FRAME_EVERY_MS = 250;

const sinks = new Map(); // client name -> {writer, codecs, passing: boolean | null}
let vehicleCodecs = [];
let vehicle = null; // the RTCRtpScriptTransformer of the served vehicle's video
let keyFrameAskedAt = -Infinity;
const timestamps = new ContinuousTimestamps(); // one timeline across vehicles for the clients

self.onrtctransform = ({ transformer }) => {
  // One vehicle at a time: a new receiver's transform is the vehicle that now holds the seat.
  vehicle = transformer;
  // A vehicle that came back (a reload) is a new stream: the clients' decoders need its key frame,
  // whatever was asked of the vehicle before.
  keyFrameAskedAt = -Infinity;
  pump(transformer);
};

self.onmessage = ({ data }) => {
  switch (data.type) {
    case 'vehicleCodecs':
      vehicleCodecs = data.codecs;
      break;
    case 'addSink':
      addSink(data);
      break;
    case 'removeSink':
      sinks.delete(data.name);
      break;
    case 'keyFrame':
      askKeyFrame();
      break;
    default:
      throw new Error(`forward-worker: unknown message type "${data.type}"`);
  }
};

async function pump(transformer) {
  const reader = transformer.readable.getReader();
  const writer = transformer.writable.getWriter();
  let first = true;
  for (;;) {
    const { value: frame, done } = await reader.read();
    if (done) return;
    if (transformer === vehicle) {
      // The transform may start after the stream's opening key frame went by: without a key
      // frame the clients' decoders show nothing until they ask for one themselves.
      if (first && frame.type !== 'key') askKeyFrame();
      forward(frame, transformer);
    }
    first = false;
    await writer.write(frame);
  }
}

function forward(frame, stream) {
  const metadata = frame.getMetadata();
  const { payloadType } = metadata;
  const rtpTimestamp = timestamps.next(stream, metadata.rtpTimestamp);
  const options =
    rtpTimestamp === metadata.rtpTimestamp ? {} : { metadata: { ...metadata, rtpTimestamp } };
  for (const [name, sink] of sinks) {
    const passing = passesThrough(payloadType, vehicleCodecs, sink.codecs);
    if (passing !== sink.passing) {
      sink.passing = passing;
      postMessage({ type: 'mode', name, passing });
    }
    // A copy per client: writing a frame hands it over. A sink whose connection closed refuses
    // it, and goes with its client.
    if (passing) sink.writer.write(new RTCEncodedVideoFrame(frame, options)).catch(() => {});
  }
}

function addSink({ name, readable, writable, codecs }) {
  const writer = writable.getWriter();
  sinks.set(name, { writer, codecs, passing: null });
  // The sender's own encoder's frames, while it encodes for this client (no pass-through):
  // they go out as they are.
  (async () => {
    const reader = readable.getReader();
    for (;;) {
      const { value: frame, done } = await reader.read();
      if (done) return;
      await writer.write(frame);
    }
  })().catch(() => {});
}

function askKeyFrame() {
  const now = performance.now();
  if (vehicle === null || now - keyFrameAskedAt < KEY_FRAME_EVERY_MS) return;
  keyFrameAskedAt = now;
  // Rejected while the receiver has no frame yet: its first one is a key frame anyway.
  vehicle.sendKeyFrameRequest().catch(() => {});
}
