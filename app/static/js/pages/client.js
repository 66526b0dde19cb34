// The client page: watches the relayed video (with detection boxes) and the turtle's route,
// lists the relay's operations, sets one, starts and stops piloting, and stops the robot
// (Stop robot, whoever drives).
import { ControlLaw } from '../core/control.js';
import { LinkMeter, warnings } from '../net/link-health.js';
import { LockPanel } from '../view/lock-view.js';
import { preferLowLatency, RelayLink, sendJson, serveChannel } from '../net/peer.js';
import { CHANNELS, CONFIG, PROTOCOL, SCHEMAS } from '../config.js';
import { RoomSession } from '../net/room.js';
import { pollArenaState } from '../net/arena-state.js';
import { ArenaView } from '../view/arenaview.js';
import { TurtleView } from '../view/turtleview.js';
import {
  button,
  byTestId,
  drawDetections,
  FIGURES_PERIOD_MS,
  fmt,
  Log,
  searchText,
  show,
  throttle,
} from '../view/ui.js';
import { DriveInput } from '../view/drive-input.js';
import { GlassView } from '../view/glass-view.js';
import { showLinkHealth } from '../view/health-view.js';
import { hasTouch, Joystick } from '../view/joystick.js';

const MS_SMOOTHING = 15; // the figure shows the median of the last few snapshots

const config = CONFIG;
const log = new Log(byTestId('log'));
const room = new RoomSession(config, log);
const video = byTestId('video');
const overlay = byTestId('overlay');
const select = byTestId('operation');
const law = new ControlLaw(config.control);
// The simulated arena when the server has one (`autopilot serve --robot diffdrive`), else
// turtlesim's terrain.
const map = config.arenaMap;
const mapView =
  map === null
    ? new TurtleView(byTestId('turtle-view'), law.worldSize)
    : new ArenaView(byTestId('turtle-view'), map);
// Vehicle capture → presentation here, frame by frame (view/glass-view.js).
const glassView = new GlassView({
  video,
  layout: PROTOCOL.frameTag,
  figure: byTestId('glass-to-glass'),
});
// A click on the video locks the relay on the target there; Unlock releases it.
const lockPanel = new LockPanel({
  stage: video.parentElement,
  unlockButton: button('unlock'),
  showState: (text) => show('lock-state', text),
  send: (msg) => sendJson(session.control, msg),
  frame: () => status.lastDetections,
  log,
});

/** The page's one session object, read-only for tests. */
const status = {
  controlOpen: false,
  relay: null, // the relay's last `state`: {piloting, op, vehicle}
  ops: [],
  detections: 0,
  lastDetections: null,
  pose: null,
  poses: 0,
  routeM: 0, // metres the turtle drove while this page watched (the drawn route)
  search: null, // the vehicle's search for a lost target: 'left', 'right', 'timed_out' or null
  videoTracks: 0, // how many times a (new) relayed video track arrived
  // The person asked to pilot (Start) and has not asked to stop: a relay that replaces a lost
  // one (a relay pool taking the room over) is asked to start again on its first state.
  wantPiloting: false,
  lock: null, // the relay's last lockState: {state, box, reason}
  stopped: null, // the last robotStopped while it stands: {by: client or null, reason}
  mode: null, // the relay's last mode: {mode: 'auto'|'manual', operator, reason}
  get drivesSent() {
    return driveInput.sent;
  },
  // The simulated arena's billboards where the map draws them ({name: {x, y, yaw}}), or null.
  get billboards() {
    return map === null ? null : mapView.placed;
  },
};
window.autopilotStatus = status;

/**
 * Link health, read-only for tests: each link's latest figures ({rttMs, lossPct, fps, width,
 * height, candidate}, null until measured), the vehicle's goal age and the warnings on show.
 */
const health = {
  vehicleToRelay: null, // measured by the relay, sent in `health`
  relayToClient: null, // measured here
  goalAgeMs: null, // from the vehicle's pose: since it last applied a goal
  warnings: [],
  /** Vehicle capture → presentation here: {p50Ms, p95Ms, lastMs, frames} of the latest
   * frames, or null until a tagged frame's capture time is known (docs/contracts.md). */
  get glassToGlass() {
    return glassView.glass.summary();
  },
  /** The same, every frame measured (the latest 2000, ms, oldest first), and how many. */
  get glassToGlassMs() {
    return glassView.glass.samples.toArray();
  },
  get framesTimed() {
    return glassView.glass.count;
  },
};
window.autopilotHealth = health;

