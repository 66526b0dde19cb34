// The relay page (the thesis's "intermediate server"): answers the vehicle's and the clients'
// offers, forwards the vehicle's video to every client, and while piloting feeds the vehicle's
// frames to the snapshot loop, whose goals go to the vehicle on the `autopilot` channel and whose
// detections go to the clients on `control`. This module wires the parts and answers the
// clients' control messages:
// - net/relay-links.js: the peer connections, the vehicle seat and the video forwarding;
// - core/relay-seats.js: who holds the wheel (manual override), and who watches (the autopilot
//   drives only while a client does);
// - view/frame-source.js: how frames reach core/snapshot-loop.js, whose analyzer's worker owns
//   the target lock;
// - view/relay-view.js: what the page shows.
import { CONFIG, PROTOCOL } from '../config.js';
import { OneAtATime } from '../core/one-at-a-time.js';
import { OperatorSeat, Watchers } from '../core/relay-seats.js';
import { RobotStop } from '../core/robot-stop.js';
import { SnapshotLoop } from '../core/snapshot-loop.js';
import { BadMessage } from '../net/peer.js';
import { RelayLinks } from '../net/relay-links.js';
import { RoomSession } from '../net/room.js';
import { FrameSource } from '../view/frame-source.js';
import { RelayView } from '../view/relay-view.js';
import { byTestId, fmt, Log } from '../view/ui.js';
import { createAnalyzer } from '../worker/vision.js';

const config = CONFIG;
const log = new Log(byTestId('log'));
const room = new RoomSession(config, log);

const frames = new FrameSource({
  video: byTestId('video'),
  // null: a snapshot per decoded video frame; otherwise one every this many ms.
  periodMs: PROTOCOL.relayProfiles[config.profile].snapshotPeriodMs,
  onError: (err) => log.error(`reading video frames failed: ${err.message}`),
});
// Whether the page shows the vehicle's video. An unattended relay (`?preview=0`, as `autopilot
// relay` opens it) that reads frames from the decoder needs no preview, and drawing one costs
// Chromium's compositor (docs/bench/relay-cost.md). The frames of the thesis profile are the
// video element's, so it always shows it.
const view = new RelayView({ preview: config.preview || frames.readsVideoElement });

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
  /** Name of the connected vehicle (its autopilot channel open), or null. */
  get vehicle() {
    return session.links.vehicle;
  },
  /** Names of the connected clients. */
  get clients() {
    return session.links.clients;
  },
  vehicleTracks: 0, // vehicle video tracks received (a vehicle that comes back brings a new one)
  /** How each client gets the video: {name: 'pass-through' | 're-encode'} (relay-links.js). */
  get forwards() {
    return session.links.forwards;
  },
  lock: 'none', // the target lock's state (lock.js)
  /** The client holding the wheel (manual override), or null: the autopilot steers. */
  get operator() {
    return session.operator.holder;
  },
  /** The clients watching: in the room, their link not dropped (relay-seats.js Watchers). */
  get watchers() {
    return session.watchers.names;
  },
  /** The last robotStopped message ({by, reason}) while that stop stands, or null. */
  get stopped() {
    return session.stop.standing;
  },
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
  analyzer: null,
  loop: null, // the SnapshotLoop, once the analyzer is ready
  operator: new OperatorSeat(),
  watchers: new Watchers(),
  // The stop that stands until piloting starts again: a client that connects meanwhile hears
  // why the robot stands, and more presses meanwhile are no news.
  stop: new RobotStop(),
  // A client's lock and unlock clicks reach the analyzer one at a time, the newest waiting.
  lockRequests: new OneAtATime(),
  links: new RelayLinks({
    room,
    log,
    controlHandlers: (name) => ({
      getOps: () => sendOps(name),
      setOp: (msg) => setOp(msg, name),
      start: () => setPiloting(true, name),
      stop: () => setPiloting(false, name),
      stopRobot: () => stopRobot(name, `Stop robot pressed by ${name}`),
      lock: (msg) => lockAt(msg, name),
      unlock: () => unlock(`released by ${name}`),
      takeOver: () => takeOver(name),
      handBack: () => handBack(name),
      drive: (msg) => forwardDrive(msg, name),
    }),
    // The capture times go to every client as they came: each measures its own glass to glass.
    vehicleHandlers: { pose: onPose, frameTimes: (msg) => session.links.broadcast(msg) },
  }),
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
      frames.loop = session.loop;
      if (status.piloting) session.loop.start(); // asked to pilot while OpenCV.js was loading
      status.analyzerReady = true;
      status.opencvBuild = created.build;
      status.op = session.loop.op;
      view.operation(status.op);
      const ops = created.ops.map((op) => op.id).join(', ');
      log.info(`OpenCV.js (${created.build} build) ready: operations ${ops}`);
      broadcastState();
      return created;
    },
    (err) => {
      log.error(`OpenCV.js analyzer could not start: ${err.message}`);
      view.operation('unavailable');
      return null;
    },
  );

