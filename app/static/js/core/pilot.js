// The vehicle's pilot: what a vehicle does with what its relay tells it, without any I/O. A port
// of vehicle_agent/core/pilot.py; both run the shared sequences of
// tests/vehicle_agent/core/pilot_sequences.py (tests/vehicle_agent/core/test_pilot.py in Python,
// e2e/test_pilot_js.py here), which also state the rules themselves.
//
// It is fed goals, stop commands, mode changes, drive commands, poses, link resets and clock
// ticks, each with the time it happened (seconds, one clock), and answers with the event records
// of what it did, in order: the records of app/protocol/events.py ({ev, ...fields, t}), the same
// the agent's event log writes. A `twist` record is a Twist to publish now. It composes the twins:
// the manual gate (core/manual.js: while an operator holds the wheel, goals are dropped with
// why 'manual' and drive commands steer, until the dead-man), then the freshness gate
// (core/freshness.js: latest wins, stale goals dropped), then the controller (core/control.js,
// with the control law the profile names); every Twist, the operator's too, then passes the
// robot's limiter (core/limits.js: clamped to its top speeds, ramped within its accelerations, a
// stop at once). A lost link, a mode change and a stop halt the turtle.
// The searching profiles record when a search for a lost target starts (`search`, and the side
// it turns to) and how it ends (`search_ended`: found, timed_out when its time ran out and the
// vehicle stopped, or stopped when piloting did).
import { Controller } from './control.js';
import { FrameTimes } from './frame-times.js';
import { GoalGate } from './freshness.js';
import { Limiter } from './limits.js';
import { ManualDrive } from './manual.js';

function record(twist, now) {
  if (twist === null) return [];
  return [
    {
      ev: 'twist',
      seq: twist.seq,
      frame: twist.frame,
      linear: twist.linear,
      angular: twist.angular,
      t: now,
    },
  ];
}

/**
 * `profile` fitted to `robot` (config.robot: its description and whether it is a turtlesim): an
 * operator's full deflection is at most the robot's top speed, the follow law knows of walls on a
 * turtlesim only, and the onboard law sees through the robot's camera (no camera, no bearing).
 * The twin of app/protocol/control.py's for_robot.
 */
function forRobot(profile, robot) {
  const { limits, camera } = robot.description;
  return Object.freeze({
    ...profile,
    manualLinear: Math.min(profile.manualLinear, limits.maxLinear),
    manualAngular: Math.min(profile.manualAngular, limits.maxAngular),
    walls: robot.turtlesim,
    hfov: camera === null ? 0 : (camera.hfovDeg * Math.PI) / 180,
  });
}

export class Pilot {
  #lastGoalAt = null; // when the last goal was applied on this link (link health)
  #searchTimedOut = false; // a search ran out and stopped the vehicle; nothing steered it since

  /**
   * @param controlLaw the law's numbers (core/control.js ControlLaw, from `config.control`)
   * @param profile one of `controlLaw.profiles`; the pilot fits it to `robot`
   * @param robot the robot driven (`config.robot`: its description and whether it is a
   *   turtlesim); every command is held to its limits
   * @param {{deadmanS: number, tickS: number, freshness: object, law?: Function}} rules the
   *   protocol's numbers (`config.control`, `config.protocol.goalFreshness`); `law` replaces the
   *   profile's control law
   */
  constructor(controlLaw, profile, robot, { deadmanS, tickS, freshness, law = null }) {
    profile = forRobot(profile, robot);
    this.profile = profile;
    this.tickS = tickS;
    this.controller = new Controller(controlLaw, profile, law);
    this.manual = new ManualDrive(profile, deadmanS);
    // Between every command and the robot: its top speeds and accelerations.
    this.limiter = new Limiter(robot.description.limits, tickS);
    // When the vehicle's own camera took its recent frames: a goal names its frame.
    this.frames = new FrameTimes(controlLaw.keptFrames);
    // Latest-wins on the lossy goal channel; reset for every new link.
    this.gate = new GoalGate(freshness);
  }

  /** 'manual' while an operator holds the wheel, else 'auto'. */
  get mode() {
    return this.manual.mode;
  }

  /** Who holds the wheel, in manual mode. */
  get operator() {
    return this.manual.operator;
  }

  /** True while goals steer the turtle (between the first goal and a stop). */
  get active() {
    return this.controller.active;
  }

  /**
   * How the search for a lost target stands, as the vehicle's pose tells the client: the side
   * it turns to ('left', 'right'), 'timed_out' once it ran out and stopped the vehicle (until a
   * goal, a stop or a mode change), null when there is none.
   */
  get search() {
    if (this.controller.searchSince !== null)
      return this.controller.lastSide > 0 ? 'left' : 'right';
    return this.#searchTimedOut ? 'timed_out' : null;
  }

  /** Seconds since the last goal applied on this link, null before the first. */
  goalAge(now) {
    return this.#lastGoalAt === null ? null : now - this.#lastGoalAt;
  }

  /**
   * The vehicle's own camera took its frame number `frame` (the number its frame tag carries) at
   * `now`: a goal found in it later takes its bearing from the heading then.
   */
  frame(frame, now) {
    this.frames.add(frame, now);
  }