/**
 * What the video shows, read-only for tests: the boxes drawn over it, each {x, y, w, h} in the
 * analysed frame's pixels and its kind, 'tracked', 'locked' or 'candidate'
 * (core/shown-boxes.js), and that frame's size.
 */
const view = { boxes: [], w: null, h: null };
window.autopilotView = view;

/** Everything else this page holds, in one place. */
const session = {
  meter: null, // the LinkMeter of the connection to the relay
  control: null, // the open `control` data channel
  recentMs: [],
  driveSeq: 0,
};
// Keys and gamepads drive while this client holds the wheel (manual override).
const driveInput = new DriveInput({
  repeatS: config.control.driveRepeatS,
  send: (command) => {
    session.driveSeq += 1;
    sendJson(session.control, { type: 'drive', seq: session.driveSeq, ...command });
  },
});
// On a touch screen the on-screen joystick drives too; lifting the finger stops at once.
const touch = hasTouch();
const joystick = new Joystick(byTestId('joystick'), (command) => driveInput.setStick(command));
if (touch) joystick.show();

// ---------------------------------------------------------------- relay messages

// Each handler gets a message already validated against the protocol's model (serveChannel).

function onOps(msg) {
  status.ops = msg.ops;
  select.replaceChildren(
    ...msg.ops.map((op) => {
      const option = new Option(op.label || op.id, op.id);
      option.title = op.description;
      return option;
    }),
  );
  if (typeof msg.current === 'string') select.value = msg.current;
  showDescription();
  log.info(`operations offered by the relay: ${msg.ops.map((op) => op.id).join(', ')}`);
  updateControls();
}

function onState(msg) {
  const previous = status.relay;
  status.relay = { piloting: msg.piloting, op: msg.op, vehicle: msg.vehicle };
  if (previous === null && status.wantPiloting && !status.relay.piloting) {
    log.info('a new relay took over: asking it to resume piloting');
    try {
      askRelay('start');
    } catch (err) {
      log.error(err.message);
    }
  }
  if (previous?.op !== status.relay.op && status.relay.op)
    log.info(`operation is now ${status.relay.op}`);
  if (previous !== null && previous.piloting !== status.relay.piloting) {
    log.info(status.relay.piloting ? 'piloting started' : 'piloting stopped');
  }
  if (!status.relay.piloting) clearDetections();
  else if (status.stopped !== null) {
    status.stopped = null; // piloting again: the stop no longer stands
    show('stop-state', '');
  }
  show('active-op', status.relay.op ?? '–');
  showState();
  updateControls();
}

function onDetections(msg) {
  status.detections += 1;
  status.lastDetections = msg;
  // The boxes go with the video's frames; the figures and the map change a few times a second.
  Object.assign(view, { boxes: drawDetections(overlay, msg), w: msg.w, h: msg.h });
  session.recentMs.push(msg.ms);
  if (session.recentMs.length > MS_SMOOTHING) session.recentMs.shift();
  // A goal pixel is a place on turtlesim's terrain only: the fixed camera watches it.
  const fixed = map === null && msg.target;
  mapView.setTarget(fixed ? law.pixelToTerrain(msg.target.x, msg.target.y, msg.w, msg.h) : null);
  showFigures();
}

function onPose(msg) {
  const pose = { x: msg.x, y: msg.y, theta: msg.theta };
  status.pose = pose;
  if (msg.goalAgeMs !== undefined) health.goalAgeMs = msg.goalAgeMs;
  const search = msg.search ?? null;
  // At once, not with the throttled figures: a person needs to know the robot gave up.
  if (search !== status.search) show('search', searchText(search));
  status.search = search;
  status.poses += 1;
  mapView.addPose(pose);
  status.routeM = mapView.routeLength;
  showFigures();
}

const showFigures = throttle(FIGURES_PERIOD_MS, () => {
  const detections = status.lastDetections;
  if (detections !== null) {
    show('ms-per-snapshot', fmt(median(session.recentMs)));
    show('goals-per-s', fmt(detections.goalsPerS));
  }
  const { pose } = status;
  if (pose !== null) {
    show('pose', `x ${fmt(pose.x, 2)} m   y ${fmt(pose.y, 2)} m   θ ${fmt(pose.theta, 3)} rad`);
    show('route', `route ${fmt(status.routeM, 1)} m driven`);
  }
});

function onHealth(msg) {
  health.vehicleToRelay = msg.link;
  showHealth();
}

