// The vehicle page: camera to the relay, goals from the lossy `autopilot-state` data channel
// (latest wins) turned into velocity commands for the robot `?robot=` names (turtlesim's
// /turtle1/cmd_vel by default; config.robot, from app/protocol/robot.py) through roslib.js,
// pose telemetry back to the relay on the same channel; `stop` on the reliable `autopilot`
// channel. What to do with goals, stops, mode changes, drive commands, poses and the clock is
// the pilot's to decide (core/pilot.js, the twin of the agent's vehicle_agent/core/pilot.py):
// this page feeds it, with the time, and acts on its records: publishes their Twists, counts and
// shows them.
import { ControlLaw } from '../core/control.js';
import { Pilot } from '../core/pilot.js';
import { RelayLink, sendJson, serveChannel } from '../net/peer.js';
import { CHANNELS, CONFIG, PROTOCOL, SCHEMAS } from '../config.js';
import { RobotLink } from '../net/robot-link.js';
import { RoomSession } from '../net/room.js';
import { byTestId, fmt, Log, searchText, show } from '../view/ui.js';

const POSE_FORWARD_MS = 50; // turtlesim publishes every 16 ms; 20 Hz is plenty for a route
// The pilot's latest records kept in the status (the agent's event log keeps them all).
const RECORDS_KEPT = 200;

const config = CONFIG;
const log = new Log(byTestId('log'));
const room = new RoomSession(config, log);
const law = new ControlLaw(config.control);
const described = config.robot.description;
const pilot = new Pilot(law, law.profiles[config.profile], config.robot, {
  deadmanS: config.control.deadmanS,
  tickS: config.control.tickS,
  freshness: PROTOCOL.goalFreshness,
});
/** The page's clock, in the seconds the pilot takes. */
const now = () => performance.now() / 1000;

/** The page's one session object, read-only for tests and benchmarks. */
const status = {
  // The pilot's records, as the agent's event log has them: counted by kind, the latest kept.
  events: { goal: 0, goal_dropped: 0, mode: 0, drive: 0, twist: 0, search: 0, search_ended: 0 },
  records: [],
  goalsReceived: 0, // goals applied
  lastGoal: null,
  twistsPublished: 0, // Twists that reached rosbridge
  lastTwist: null,
  pose: null,
  robot: described.name,
  velocityType: null, // the velocity topic's type once connected (the robot's, if it says)
  rosConnected: false,
  rosFlavour: null, // '1', '2' or 'jazzy' once connected
  rosTypesFrom: null, // 'robot' (its rosapi named them) or 'setting' (the ros= fallback)
  relayChannelOpen: false,
  // Goals not applied, by why: not newer (old), too late (stale), an operator held the wheel.
  goalsDropped: { old: 0, stale: 0, future: 0, manual: 0 },
  mode: 'auto', // 'manual' while an operator holds the wheel
  operator: null,
  drivesApplied: 0,
  // The relay's stops heard, whether or not the turtle was moving (a stop with no goal in hand
  // publishes nothing, so the Twists alone cannot tell that it arrived).
  stopsHeard: 0,
};
window.autopilotStatus = status;

const robotLink = new RobotLink(
  config.rosbridge,
  config.ros,
  config.rosTypes,
  config.robot,
  config.rosbridgeAuth ? config.token : null,
  { log, spawnTheta: config.spawnStep ? law.spawnTheta : null },
);
robotLink.onState = (text) => {
  status.rosConnected = robotLink.connected;
  status.rosFlavour = robotLink.types?.flavour ?? null;
  status.rosTypesFrom = robotLink.types === null ? null : robotLink.typesFrom;
  status.velocityType = robotLink.types?.velocity ?? null;
  show('ros-state', text);
};
/** Everything else this page holds, in one place. */
const session = {
  channel: null, // the open `autopilot` data channel (reliable)
  stateChannel: null, // the open `autopilot-state` data channel (unordered, no retransmits)
  lastPoseSent: 0,
  rosWarned: false, // a lost Twist has been reported for this outage
};