  /**
   * A goal (validated against the protocol's Goal model): dropped, or it steers, from the heading
   * the vehicle had when its frame was taken (when the vehicle took that frame).
   */
  goal(goal, now) {
    const frame = goal.frame ?? null;
    if (this.manual.manual)
      return [{ ev: 'goal_dropped', seq: goal.seq, frame, why: 'manual', t: now }];
    const verdict = this.gate.admit(goal.seq, goal.t, now);
    if (verdict !== 'fresh') {
      return [{ ev: 'goal_dropped', seq: goal.seq, frame, why: verdict, t: now }];
    }
    this.#lastGoalAt = now;
    this.#searchTimedOut = false;
    const searching = this.controller.searchSince;
    const { seq, op, x, y, w, h } = goal;
    const applied = {
      ev: 'goal',
      seq,
      op,
      frame,
      x,
      y,
      w,
      h,
      box_w: goal.boxW ?? null,
      box_h: goal.boxH ?? null,
      locked: goal.locked ?? false,
      t: now,
    };
    const target = {
      x,
      y,
      w,
      h,
      seq,
      frame,
      boxH: goal.boxH ?? null,
      targetHeightM: goal.targetHeightM ?? null,
    };
    const twist = this.controller.goal(target, now, this.frames.capturedAt(frame));
    return [applied, ...this.#searched(searching, 'found', now), ...this.#sent(twist, now)];
  }

  /** The relay stopped piloting: the autopilot's turtle stops. */
  stop(now) {
    const searching = this.controller.searchSince;
    const twist = this.controller.stop();
    this.#searchTimedOut = false;
    return [...this.#searched(searching, 'stopped', now), ...this.#sent(twist, now)];
  }

  /**
   * The relay's mode. Whichever way it changes, the turtle stops first: the autopilot's last
   * command must not outlive its goals, nor the operator's outlive the wheel.
   */
  modeChange(mode, operator, now) {
    const stopped = this.manual.setMode(mode, operator);
    if (stopped === null) return [];
    const searching = this.controller.searchSince;
    this.controller.stop();
    this.#searchTimedOut = false;
    const changed = { ev: 'mode', mode, operator: this.manual.operator, t: now };
    return [changed, ...this.#searched(searching, 'stopped', now), ...this.#sent(stopped, now)];
  }

  /** An operator's drive command: it steers in manual mode when it is the newest. */
  drive(seq, linear, angular, now) {
    const twist = this.manual.drive(seq, linear, angular, now);
    const moving = twist !== null && (twist.linear !== 0 || twist.angular !== 0);
    const received = { ev: 'drive', seq, applied: twist !== null, moving, t: now };
    return [received, ...this.#sent(twist, now)];
  }

  /** The turtle's pose ({x, y, theta}): closed-loop profiles answer it (a search starts on it). */
  pose(pose, now) {
    const searching = this.controller.searchSince;
    const twist = this.controller.pose(pose, now);
    return [...this.#searched(searching, 'timed_out', now), ...this.#sent(twist, now)];
  }

  /**
   * The clock: the goal timeout, the clock-driven profile's period, the dead-man, and the next
   * step of a ramp under way.
   */
  tick(now) {
    const searching = this.controller.searchSince;
    const done = [
      ...this.#sent(this.controller.tick(now), now),
      ...this.#sent(this.manual.tick(now), now),
    ];
    const searched = this.#searched(searching, 'timed_out', now);
    return [...searched, ...(done.length > 0 ? done : record(this.limiter.tick(now), now))];
  }

  /**
   * Seconds from `now` until `tick` is due: every `tickS`, and at once when the goal timeout or
   * the dead-man falls due sooner, so a stop goes out on time.
   */
  nextTick(now) {
    const waits = [this.controller.untilTimeout(now), this.manual.untilDeadman(now)];
    return Math.min(this.tickS, ...waits.filter((wait) => wait !== null));
  }

  /**
   * A new link to a relay: halted, and everything numbered per link starts again (the relay's
   * goal and drive seq; a new relay knows of no operator).
   */
  newLink(now) {
    const halted = this.halt(now);
    this.gate.reset();
    this.manual.resetLink();
    this.#lastGoalAt = null;
    return halted;
  }

  /**
   * Stop at once, autopilot or operator: the link that carried the commands is gone (or the
   * page is leaving). Back in auto mode.
   */
  halt(now) {
    if (this.manual.manual) return this.modeChange('auto', null, now);
    return this.stop(now);
  }

  /**
   * The record of a search that started or ended since the controller's search began at
   * `before` (null: none was under way); `end` says how one that ended did.
   */
  #searched(before, end, now) {
    const since = this.controller.searchSince;
    if (before === null && since !== null) {
      return [{ ev: 'search', side: this.controller.lastSide > 0 ? 'left' : 'right', t: now }];
    }
    if (before !== null && since === null) {
      this.#searchTimedOut = end === 'timed_out';
      return [{ ev: 'search_ended', why: end, after_s: now - before, t: now }];
    }
    return [];
  }

  // The record of publishing `twist` (null: nothing to publish) within the limits.
  #sent(twist, now) {
    return twist === null ? [] : record(this.limiter.command(twist, now), now);
  }
}
