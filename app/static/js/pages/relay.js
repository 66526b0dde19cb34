// The relay page (the thesis's "intermediate server"): answers the vehicle's and the clients'
// offers, forwards the vehicle's video to every client, and while piloting feeds the frames on
// show to the snapshot loop (snapshot-loop.js), whose goals go to the vehicle on the
// `autopilot` channel and whose detections go to the clients on `control`. This module is the
// page: connections, control messages, scheduling the frames and the DOM.
import { LinkMeter } from '../net/link-health.js';
import { BadMessage, Peer, preferLowLatency, sendJson, serveChannel } from '../net/peer.js';
import { CHANNELS, CONFIG, PROTOCOL, SCHEMAS } from '../config.js';
import { RoomSession } from '../net/room.js';
import { SnapshotLoop } from '../core/snapshot-loop.js';
import {
  byTestId,
  drawDetections,
  FIGURES_PERIOD_MS,
  fmt,
  Log,
  show,
  throttle,
} from '../view/ui.js';
import { createAnalyzer } from '../worker/vision.js';

const config = CONFIG;
const log = new Log(byTestId('log'));
const room = new RoomSession(config, log);
const video = byTestId('video');
const overlay = byTestId('overlay');

// null: a snapshot per decoded video frame; otherwise one every this many ms.
const SNAPSHOT_PERIOD_MS = PROTOCOL.relayProfiles[config.profile].snapshotPeriodMs;
// Whether the page shows the vehicle's video. An unattended relay (`?preview=0`, as `autopilot
// relay` opens it) that reads frames from the decoder needs no preview, and drawing one cost
// Chromium's compositor about 0.08 cores at 30 fps (docs/bench/relay-cost.md). The thesis
// profile snapshots the video element, so it always shows it.
const PREVIEW =
  config.preview || SNAPSHOT_PERIOD_MS !== null || typeof MediaStreamTrackProcessor !== 'function';

/**
 * The page's one status object, read-only, for tests and benchmarks: its fields are the
 * declared interface (docs/contracts.md, "Role pages"); nothing else of the page is.
 */
const status = {
  profile: config.profile,
  analyzerReady: false,
  opencvBuild: null, // 'simd' or 'official', once the analyzer is ready
  op: null,
  piloting: false,
  vehicle: null, // name of the connected vehicle
  clients: [], // names of connected clients
  vehicleTracks: 0, // vehicle video tracks received (a vehicle that comes back brings a new one)
  lock: 'none', // the target lock's state (lock.js)
  operator: null, // the client holding the wheel (manual override), or null: the autopilot steers
  drivesForwarded: 0,
  get snapshots() {
    return session.loop?.stats.snapshots ?? 0;
  },
  get goalsSent() {
    return session.loop?.stats.goalsSent ?? 0;
  },
  get lastGoal() {
    return session.loop?.lastGoal ?? null;
  },
  get lastDetections() {
    return session.loop?.lastDetections ?? null;
  },
  /** Snapshot taken -> goal sent (or analysis done when nothing was found), ms, oldest first. */
  get processingMs() {
    return session.loop?.stats.processing.toArray() ?? [];
  },
  /** Of which in the vision worker: pixels read and detection. */
  get workMs() {
    return session.loop?.stats.work.toArray() ?? [];
  },
  /** Of which the operation's detect() alone. */
  get detectMs() {
    return session.loop?.stats.detect.toArray() ?? [];
  },
  /** performance.now() of the goals sent in the last rate window. */
  get goalTimes() {
    return [...(session.loop?.stats.goalTimes ?? [])];
  },
};
window.autopilotStatus = status;
/**
 * The bench's one other entry point (status stays plain data, cloneable by tests): resolves to
 * {wasmHeapBytes}, the analyzer's OpenCV WASM heap size (analyzer.memory()), or null.
 */
window.autopilotMemory = () =>
  session.analyzer === null ? Promise.resolve(null) : session.analyzer.memory();

/** Everything else this page holds, in one place. */
const session = {
  peers: new Map(), // remote name -> {peer, role, channel}
  signalQueues: new Map(), // remote name -> promise of its last signaling message handled
  vehicleTrack: null,
  analyzer: null,
  loop: null, // the SnapshotLoop, once the analyzer is ready
  timer: null, // a profile with a snapshot period: its interval
  frameCallback: null, // a snapshot per frame: the pending requestVideoFrameCallback
  frameReader: null, // default profile: the reader of the vehicle track's decoded frames
  driveSeq: 0, // the seq of the last drive command forwarded to the vehicle
};