function createLoop(analyzer) {
  const loop = new SnapshotLoop({
    analyzer,
    profile: config.profile,
    // The vehicle profile's operation (config.operation), else the spec's default.
    op: analyzer.ops.some((op) => op.id === config.operation)
      ? config.operation
      : analyzer.defaultOp,
    // Between full scans, search only around the last target (the spec's fullScanEvery).
    track: true,
    sendGoal: (goal) => session.links.sendToVehicle(goal, { lossy: true }),
  });
  loop.addEventListener('detections', (event) => {
    session.links.broadcast(event.detail);
    view.detections(event.detail, loop.stats.goalsSent);
  });
  loop.addEventListener('lock', (event) => onLockChanged(event.detail));
  loop.addEventListener('failure', (event) => log.error(`snapshot failed: ${event.detail}`));
  return loop;
}

// ---------------------------------------------------------------- piloting

function stateMessage() {
  return { type: 'state', piloting: status.piloting, op: status.op, vehicle: status.vehicle };
}

function broadcastState() {
  view.piloting(status.piloting);
  if (status.op !== null) view.operation(status.op);
  showState();
  session.links.broadcast(stateMessage());
}

async function sendOps(name) {
  const ready = await analyzerReady;
  if (ready === null) {
    const reason = 'the relay has no OpenCV.js analyzer (see its log)';
    session.links.sendTo(name, { type: 'error', reason, ref: 'getOps' });
    return;
  }
  session.links.sendTo(name, { type: 'ops', ops: ready.ops, current: status.op });
  session.links.sendTo(name, stateMessage());
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
  if (on && session.watchers.names.length === 0) {
    // The autopilot drives only while someone watches (a start from a client whose link dropped).
    log.warn(`not piloting for ${from}: no client is watching`);
    const reason = 'no client is watching the robot, so piloting stays off';
    session.links.sendTo(from, { type: 'error', reason, ref: 'start' });
    broadcastState();
    return;
  }
  if (on === status.piloting) {
    broadcastState();
    return;
  }
  status.piloting = on;
  log.info(`${on ? 'piloting started' : 'piloting stopped'} by ${from}`);
  if (on) {
    session.stop.clear();
    session.loop?.start();
    frames.start();
  } else {
    haltPiloting();
  }
  broadcastState();
}

/** The snapshots stop, and the vehicle hears `stop` (zero at once). */
function haltPiloting() {
  session.loop?.stop();
  frames.stop();
  session.links.sendToVehicle({ type: 'stop' });
}

/**
 * Stop the robot at once, whoever holds the wheel (docs/contracts.md): piloting stops, the
 * vehicle hears `stop`, and an operator's wheel goes back to the autopilot -- its mode change
 * stops the vehicle too, and makes it ignore a drive command still on its way (drive commands
 * ride the lossy channel, which the reliable one does not wait for). Every client hears who
 * (`by`: a client, or null when the relay stopped because nobody watches) and why.
 */
