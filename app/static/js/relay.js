// The relay page (the thesis's "intermediate server"): answers the vehicle's and the clients'
// offers, forwards the vehicle's video to every client, runs the selected OpenCV.js operation
// on snapshots while piloting and sends goals to the vehicle on the `autopilot` channel.
import { BadMessage, Peer, preferLowLatency, requireNumber, sendJson, serveChannel } from './peer.js';
import { RoomSession } from './room.js';
import { byTestId, drawDetections, fmt, Log, readConfig, show } from './ui.js';
import { createAnalyzer } from './vision.js';

const THESIS_PERIOD_MS = 1500;
const RATE_WINDOW_MS = 2000;
const MS_SAMPLES = 2000;

/**
 * The latest `capacity` samples, in storage allocated once: a ring that fills up must not look
 * like heap growth to a memory check. `toArray()` gives them oldest first.
 */
class SampleRing {
  constructor(capacity) {
    this.values = new Float64Array(capacity);
    this.count = 0;
    this.next = 0;
  }

  push(value) {
    this.values[this.next] = value;
    this.next = (this.next + 1) % this.values.length;
    this.count = Math.min(this.count + 1, this.values.length);
  }

  toArray() {
    const start = (this.next - this.count + this.values.length) % this.values.length;
    return Array.from({ length: this.count }, (_, i) => this.values[(start + i) % this.values.length]);
  }
}

const config = readConfig();
const log = new Log(byTestId('log'));
const room = new RoomSession(config, log);
const video = byTestId('video');
const overlay = byTestId('overlay');

/** The page's one session object, read-only for tests and benchmarks. */
const status = {
  profile: config.profile,
  analyzerReady: false,
  op: null,
  piloting: false,
  vehicle: null, // name of the connected vehicle
  clients: [], // names of connected clients
  vehicleTracks: 0, // vehicle video tracks received (a vehicle that comes back brings a new one)
  snapshots: 0,
  goalsSent: 0,
  lastGoal: null,
  lastDetections: null,
  /** Snapshot taken -> goal sent (or analysis done when nothing was found), ms, oldest first. */
  get processingMs() {
    return session.samples.processing.toArray();
  },
  /** Of which in the vision worker: pixels read and detection. */
  get workMs() {
    return session.samples.work.toArray();
  },
  /** Of which the operation's detect() alone. */
  get detectMs() {
    return session.samples.detect.toArray();
  },
  goalTimes: [], // performance.now() of recent goals, for goals per second
};
window.autopilotStatus = status;

/** Everything else this page holds, in one place. */
const session = {
  peers: new Map(), // remote name -> {peer, role, channel}
  signalQueues: new Map(), // remote name -> promise of its last signaling message handled
  vehicleTrack: null,
  analyzer: null,
  lastError: null, // the last snapshot failure, logged once
  busy: false, // a snapshot is being analysed
  timer: null, // thesis profile: the snapshot interval
  frameCallback: null, // default profile without MediaStreamTrackProcessor: the pending rVFC
  frameReader: null, // default profile: the reader of the vehicle track's decoded frames
  // Per-snapshot timings behind status.processingMs, workMs and detectMs.
  samples: {
    processing: new SampleRing(MS_SAMPLES),
    work: new SampleRing(MS_SAMPLES),
    detect: new SampleRing(MS_SAMPLES),
  },
};

const ANALYZER_SLOW_MS = 30000;
const slowAnalyzer = setTimeout(
  () => log.warn(`OpenCV.js is still loading after ${ANALYZER_SLOW_MS / 1000} s`),
  ANALYZER_SLOW_MS,
);
const analyzerReady = createAnalyzer().finally(() => clearTimeout(slowAnalyzer)).then(
  (created) => {
    session.analyzer = created;
    status.analyzerReady = true;
    status.op = created.defaultOp;
    show('operation', status.op);
    log.info(`OpenCV.js ready: operations ${created.ops.map((op) => op.id).join(', ')}`);
    broadcastState();
    return created;
  },
  (err) => {
    log.error(`OpenCV.js analyzer could not start: ${err.message}`);
    show('operation', 'unavailable');
    return null;
  },
);

// ---------------------------------------------------------------- connections

function roleOf(name) {
  return room.roster.find((peer) => peer.name === name)?.role;
}

function clientEntries() {
  return [...session.peers.values()].filter((entry) => entry.role === 'client');
}

function vehicleEntry() {
  return [...session.peers.values()].find((entry) => entry.role === 'vehicle');
}