const ANALYZER_SLOW_MS = 30000;
const slowAnalyzer = setTimeout(
  () => log.warn(`OpenCV.js is still loading after ${ANALYZER_SLOW_MS / 1000} s`),
  ANALYZER_SLOW_MS,
);
const analyzerReady = createAnalyzer()
  .finally(() => clearTimeout(slowAnalyzer))
  .then(
    (created) => {
      session.analyzer = created;
      session.loop = createLoop(created);
      if (status.piloting) session.loop.start(); // asked to pilot while OpenCV.js was loading
      status.analyzerReady = true;
      status.opencvBuild = created.build;
      status.op = created.defaultOp;
      show('operation', status.op);
      const ops = created.ops.map((op) => op.id).join(', ');
      log.info(`OpenCV.js (${created.build} build) ready: operations ${ops}`);
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
  // The vehicle's link is measured here, where its video is received (link health).
  const entry = {
    peer,
    role,
    channel: null,
    stateChannel: null,
    meter: role === 'vehicle' ? new LinkMeter(peer.pc) : null,
  };
  peer.addEventListener('track', (event) => {
    if (role === 'vehicle' && event.detail.track.kind === 'video') onVehicleTrack(event.detail);
  });
  peer.addEventListener('datachannel', (event) => onDataChannel(entry, event.detail));
  peer.addEventListener('state', (event) => {
    if (event.detail === 'failed' && session.peers.get(name) === entry)
      closePeer(name, 'connection failed');
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
  if (entry.role === 'client' && status.operator === name) {
    // The failsafe: the operator's link is gone, so nobody drives and the autopilot stays off.
    if (status.piloting) setPiloting(false, `operator ${name} leaving`);
    setOperator(null, `operator ${name} left`);
  }
  if (entry.role === 'vehicle') {
    session.vehicleTrack = null;
    video.srcObject = null;
    for (const client of clientEntries()) {
      sendVideoOn(client.peer.pc).catch((err) =>
        log.error(`could not stop forwarding video: ${err.message}`),
      );
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
    log.warn(
      `offer from ${msg.from} does not fit the old connection (${err.message}); starting a new one`,
    );
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
  const next = previous
    .then(run)
    .catch((err) => log.error(`negotiation with ${msg.from} failed: ${err.message}`));
  session.signalQueues.set(msg.from, next);
}

/** Send the vehicle's video (or nothing yet) on every video transceiver of a client's link. */
async function sendVideoOn(pc) {
  for (const transceiver of pc.getTransceivers()) {
    if (transceiver.stopped || transceiver.receiver.track.kind !== 'video') continue;
    // The client offers recvonly; answering sendonly lets the track change later with no
    // renegotiation, which this side could not start anyway.
    if (pc.signalingState === 'have-remote-offer') transceiver.direction = 'sendonly';
    // Chromium's default degradation (balanced) on purpose: see vehicle.js.
    await transceiver.sender.replaceTrack(session.vehicleTrack);
    await forwardSmaller(transceiver.sender);
  }
}

/**
 * Encode the forward to a client at PROTOCOL.clientForwardScaleDown of the vehicle's size per
 * side: the encode is the relay's largest cost after the cascade (docs/bench/relay-cost.md).
 */
async function forwardSmaller(sender) {
  const params = sender.getParameters();
  // Before the answer the sender may have no encoding yet; sendVideoOn runs again with the track.
  if (params.encodings.length === 0) return;
  const scale = PROTOCOL.clientForwardScaleDown;
  if (params.encodings.every((encoding) => encoding.scaleResolutionDownBy === scale)) return;
  for (const encoding of params.encodings) encoding.scaleResolutionDownBy = scale;
  await sender.setParameters(params);
}

function onVehicleTrack({ track, receiver }) {
  // Goals are worth most when fresh: a decoded frame is shown (and analysed) at once.
  preferLowLatency(receiver);
  session.vehicleTrack = track;
  status.vehicleTracks += 1;
  // A new video starts with a full scan, not a window where the old one last saw its target.
  session.analyzer
    ?.resetTracking()
    .catch((err) => log.error(`could not reset tracking: ${err.message}`));
  if (status.piloting && session.timer === null) {
    stopLoop();
    startLoop();
  }
  if (PREVIEW) video.srcObject = new MediaStream([track]);
  log.info('vehicle video arrived; forwarding it to the clients');
  for (const client of clientEntries()) {
    sendVideoOn(client.peer.pc).catch((err) =>
      log.error(`could not forward video: ${err.message}`),
    );
  }
}

function onDataChannel(entry, channel) {
  const name = entry.peer.remote;
  if (entry.role === 'vehicle' && channel.label === CHANNELS.autopilotState) {
    // Goals go out and pose comes in here: unordered, never retransmitted, latest wins.
    serveChannel(
      channel,
      { pose: (msg) => onPose(msg) },
      log,
      SCHEMAS[CHANNELS.autopilotState].relay,
    );
    channel.addEventListener('open', () => {
      entry.stateChannel = channel;
    });
    channel.addEventListener('close', () => {
      if (entry.stateChannel === channel) entry.stateChannel = null;
    });
    return;
  }
  if (entry.role === 'vehicle' && channel.label === CHANNELS.autopilot) {
    serveChannel(channel, { pose: (msg) => onPose(msg) }, log, SCHEMAS.autopilot.relay);
    channel.addEventListener('open', () => {
      entry.channel = channel;
      status.vehicle = name;
      log.info(`autopilot channel to vehicle ${name} open`);
      if (status.operator !== null) sendJson(channel, modeMessage('an operator holds the wheel'));
      broadcastState();
      updatePeers();
    });
  } else if (entry.role === 'client' && channel.label === CHANNELS.control) {
    serveChannel(
      channel,
      {
        getOps: () => sendOps(entry),
        setOp: (msg) => setOp(msg, name),
        start: () => setPiloting(true, name),
        stop: () => setPiloting(false, name),
        lock: (msg) => lockAt(msg, name),
        unlock: () => unlock(`released by ${name}`),
        takeOver: () => takeOver(name),
        handBack: () => handBack(name),
        drive: (msg) => forwardDrive(msg, name),
      },
      log,
      SCHEMAS.control.relay,
    );
    channel.addEventListener('open', () => {
      entry.channel = channel;
      log.info(`control channel to client ${name} open`);
      sendJson(channel, stateMessage());
      sendJson(channel, modeMessage(null));
      if (session.loop !== null) sendJson(channel, session.loop.lockMessage());
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
  if (session.analyzer === null) throw new BadMessage('operations are still loading; try again');
  if (!session.analyzer.ops.some((op) => op.id === msg.op)) {
    throw new BadMessage(`unknown operation "${msg.op}"; the current one stays "${status.op}"`);
  }
  if (msg.op !== status.op) {
    log.info(`operation ${status.op} → ${msg.op} (asked by ${from})`);
    unlock(`the operation changed to ${msg.op}`);
  }
  status.op = msg.op;
  session.loop.op = msg.op;
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

// ---------------------------------------------------------------- manual override

function modeMessage(reason) {
  const mode = status.operator === null ? 'auto' : 'manual';
  return { type: 'mode', mode, operator: status.operator, ...(reason ? { reason } : {}) };
}

/** Give the wheel to `name` (null: back to the autopilot); tell the vehicle and every client. */
function setOperator(name, reason) {
  status.operator = name;
  session.driveSeq = 0; // the vehicle numbers each operator's commands afresh
  const message = modeMessage(reason);
  log.info(`${name === null ? 'autopilot steers' : `${name} has the wheel`} (${reason})`);
  show('mode', name === null ? 'autopilot' : `manual: ${name}`);
  sendJson(vehicleEntry()?.channel, message);
  broadcast(message);
}

function takeOver(from) {
  if (status.operator === from) return;
  if (status.operator !== null) {
    throw new BadMessage(`${status.operator} is driving; take over once they hand back or leave`);
  }
  setOperator(from, `taken over by ${from}`);
}

function handBack(from) {
  if (status.operator !== from) {
    throw new BadMessage(
      status.operator === null
        ? 'nobody holds the wheel'
        : `${status.operator} holds the wheel, not ${from}`,
    );
  }
  setOperator(null, `handed back by ${from}`);
}

/** The operator's drive command, renumbered for the vehicle (latest wins on the lossy channel). */
function forwardDrive(msg, from) {
  if (status.operator !== from) {
    throw new BadMessage(
      status.operator === null
        ? 'take over before driving'
        : `${status.operator} is driving, not ${from}`,
    );
  }
  const vehicle = vehicleEntry();
  session.driveSeq += 1;
  const drive = { type: 'drive', seq: session.driveSeq, linear: msg.linear, angular: msg.angular };
  if (!sendJson(vehicle?.stateChannel ?? vehicle?.channel, drive))
    throw new BadMessage('no vehicle connected');
  status.drivesForwarded += 1;
}

// ---------------------------------------------------------------- target lock

/** A client clicked frame pixel (x, y): lock on the box there, or release (lock.js). */
function lockAt(msg, from) {
  if (session.loop === null) throw new BadMessage('operations are still loading; try again');
  if (session.loop.lockAt(msg.x, msg.y))
    log.info(`locked on the target at (${fmt(msg.x, 0)}, ${fmt(msg.y, 0)}) for ${from}`);
}

function unlock(reason) {
  session.loop?.unlock(reason);
}

function onLockChanged(message) {
  const where = message.box ? ` at [${message.box.map((v) => fmt(v, 0)).join(', ')}]` : '';
  log.info(`target lock: ${message.state}${where}${message.reason ? ` (${message.reason})` : ''}`);
  status.lock = message.state;
  show('lock', message.state === 'none' ? 'none (largest)' : message.state);
  broadcast(message);
}

/** Forward the vehicle's pose (validated by serveChannel) to every client. */
function onPose(msg) {
  const pose = { type: 'pose', x: msg.x, y: msg.y, theta: msg.theta, t: msg.t ?? Date.now() };
  broadcast(msg.goalAgeMs === undefined ? pose : { ...pose, goalAgeMs: msg.goalAgeMs });
}

/** Once a period: the vehicle → relay link's figures, to every client (link health). */
async function reportHealth() {
  const vehicle = vehicleEntry();
  if (vehicle?.meter == null || clientEntries().length === 0) return;
  try {
    broadcast({ type: 'health', link: await vehicle.meter.read() });
  } catch (err) {
    log.warn(`could not read the vehicle link's statistics: ${err.message}`);
  }
}
setInterval(reportHealth, PROTOCOL.health.periodS * 1000);

// ---------------------------------------------------------------- snapshot loop

function createLoop(analyzer) {
  const loop = new SnapshotLoop({
    analyzer,
    profile: config.profile,
    op: analyzer.defaultOp,
    // Between full scans, search only around the last target (the spec's fullScanEvery).
    track: true,
    lockRule: PROTOCOL.lock,
    // The lossy state channel when it is open (latest wins), else the reliable one.
    sendGoal: (goal) => {
      const vehicle = vehicleEntry();
      return sendJson(vehicle?.stateChannel ?? vehicle?.channel, goal);
    },
  });
  let latest = null;
  const showFigures = throttle(FIGURES_PERIOD_MS, () => {
    show('goals-sent', String(loop.stats.goalsSent));
    show('ms-per-snapshot', fmt(latest.ms));
    show('goals-per-s', fmt(latest.goalsPerS));
  });
  loop.addEventListener('detections', (event) => {
    latest = event.detail;
    broadcast(latest);
    if (PREVIEW) drawDetections(overlay, latest);
    showFigures();
  });
  loop.addEventListener('lock', (event) => onLockChanged(event.detail));
  loop.addEventListener('failure', (event) => log.error(`snapshot failed: ${event.detail}`));
  return loop;
}

/** Feed the loop the frame on show: on every decoded frame, or every snapshot period. */
function startLoop() {
  session.loop?.start();
  if (SNAPSHOT_PERIOD_MS !== null) {
    session.timer = setInterval(snapshot, SNAPSHOT_PERIOD_MS);
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
      if (session.loop?.busy || !status.piloting || session.frameReader !== reader) frame.close();
      else snapshot(frame);
    }
  } catch (err) {
    log.error(`reading video frames failed: ${err.message}`);
  }
}

function stopLoop() {
  session.loop?.stop();
  if (session.timer !== null) clearInterval(session.timer);
  if (session.frameCallback !== null) video.cancelVideoFrameCallback(session.frameCallback);
  session.frameReader?.cancel().catch(() => {}); // the stream may have ended with its track
  session.timer = null;
  session.frameCallback = null;
  session.frameReader = null;
}

/**
 * Hand the loop a frame, unless it is still busy with the last one: `frame` is a decoded
 * VideoFrame (owned from here on), or null for the frame the video element shows.
 */
function snapshot(frame = null) {
  if (session.loop === null || session.loop.busy || (frame === null && video.videoWidth === 0)) {
    frame?.close();
    return;
  }
  // A VideoFrame wraps the decoded picture without copying it; the worker converts it to RGBA
  // straight into OpenCV's memory.
  session.loop.frame(frame ?? new VideoFrame(video));
}

// ---------------------------------------------------------------- page

function updatePeers() {
  status.clients = clientEntries().map((entry) => entry.peer.remote);
  const lines = [...session.peers.entries()].map(([name, entry]) => {
    const open = entry.channel ? ', channel open' : '';
    return `${entry.role} ${name} (${entry.peer.pc.connectionState}${open})`;
  });
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
room.addEventListener('problem', showState);
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