function stopRobot(by, reason) {
  const moving = status.piloting || session.operator.holder !== null;
  const stop = session.stop.press(by, reason, moving);
  if (stop === null) return; // stands stopped already: nothing to do, nobody to tell again
  log.warn(`robot stopped: ${reason}`);
  status.piloting = false;
  haltPiloting();
  if (session.operator.takeBack() !== null) announceOperator(reason);
  session.links.broadcast(stop);
  broadcastState();
}

/** A change of who watches left nobody watching: nothing drives unwatched. */
function nobodyWatching(why) {
  if (status.piloting || session.operator.holder !== null) {
    stopRobot(null, `no client is watching (${why})`);
  }
}

// ---------------------------------------------------------------- manual override

/** The wheel changed hands: tell the vehicle and every client. */
function announceOperator(reason) {
  const holder = session.operator.holder;
  const message = session.operator.modeMessage(reason);
  log.info(`${holder === null ? 'autopilot steers' : `${holder} has the wheel`} (${reason})`);
  view.operator(holder);
  session.links.sendToVehicle(message);
  session.links.broadcast(message);
}

function takeOver(from) {
  const { refused, changed } = session.operator.takeOver(from);
  if (refused) throw new BadMessage(refused);
  if (changed) announceOperator(`taken over by ${from}`);
}

function handBack(from) {
  const refused = session.operator.handBack(from);
  if (refused) throw new BadMessage(refused);
  announceOperator(`handed back by ${from}`);
}

/** The operator's drive command, renumbered for the vehicle (latest wins on the lossy channel). */
function forwardDrive(msg, from) {
  const { refused, drive } = session.operator.drive(from, msg);
  if (refused) throw new BadMessage(refused);
  if (!session.links.sendToVehicle(drive, { lossy: true })) {
    throw new BadMessage('no vehicle connected');
  }
  status.drivesForwarded += 1;
}

// ---------------------------------------------------------------- target lock

/** A client clicked frame pixel (x, y): lock on the box there, or release (the worker's lock). */
function lockAt(msg, from) {
  const loop = session.loop;
  if (loop === null) throw new BadMessage('operations are still loading; try again');
  session.lockRequests
    .run(() => loop.lockAt(msg.x, msg.y))
    .then(
      (locked) => {
        if (locked)
          log.info(`locked on the target at (${fmt(msg.x, 0)}, ${fmt(msg.y, 0)}) for ${from}`);
      },
      (err) => log.error(`could not lock for ${from}: ${err.message}`),
    );
}

function unlock(reason) {
  const loop = session.loop;
  if (loop === null) return;
  session.lockRequests
    .run(() => loop.unlock(reason))
    .catch((err) => log.error(`could not unlock: ${err.message}`));
}

function onLockChanged(message) {
  const where = message.box ? ` at [${message.box.map((v) => fmt(v, 0)).join(', ')}]` : '';
  log.info(`target lock: ${message.state}${where}${message.reason ? ` (${message.reason})` : ''}`);
  status.lock = message.state;
  view.lock(message.state);
  session.links.broadcast(message);
}

// ---------------------------------------------------------------- vehicle

/**
 * Forward the vehicle's pose (validated by serveChannel) to every client, with its goal age and
 * its search for a lost target when it tells them.
 */
function onPose(msg) {
  const pose = { type: 'pose', x: msg.x, y: msg.y, theta: msg.theta, t: msg.t ?? Date.now() };
  if (msg.goalAgeMs !== undefined) pose.goalAgeMs = msg.goalAgeMs;
  if (msg.search !== undefined) pose.search = msg.search;
  // While the vehicle searches for the locked target, the lock holds.
  session.loop?.vehicleSearch(msg.search ?? null);
  session.links.broadcast(pose);
}

