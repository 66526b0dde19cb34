// The control law of DESIGN §5 and its two timing profiles (docs/contracts.md): a port of
// vehicle_agent/control.py so the browser vehicle and the Python agent behave alike.
//
// Image pixels have their origin top-left with y growing downward; the turtlesim terrain has
// its origin bottom-left with y growing upward. A goal pixel is flipped vertically when mapped
// to the terrain: a face in the top half of the frame is a target in the upper half.

import { WORLD } from './protocol.js';

// From app/protocol/constants.py, through the page config.
export const TERRAIN_CENTRE = WORLD.terrainCentre;
export const WORLD_SIZE = WORLD.size;
// Below this distance the direction to the target is meaningless.
export const MIN_TARGET_DISTANCE_M = 0.05;

export const PROFILES = Object.freeze({
  default: Object.freeze({
    name: 'default', periodMs: 50, onPose: true, gain: 6.0, maxAngular: 4.0, deadband: 0.01, goalTimeoutMs: 750,
  }),
  // The thesis publishes the latest goal every 1100 ms; turtlesim runs a command for 1 s, so
  // angular.z = e turns the turtle by e.
  thesis: Object.freeze({
    name: 'thesis', periodMs: 1100, onPose: false, gain: 1.0, maxAngular: Infinity, deadband: 0, goalTimeoutMs: 2500,
  }),
});

/** `angle` wrapped into (−π, π]. */
export function wrapAngle(angle) {
  let wrapped = angle % (2 * Math.PI);
  if (wrapped <= -Math.PI) wrapped += 2 * Math.PI;
  else if (wrapped > Math.PI) wrapped -= 2 * Math.PI;
  return wrapped;
}

/** Terrain metres {x, y} of goal pixel (x, y) in a w×h frame (image y flipped). */
export function pixelToTerrain(x, y, w, h) {
  return { x: (x * TERRAIN_CENTRE) / (w / 2), y: ((h - y) * TERRAIN_CENTRE) / (h / 2) };
}

/** Signed turn in (−π, π] that makes the turtle at `pose` face `goal`; null when undefined. */
export function steeringError(goal, pose) {
  const target = pixelToTerrain(goal.x, goal.y, goal.w, goal.h);
  const dx = target.x - pose.x;
  const dy = target.y - pose.y;
  if (Math.hypot(dx, dy) < MIN_TARGET_DISTANCE_M) return null;
  return wrapAngle(Math.atan2(dy, dx) - pose.theta);
}

/** The profile's angular velocity for a steering error. */
export function angularCommand(error, profile) {
  if (Math.abs(error) < profile.deadband) return 0;
  return Math.max(-profile.maxAngular, Math.min(profile.maxAngular, profile.gain * error));
}

export const ZERO_TWIST = Object.freeze({ linear: 0, angular: 0, seq: null, frame: null });

/**
 * Turns goals into Twists with one profile; rotates in place (linear = 0). Call `goal` for each
 * goal, `pose` for each pose update and `tick` every few tens of milliseconds; each returns the
 * Twist to publish now, or null. After a goal timeout or `stop` exactly one zero Twist comes
 * back, then nothing until the next goal.
 */
export class Controller {
  #goal = null;
  #goalAt = 0;
  #pose = null;
  #lastPublish = null;

  constructor(profile, clock = () => performance.now()) {
    this.profile = profile;
    this.clock = clock;
  }

  /** True while goals are arriving. */
  get active() {
    return this.#goal !== null;
  }

  goal(goal) {
    this.#goal = goal;
    this.#goalAt = this.clock();
    return this.profile.onPose ? null : this.#due();
  }

  pose(pose) {
    this.#pose = pose;
    return this.#checkTimeout() ?? (this.profile.onPose ? this.#due() : null);
  }

  tick() {
    return this.#checkTimeout() ?? (this.profile.onPose ? null : this.#due());
  }

  stop() {
    if (this.#goal === null) return null;
    this.#goal = null;
    this.#lastPublish = null;
    return ZERO_TWIST;
  }

  #checkTimeout() {
    if (this.#goal !== null && this.clock() - this.#goalAt > this.profile.goalTimeoutMs) return this.stop();
    return null;
  }

  #due() {
    const goal = this.#goal;
    const pose = this.#pose;
    if (goal === null || pose === null) return null;
    const now = this.clock();
    const last = this.#lastPublish;
    const period = this.profile.periodMs;
    if (last !== null && now - last < period) return null;
    // The clock-driven profile keeps a fixed cadence (like the thesis's setInterval) instead of
    // drifting by the tick granularity; after a pause it starts a new grid.
    this.#lastPublish = !this.profile.onPose && last !== null && now - last < 2 * period ? last + period : now;
    const error = steeringError(goal, pose);
    // No defined heading: hold still rather than keep the last turn going.
    const angular = error === null ? 0 : angularCommand(error, this.profile);
    return { linear: 0, angular, seq: goal.seq ?? null, frame: goal.frame ?? null };
  }
}