function createPeer(name, role) {
  const peer = new Peer({
    remote: name,
    polite: true,
    mayOffer: false,
    ice: room.ice,
    send: (msg) => room.send(msg),
    log,
    beforeAnswer: role === 'client' ? (pc) => sendVideoOn(pc) : undefined,
  });
  const entry = { peer, role, channel: null, stateChannel: null };
  peer.addEventListener('track', (event) => {
    if (role === 'vehicle' && event.detail.track.kind === 'video') onVehicleTrack(event.detail);
  });
  peer.addEventListener('datachannel', (event) => onDataChannel(entry, event.detail));
  peer.addEventListener('state', (event) => {
    if (event.detail === 'failed' && session.peers.get(name) === entry) closePeer(name, 'connection failed');
    updatePeers();
  });
  session.peers.set(name, entry);
  updatePeers();
  return entry;
}

function closePeer(name, reason) {
  const entry = session.peers.get(name);
  if (entry === undefined) return;
  session.peers.delete(name);
  entry.peer.close();
  log.info(`connection with ${name} closed: ${reason}`);
  if (entry.role === 'vehicle') {
    session.vehicleTrack = null;
    video.srcObject = null;
    for (const client of clientEntries()) {
      sendVideoOn(client.peer.pc).catch((err) => log.error(`could not stop forwarding video: ${err.message}`));
    }
    status.vehicle = null;
    broadcastState();
  }
  updatePeers();
}

async function onOffer(msg) {
  const role = roleOf(msg.from);
  if (role !== 'vehicle' && role !== 'client') {
    log.warn(`ignored an offer from ${msg.from}: not a vehicle or client of this room`);
    return;
  }
  let entry = session.peers.get(msg.from);
  if (entry === undefined || entry.peer.closed) entry = createPeer(msg.from, role);
  try {
    await entry.peer.handle(msg);
  } catch (err) {
    // A peer that reloaded offers a new DTLS identity to our old connection: start afresh.
    log.warn(`offer from ${msg.from} does not fit the old connection (${err.message}); starting a new one`);
    closePeer(msg.from, 'replaced');
    entry = createPeer(msg.from, role);
    await entry.peer.handle(msg);
  }
}

/** Queue a signaling message per sender, so an offer is applied before its candidates. */
function onPeerSignal(msg) {
  const run = async () => {
    if (msg.type === 'offer') await onOffer(msg);
    else await session.peers.get(msg.from)?.peer.handle(msg);
  };
  const previous = session.signalQueues.get(msg.from) ?? Promise.resolve();
  const next = previous.then(run).catch((err) => log.error(`negotiation with ${msg.from} failed: ${err.message}`));
  session.signalQueues.set(msg.from, next);
}

/** Send the vehicle's video (or nothing yet) on every video transceiver of a client's connection. */
async function sendVideoOn(pc) {
  for (const transceiver of pc.getTransceivers()) {
    if (transceiver.stopped || transceiver.receiver.track.kind !== 'video') continue;
    // The client offers recvonly; answering sendonly lets the track change later with no
    // renegotiation, which this side could not start anyway.
    if (pc.signalingState === 'have-remote-offer') transceiver.direction = 'sendonly';
    await transceiver.sender.replaceTrack(session.vehicleTrack);
  }
}

function onVehicleTrack({ track, receiver }) {
  // Goals are worth most when fresh: a decoded frame is shown (and analysed) at once.
  preferLowLatency(receiver);
  session.vehicleTrack = track;
  status.vehicleTracks += 1;
  // A new video starts with a full scan, not a window where the old one last saw its target.
  session.analyzer?.resetTracking().catch((err) => log.error(`could not reset tracking: ${err.message}`));
  if (status.piloting && session.timer === null) {
    stopLoop();
    startLoop();
  }
  video.srcObject = new MediaStream([track]);
  log.info('vehicle video arrived; forwarding it to the clients');
  for (const client of clientEntries()) {
    sendVideoOn(client.peer.pc).catch((err) => log.error(`could not forward video: ${err.message}`));
  }
}