/** Once a period: the vehicle → relay link's figures, to every client (link health). */
async function reportHealth() {
  if (status.clients.length === 0) return;
  try {
    const link = await session.links.readVehicleLink();
    if (link !== null) session.links.broadcast({ type: 'health', link });
  } catch (err) {
    log.warn(`could not read the vehicle link's statistics: ${err.message}`);
  }
}
setInterval(reportHealth, PROTOCOL.health.periodS * 1000);

// ---------------------------------------------------------------- links and room

function showState() {
  const piloting = status.piloting ? ` · piloting with ${status.op}` : '';
  view.state(`${room.describe()}${piloting}`);
}

session.links.addEventListener('vehicletrack', ({ detail: track }) => {
  if (track !== null) {
    status.vehicleTracks += 1;
    // A new video starts with a full scan, not a window where the old one last saw its target.
    session.analyzer
      ?.resetTracking()
      .catch((err) => log.error(`could not reset tracking: ${err.message}`));
  }
  frames.setTrack(track);
  view.vehicleTrack(track);
});
session.links.addEventListener('vehicle', ({ detail: name }) => {
  // A vehicle gone searches no more; one that comes says so in its poses.
  if (name === null) session.loop?.vehicleSearch(null);
  if (name !== null && session.operator.holder !== null) {
    session.links.sendToVehicle(session.operator.modeMessage('an operator holds the wheel'));
  }
  broadcastState();
});
session.links.addEventListener('control', ({ detail: name }) => {
  session.watchers.linkUp(name);
  // Why the robot stands, before the state that shows it standing.
  if (session.stop.standing !== null) session.links.sendTo(name, session.stop.standing);
  session.links.sendTo(name, stateMessage());
  session.links.sendTo(name, session.operator.modeMessage());
  if (session.loop !== null) session.links.sendTo(name, session.loop.lockMessage());
});
session.links.addEventListener('left', ({ detail: { name, role } }) => {
  // What the peer held goes with it, and nothing else: the vehicle seat (relay-links.js), the
  // wheel. The failsafe: the operator's link is gone, so nobody drives and the autopilot stays
  // off.
  if (session.operator.leave(name)) {
    if (status.piloting) setPiloting(false, `operator ${name} leaving`);
    announceOperator(`operator ${name} left`);
  }
  if (role === 'client' && session.watchers.linkDown(name)) {
    nobodyWatching(`${name}'s link to the relay closed`);
  }
});
session.links.addEventListener('controlclosed', ({ detail: name }) => {
  if (session.watchers.linkDown(name)) nobodyWatching(`${name}'s control channel closed`);
});
session.links.addEventListener('changed', () => view.peers(session.links.describe()));

room.bindControls();
room.addEventListener('phase', (event) => {
  showState();
  if (event.detail === 'disconnected') {
    // Stop first, while the vehicle's channel is still there to hear it.
    if (status.piloting) setPiloting(false, 'this relay leaving');
    session.links.closeAll('left the room');
  }
});
room.addEventListener('roster', ({ detail: roster }) => {
  const clients = roster.filter((peer) => peer.role === 'client').map((peer) => peer.name);
  if (session.watchers.room(clients)) nobodyWatching('the last client left the room');
  showState();
});
room.addEventListener('problem', showState);
room.addEventListener('peerleft', (event) => session.links.left(event.detail));
room.addEventListener('signal', (event) => {
  const msg = event.detail;
  switch (msg.type) {
    case 'offer':
    case 'candidate':
      session.links.signal(msg);
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
    case 'getOps':
      // The answer rides the control channel; a client whose channel is not open yet asks
      // again on it once it opens.
      sendOps(msg.from);
      break;
    default:
      log.warn(`unexpected signaling message "${msg.type}" from ${msg.from}`);
  }
});
if (config.auto) room.autoJoin();