function showHealth() {
  const limits = PROTOCOL.health;
  health.warnings = [
    ...warnings('vehicle → relay', health.vehicleToRelay, limits),
    ...warnings('relay → client', health.relayToClient, limits),
  ];
  showLinkHealth(health);
}

async function measureHealth() {
  if (session.meter === null || session.control === null) return;
  try {
    health.relayToClient = await session.meter.read();
  } catch (err) {
    log.warn(`could not read this link's statistics: ${err.message}`);
  }
  showHealth();
}
setInterval(measureHealth, PROTOCOL.health.periodS * 1000);

function onLockState(msg) {
  status.lock = { state: msg.state, box: msg.box ?? null, reason: msg.reason ?? null };
  lockPanel.onState(msg);
  if (msg.reason) log.info(`target lock ${msg.state}: ${msg.reason}`);
}

/** Someone pressed Stop robot, or the relay stopped because nobody watched: say who and why. */
function onRobotStopped(msg) {
  status.stopped = { by: msg.by ?? null, reason: msg.reason };
  // A stop outranks this person's wish to pilot: a relay that takes over must not resume.
  status.wantPiloting = false;
  show('stop-state', stopText(status.stopped));
  log.warn(`robot stopped: ${msg.reason}`);
}

function stopText({ by, reason }) {
  return by === null ? `Robot stopped: ${reason}` : `Robot stopped by ${by}`;
}

function onMode(msg) {
  const previous = status.mode;
  status.mode = { mode: msg.mode, operator: msg.operator ?? null, reason: msg.reason ?? null };
  const mine = msg.mode === 'manual' && msg.operator === room.name;
  driveInput.setEnabled(mine);
  joystick.setEnabled(mine);
  show('mode', modeText());
  if (
    previous !== null &&
    (previous.mode !== msg.mode || previous.operator !== status.mode.operator)
  ) {
    const who = msg.mode === 'manual' ? `${msg.operator} has the wheel` : 'the autopilot steers';
    log.info(`${who}${msg.reason ? ` (${msg.reason})` : ''}`);
  }
  updateControls();
}

function modeText() {
  const mode = status.mode;
  if (mode === null) return 'unknown (no relay)';
  if (mode.mode === 'auto') return 'autopilot steers';
  if (mode.operator === room.name) {
    return touch
      ? 'you drive: drag the joystick, lift your finger to stop'
      : 'you drive: arrow keys (held) or gamepad; Space stops';
  }
  return `${mode.operator} is driving`;
}

function median(values) {
  const sorted = [...values].sort((a, b) => a - b);
  const mid = Math.floor(sorted.length / 2);
  return sorted.length % 2 ? sorted[mid] : (sorted[mid - 1] + sorted[mid]) / 2;
}

function clearDetections() {
  Object.assign(view, { boxes: drawDetections(overlay, null), w: null, h: null });
  mapView.setTarget(null);
}

// ---------------------------------------------------------------- connection to the relay

function setupPeer(peer) {
  // Receive-only video from the start: the relay can then send the vehicle's track whenever
  // it has one, with no renegotiation.
  peer.pc.addTransceiver('video', { direction: 'recvonly' });
  session.meter = new LinkMeter(peer.pc);
  peer.addEventListener('track', (event) => {
    preferLowLatency(event.detail.receiver);
    status.videoTracks += 1;
    video.srcObject = new MediaStream([event.detail.track]);
    glassView.newVideo();
    log.info('relayed video track received');
  });
  const dc = peer.pc.createDataChannel(CHANNELS.control);
  const handlers = {
    ops: onOps,
    state: onState,
    detections: onDetections,
    pose: onPose,
    lockState: onLockState,
    mode: onMode,
    robotStopped: onRobotStopped,
    health: onHealth,
    frameTimes: (msg) => glassView.captured(msg),
  };
  serveChannel(dc, handlers, log, SCHEMAS.control.client);
  dc.addEventListener('open', () => {
    session.control = dc;
    status.controlOpen = true;
    log.info(`control channel to relay ${peer.remote} open`);
    sendJson(dc, { type: 'getOps' });
    showState();
    updateControls();
  });
  dc.addEventListener('close', () => {
    if (session.control !== dc) return;
    session.control = null;
    status.controlOpen = false;
    forgetMode();
    showState();
    updateControls();
  });
}