function onDataChannel(entry, channel) {
  const name = entry.peer.remote;
  if (entry.role === 'vehicle' && channel.label === config.channels.state.label) {
    // Goals go out and pose comes in here: unordered, never retransmitted, latest wins.
    serveChannel(channel, { pose: (msg) => onPose(msg) }, log);
    channel.addEventListener('open', () => {
      entry.stateChannel = channel;
    });
    channel.addEventListener('close', () => {
      if (entry.stateChannel === channel) entry.stateChannel = null;
    });
    return;
  }
  if (entry.role === 'vehicle' && channel.label === config.channels.control) {
    serveChannel(channel, { pose: (msg) => onPose(msg) }, log);
    channel.addEventListener('open', () => {
      entry.channel = channel;
      status.vehicle = name;
      log.info(`autopilot channel to vehicle ${name} open`);
      broadcastState();
      updatePeers();
    });
  } else if (entry.role === 'client' && channel.label === 'control') {
    serveChannel(
      channel,
      {
        getOps: () => sendOps(entry),
        setOp: (msg) => setOp(msg, name),
        start: () => setPiloting(true, name),
        stop: () => setPiloting(false, name),
      },
      log,
    );
    channel.addEventListener('open', () => {
      entry.channel = channel;
      log.info(`control channel to client ${name} open`);
      sendJson(channel, stateMessage());
      updatePeers();
    });
  } else {
    log.warn(`${entry.role} ${name} opened an unexpected data channel "${channel.label}"`);
    return;
  }
  channel.addEventListener('close', () => {
    if (entry.channel === channel) entry.channel = null;
    if (entry.role === 'vehicle' && status.vehicle === name) {
      status.vehicle = null;
      broadcastState();
    }
    updatePeers();
  });
}

// ---------------------------------------------------------------- control

function stateMessage() {
  return { type: 'state', piloting: status.piloting, op: status.op, vehicle: status.vehicle };
}

function broadcast(msg) {
  for (const client of clientEntries()) sendJson(client.channel, msg);
}

function broadcastState() {
  show('piloting', status.piloting ? 'yes' : 'no');
  if (status.op !== null) show('operation', status.op);
  showState();
  broadcast(stateMessage());
}

async function sendOps(entry) {
  const ready = await analyzerReady;
  if (ready === null) {
    const reason = 'the relay has no OpenCV.js analyzer (see its log)';
    sendJson(entry.channel, { type: 'error', reason, ref: 'getOps' });
    return;
  }
  sendJson(entry.channel, { type: 'ops', ops: ready.ops, current: status.op });
  sendJson(entry.channel, stateMessage());
}

function setOp(msg, from) {
  if (typeof msg.op !== 'string') throw new BadMessage('"setOp" needs a string "op"');
  if (session.analyzer === null) throw new BadMessage('operations are still loading; try again');
  if (!session.analyzer.ops.some((op) => op.id === msg.op)) {
    throw new BadMessage(`unknown operation "${msg.op}"; the current one stays "${status.op}"`);
  }
  if (msg.op !== status.op) log.info(`operation ${status.op} → ${msg.op} (asked by ${from})`);
  status.op = msg.op;
  broadcastState();
}

function setPiloting(on, from) {
  if (on === status.piloting) {
    broadcastState();
    return;
  }
  status.piloting = on;
  log.info(`${on ? 'piloting started' : 'piloting stopped'} by ${from}`);
  if (on) {
    startLoop();
  } else {
    stopLoop();
    sendJson(vehicleEntry()?.channel, { type: 'stop' });
  }
  broadcastState();
}

function onPose(msg) {
  const pose = {
    type: 'pose',
    x: requireNumber(msg, 'x'),
    y: requireNumber(msg, 'y'),
    theta: requireNumber(msg, 'theta'),
    t: typeof msg.t === 'number' ? msg.t : Date.now(),
  };
  broadcast(pose);
}

// ---------------------------------------------------------------- snapshot loop


function startLoop() {
  if (config.profile === 'thesis') {
    session.timer = setInterval(snapshot, THESIS_PERIOD_MS);
    return;
  }
  if (typeof MediaStreamTrackProcessor === 'function') {
    if (session.vehicleTrack !== null) readFrames(session.vehicleTrack);
    return;
  }
  const onFrame = () => {
    if (!status.piloting) return;
    session.frameCallback = video.requestVideoFrameCallback(onFrame);
    snapshot();
  };
  session.frameCallback = video.requestVideoFrameCallback(onFrame);
}

/**
 * Default profile: each frame straight from the decoder (MediaStreamTrackProcessor), without
 * waiting for the video element to present it. A frame that arrives while one is being
 * analysed is dropped, so the next snapshot is always the freshest frame.
 */
async function readFrames(track) {
  const reader = new MediaStreamTrackProcessor({ track }).readable.getReader();
  session.frameReader = reader;
  try {
    for (;;) {
      const { value: frame, done } = await reader.read();
      if (done) return;
      if (session.busy || !status.piloting || session.frameReader !== reader) frame.close();
      else snapshot(frame);
    }
  } catch (err) {
    log.error(`reading video frames failed: ${err.message}`);
  }
}

function stopLoop() {
  if (session.timer !== null) clearInterval(session.timer);
  if (session.frameCallback !== null) video.cancelVideoFrameCallback(session.frameCallback);
  session.frameReader?.cancel().catch(() => {}); // the stream may have ended with its track
  session.timer = null;
  session.frameCallback = null;
  session.frameReader = null;
}