function publish(twist, why) {
  if (!robotLink.publish(twist)) {
    // Once per outage: goals keep coming at frame rate and would flood the log.
    if (!session.rosWarned) log.warn(`no rosbridge connection: Twists are not published (${why})`);
    session.rosWarned = true;
    return;
  }
  session.rosWarned = false;
  status.twistsPublished += 1;
  status.lastTwist = twist;
  const linear = twist.linear !== 0 ? `linear.x ${fmt(twist.linear, 2)} m/s  ` : '';
  const goal = twist.seq !== null ? ` (goal ${twist.seq})` : '';
  show('twist', `${linear}angular.z ${fmt(twist.angular, 3)} rad/s${goal}`);
  if (twist.linear === 0 && twist.angular === 0 && twist.seq === null)
    log.info(`zero Twist: ${why}`);
}

/**
 * Carry out what the pilot did, in order: count and keep each record, show the mode, publish
 * the Twists. `why` says what a zero Twist answers, for the log.
 */
function act(records, why) {
  for (const record of records) {
    status.events[record.ev] += 1;
    status.records.push(record);
    if (status.records.length > RECORDS_KEPT) status.records.shift();
    switch (record.ev) {
      case 'goal':
        status.goalsReceived += 1;
        status.lastGoal = record;
        show('goals-received', String(status.goalsReceived));
        break;
      case 'goal_dropped':
        status.goalsDropped[record.why] += 1;
        break;
      case 'mode':
        status.mode = record.mode;
        status.operator = record.operator;
        show('mode', record.mode === 'manual' ? `manual: ${record.operator}` : 'autopilot');
        log.info(`mode ${record.mode}${record.operator ? ` by ${record.operator}` : ''} (${why})`);
        break;
      case 'drive':
        if (record.applied) status.drivesApplied += 1;
        break;
      case 'twist':
        publish(record, why);
        break;
      case 'search':
        log.info(`target lost: searching to the ${record.side}`);
        break;
      case 'search_ended':
        log.info(`search ended after ${fmt(record.after_s, 1)} s: ${record.why}`);
        break;
      default:
        log.error(`the pilot made an unknown record ${record.ev}`);
    }
  }
  show('search', searchText(pilot.search));
}

function halt(reason) {
  act(pilot.halt(now()), reason);
}

function onMode(msg) {
  act(pilot.modeChange(msg.mode, msg.operator ?? null, now()), msg.reason ?? 'relay');
}

function onDrive(msg) {
  const stopping = msg.linear === 0 && msg.angular === 0;
  act(
    pilot.drive(msg.seq, msg.linear, msg.angular, now()),
    stopping ? 'operator stopped' : 'operator',
  );
}

robotLink.onPose = (pose) => {
  status.pose = pose;
  show('pose', `x ${fmt(pose.x, 2)}  y ${fmt(pose.y, 2)}  θ ${fmt(pose.theta, 3)}`);
  const t = now();
  act(pilot.pose(pose, t), 'goals stopped coming');
  if (t - session.lastPoseSent < POSE_FORWARD_MS / 1000) return;
  const age = pilot.goalAge(t);
  const goalAgeMs = age === null ? null : age * 1000;
  const telemetry = { type: 'pose', ...pose, t: Date.now(), goalAgeMs, search: pilot.search };
  if (sendJson(session.stateChannel, telemetry)) session.lastPoseSent = t;
};

function tick() {
  const t = now();
  // In manual mode the autopilot has no goal to time out: a stop there is the dead-man's.
  const why = pilot.mode === 'manual' ? 'dead-man: no drive command' : 'goals stopped coming';
  act(pilot.tick(t), why);
  setTimeout(tick, pilot.nextTick(now()) * 1000);
}
tick();

/** A goal, already validated against the protocol's Goal model by serveChannel. */
function onGoal(msg) {
  const wasActive = pilot.active;
  const records = pilot.goal(msg, now());
  if (!wasActive && records[0].ev === 'goal') log.info(`piloting: first goal (${msg.op})`);
  act(records, 'goal');
}