/** start/stop go through signaling as in the thesis, or on the control channel without it. */
function askRelay(type) {
  if (room.phase === 'joined' && room.relay !== undefined) room.send({ type });
  else if (!sendJson(session.control, { type }))
    throw new Error(`cannot send ${type}: no relay connection`);
  log.info(`asked the relay to ${type === 'start' ? 'start' : 'stop'} piloting`);
}

// ---------------------------------------------------------------- page

function forgetMode() {
  status.mode = null;
  driveInput.setEnabled(false);
  joystick.setEnabled(false);
  show('mode', modeText());
}

function showDescription() {
  const op = status.ops.find((candidate) => candidate.id === select.value);
  show('op-description', op?.description ?? '');
}

function updateControls() {
  const reachable = session.control !== null;
  const piloting = status.relay?.piloting ?? false;
  select.disabled = !reachable || status.ops.length === 0;
  button('set-op').disabled = select.disabled;
  button('start').disabled = !reachable || piloting;
  button('stop').disabled = !reachable || !piloting;
  const mode = status.mode;
  // Stop robot goes on the control channel, or through signaling while that is down.
  button('stop-robot').disabled = !reachable && !(room.phase === 'joined' && room.relay);
  button('take-over').disabled = !reachable || mode === null || mode.mode === 'manual';
  button('hand-back').disabled =
    !reachable || mode?.mode !== 'manual' || mode.operator !== room.name;
}

function showState() {
  const parts = room.describeWithRelay(session.control !== null);
  if (status.relay !== null && session.control !== null) {
    parts.push(status.relay.vehicle ? `vehicle ${status.relay.vehicle}` : 'no vehicle yet');
    parts.push(status.relay.piloting ? `piloting with ${status.relay.op}` : 'not piloting');
  }
  show('state', parts.join(' · '));
}

select.addEventListener('change', showDescription);
button('set-op').addEventListener('click', () => {
  if (sendJson(session.control, { type: 'setOp', op: select.value })) {
    log.info(`asked the relay to use ${select.value}`);
  } else {
    log.error('cannot set the operation: no relay connection');
  }
});
for (const type of ['start', 'stop']) {
  button(type).addEventListener('click', () => {
    status.wantPiloting = type === 'start';
    try {
      askRelay(type);
    } catch (err) {
      log.error(err.message);
    }
  });
}

// The relay answers with `mode` (to every client), or with an error naming who drives.
for (const [action, msg] of [
  ['take-over', { type: 'takeOver' }],
  ['hand-back', { type: 'handBack' }],
]) {
  button(action).addEventListener('click', () => {
    if (!sendJson(session.control, msg))
      log.error(`cannot ${button(action).textContent}: no relay connection`);
  });
}

// Stop robot: any client, whoever drives. On the control channel (the relay stops piloting and
// takes the wheel back); with none, piloting at least is stopped through signaling.
button('stop-robot').addEventListener('click', () => {
  status.wantPiloting = false;
  if (sendJson(session.control, { type: 'stopRobot' })) {
    log.info('asked the relay to stop the robot');
    return;
  }
  try {
    askRelay('stop');
  } catch (err) {
    log.error(`cannot stop the robot: ${err.message}`);
  }
});

room.bindControls();
room.addEventListener('phase', (event) => {
  showState();
  updateControls();
  // As in the thesis, ask for the operations on joining (the answer comes on the data channel).
  if (event.detail === 'joined' && room.relay !== undefined) room.send({ type: 'getOps' });
});
room.addEventListener('roster', () => {
  showState();
  updateControls();
});
room.addEventListener('problem', showState);
const link = new RelayLink(room, { log, setup: setupPeer });
link.addEventListener('lost', () => {
  status.relay = null;
  forgetMode();
  session.meter = null;
  Object.assign(health, { vehicleToRelay: null, relayToClient: null, goalAgeMs: null });
  glassView.newVideo();
  showHealth();
  clearDetections();
  showState();
  updateControls();
});
link.addEventListener('peer', showState);
updateControls();
showState();
if (map !== null) {
  const canvas = byTestId('turtle-view');
  canvas.setAttribute('aria-label', 'Arena map');
  canvas.closest('section').setAttribute('aria-label', 'Arena');
  pollArenaState({
    path: map.statePath,
    periodMs: map.statePeriodMs,
    room: () => room.room ?? config.room,
    token: () => config.token,
    onState: (state) => mapView.setBillboards(state.billboards),
    onError: (reason) => log.error(`the arena's state: ${reason}`),
  });
}
if (config.auto) room.autoJoin();