/**
 * One snapshot → analysis → goal, unless one is already in flight. `frame`: a VideoFrame to
 * analyse (owned from here on), or null for the frame the video element shows.
 */
async function snapshot(frame = null) {
  if (session.busy || session.analyzer === null || (frame === null && video.videoWidth === 0)) {
    frame?.close();
    return;
  }
  session.busy = true;
  try {
    await analyzeOnce(frame);
    session.lastError = null;
  } catch (err) {
    // Every frame would repeat it: log a failure once until something succeeds again.
    if (err.message !== session.lastError) log.error(`snapshot failed: ${err.message}`);
    session.lastError = err.message;
  } finally {
    session.busy = false;
  }
}

async function analyzeOnce(decoded) {
  const started = performance.now();
  // A VideoFrame wraps the decoded picture without copying it; the worker converts it to RGBA
  // straight into OpenCV's memory.
  const frame = decoded ?? new VideoFrame(video);
  // track: between full scans, search only around the last target (the spec's fullScanEvery).
  const result = await session.analyzer.analyze(frame, status.op, { profile: config.profile, track: true });
  if (!status.piloting) return;
  status.snapshots += 1;
  if (result.target) {
    const goal = {
      type: 'goal',
      seq: status.goalsSent + 1,
      op: result.op,
      x: result.target.x,
      y: result.target.y,
      w: result.w,
      h: result.h,
      t: Date.now(),
    };
    if (result.frame !== null && result.frame !== undefined) goal.frame = result.frame;
    const vehicle = vehicleEntry();
    if (sendJson(vehicle?.stateChannel ?? vehicle?.channel, goal)) {
      status.goalsSent += 1;
      status.lastGoal = goal;
      status.goalTimes.push(performance.now());
    }
  }
  const ms = performance.now() - started;
  session.samples.processing.push(ms);
  session.samples.work.push(result.workMs);
  session.samples.detect.push(result.ms);
  const now = performance.now();
  while (status.goalTimes.length && now - status.goalTimes[0] > RATE_WINDOW_MS) status.goalTimes.shift();
  const goalsPerS = status.goalTimes.length / (RATE_WINDOW_MS / 1000);
  const detections = {
    type: 'detections',
    op: result.op,
    boxes: result.boxes,
    target: result.target,
    w: result.w,
    h: result.h,
    ms,
    goalsPerS,
  };
  status.lastDetections = detections;
  broadcast(detections);
  drawDetections(overlay, detections);
  show('goals-sent', String(status.goalsSent));
  show('ms-per-snapshot', fmt(ms));
  show('goals-per-s', fmt(goalsPerS));
}

// ---------------------------------------------------------------- page

function updatePeers() {
  status.clients = clientEntries().map((entry) => entry.peer.remote);
  const lines = [...session.peers.entries()].map(
    ([name, entry]) =>
      `${entry.role} ${name} (${entry.peer.pc.connectionState}${entry.channel ? ', channel open' : ''})`,
  );
  show('peers', lines.join('; ') || 'none');
}

function showState() {
  const piloting = status.piloting ? ` · piloting with ${status.op}` : '';
  show('state', `${room.describe()}${piloting}`);
}

room.bindControls();
room.addEventListener('phase', (event) => {
  showState();
  if (event.detail === 'disconnected') {
    // Stop first, while the vehicle's channel is still there to hear it.
    if (status.piloting) setPiloting(false, 'this relay leaving');
    for (const name of [...session.peers.keys()]) closePeer(name, 'left the room');
  }
});
room.addEventListener('roster', showState);
room.addEventListener('peerleft', (event) => {
  closePeer(event.detail, 'left the room');
  session.signalQueues.delete(event.detail);
});
room.addEventListener('signal', (event) => {
  const msg = event.detail;
  switch (msg.type) {
    case 'offer':
    case 'candidate':
      onPeerSignal(msg);
      break;
    case 'answer':
      log.warn(`ignored an answer from ${msg.from}: the relay never offers`);
      break;
    case 'start':
      setPiloting(true, msg.from);
      break;
    case 'stop':
      setPiloting(false, msg.from);
      break;
    case 'getOps': {
      // The answer rides the control channel; a client whose channel is not open yet asks
      // again on it once it opens.
      const entry = session.peers.get(msg.from);
      if (entry?.channel) sendOps(entry);
      break;
    }
    default:
      log.warn(`unexpected signaling message "${msg.type}" from ${msg.from}`);
  }
});
if (config.auto) room.autoJoin();