function setupPeer(peer, stream) {
  // No contentHint and no degradationPreference: on a capped uplink Chromium's default
  // (balanced) kept the most frames per second, which the control loop lives on; 'motion'
  // (maintain-framerate) kept fewer and 'detail' fewest (`autopilot bench --field`, video rows).
  if (stream !== null) for (const track of stream.getVideoTracks()) peer.pc.addTrack(track, stream);
  const dc = peer.pc.createDataChannel(CHANNELS.autopilot);
  const handlers = {
    goal: onGoal,
    stop: () => {
      status.stopsHeard += 1;
      act(pilot.stop(now()), 'relay says stop');
    },
    mode: onMode,
    drive: onDrive,
  };
  serveChannel(dc, handlers, log, SCHEMAS.autopilot.vehicle);
  // A new link: the relay's seq starts again, and a new relay knows of no operator.
  act(pilot.newLink(now()), 'a new relay link');
  const state = peer.pc.createDataChannel(CHANNELS.autopilotState, PROTOCOL.stateChannelOptions);
  serveChannel(
    state,
    { goal: onGoal, drive: onDrive },
    log,
    SCHEMAS[CHANNELS.autopilotState].vehicle,
  );
  state.addEventListener('open', () => {
    session.stateChannel = state;
  });
  state.addEventListener('close', () => {
    if (session.stateChannel === state) session.stateChannel = null;
  });
  dc.addEventListener('open', () => {
    session.channel = dc;
    status.relayChannelOpen = true;
    log.info(`autopilot channel to ${peer.remote} open`);
    showState();
  });
  dc.addEventListener('close', () => {
    if (session.channel !== dc) return;
    session.channel = null;
    status.relayChannelOpen = false;
    halt('relay channel closed');
    showState();
  });
}

function showState() {
  const parts = room.describeWithRelay(status.relayChannelOpen);
  show('state', parts.join(' · '));
}

async function startCamera() {
  if (!window.isSecureContext) {
    // Browsers hide navigator.mediaDevices from plain-HTTP pages of any host but this one.
    const why =
      'no camera: browsers give the camera only to pages served over HTTPS (or from localhost); ' +
      'serve with --self-signed or --cert and open https://… (see docs/deploying.md)';
    log.error(why);
    show('camera-state', why);
    return null;
  }
  try {
    const stream = await navigator.mediaDevices.getUserMedia({
      video: { width: { ideal: PROTOCOL.video.width }, height: { ideal: PROTOCOL.video.height } },
      audio: false,
    });
    byTestId('camera').srcObject = stream;
    const settings = stream.getVideoTracks()[0].getSettings();
    log.info(`camera on: ${settings.width}×${settings.height}`);
    show('camera-state', `camera on: ${settings.width}×${settings.height}`);
    return stream;
  } catch (err) {
    const why = `camera unavailable (${err.name}: ${err.message}); connecting without video`;
    log.error(why);
    show('camera-state', why);
    return null;
  }
}

room.addEventListener('renewed', (event) => robotLink.renew(event.detail));
room.bindControls();
room.addEventListener('phase', showState);
room.addEventListener('roster', showState);
room.addEventListener('problem', showState);
room.addEventListener('phase', (event) => {
  if (event.detail === 'disconnected') halt('left the room');
});
if (config.robotError) {
  log.error(config.robotError);
  show('ros-state', `refused: ${config.robotError}`);
} else if (config.rosbridgeError) {
  log.error(config.rosbridgeError);
  show('ros-state', 'refused: insecure rosbridge URL');
} else {
  robotLink.connect();
}
const stream = await startCamera();
const link = new RelayLink(room, { log, setup: (peer) => setupPeer(peer, stream) });
link.addEventListener('lost', (event) => {
  halt(event.detail);
  showState();
});
link.addEventListener('peer', showState);
link.sync();
if (config.auto) room.autoJoin();
