// The control laws and the controller that paces them (docs/architecture.md, "Vehicle control"):
// a port of vehicle_agent/core/control.py so the browser vehicle and the Python agent behave alike,
// checked against it on a grid (e2e/test_control_js.py); the vehicle's pilot (core/pilot.js)
// drives it. Its numbers (terrain, gains, standoff, wall margin, timeouts, profile names) are not
// written here: they come from app/protocol/control.py through the page's embedded config
// (`config.control`). A law asks for the speeds it wants; the robot's top speed holds them in the
// pilot's limiter alone (core/limits.js), to the share of it a law that drives as much as it
// faces its target allows (`topShare`).
//
// Image pixels have their origin top-left with y growing downward; the turtlesim terrain has
// its origin bottom-left with y growing upward. A goal pixel is flipped vertically when mapped
// to the terrain: a face in the top half of the frame is a target in the upper half. That is the
// fixed camera's geometry (rotate, follow); a camera the vehicle carries (onboard) turns with it:
// a goal pixel is a bearing, positive to the left as θ is counter-clockwise, and the target's
// box height against its real height is a range.
// Times are seconds, as in Python, so both sides compute the same doubles.

/** `angle` wrapped into (−π, π]. */
function wrapAngle(angle) {
  let wrapped = angle % (2 * Math.PI);
  if (wrapped <= -Math.PI) wrapped += 2 * Math.PI;
  else if (wrapped > Math.PI) wrapped -= 2 * Math.PI;
  return wrapped;
}

function clamp(value, low, high) {
  return Math.max(low, Math.min(high, value));
}

// The focal length in pixels of a camera `hfov` radians across a frame `w` wide.
function focalPx(w, hfov) {
  return w / 2 / Math.tan(hfov / 2);
}

/**
 * What a law asks for: its speeds, and the share of the robot's top speed `linear` may reach
 * (`topShare`: a law that drives only as much as it faces its target says how much). The speeds
 * are the law's wish; the pilot's limiter (core/limits.js) alone holds them to the robot's.
 */
function command(linear, angular, topShare = 1) {
  return { linear, angular, topShare };
}

// JSON has no infinity: the config sends null for "no limit" / "never".
function profileFrom(constants) {
  const unbounded = (value) => (value === null ? Infinity : value);
  return Object.freeze({
    ...constants,
    maxAngular: unbounded(constants.maxAngular),
    searchAfterS: unbounded(constants.searchAfterS),
    slowBearing: unbounded(constants.slowBearing),
  });
}

/** The law with the shared numbers of `config.control` (see app/protocol/control.py). */
export class ControlLaw {
  constructor(constants) {
    this.worldSize = constants.worldSize;
    this.terrainCentre = constants.terrainCentre;
    this.minTargetDistanceM = constants.minTargetDistanceM;
    this.spawnTheta = constants.spawnTheta;
    this.headingMemoryS = constants.headingMemoryS;
    this.keptFrames = constants.keptFrames;
    this.profiles = Object.freeze(
      Object.fromEntries(
        Object.entries(constants.profiles).map(([name, p]) => [name, profileFrom(p)]),
      ),
    );
    Object.freeze(this);
  }

  /** Terrain metres {x, y} of goal pixel (x, y) in a w×h frame (image y flipped). */
  pixelToTerrain(x, y, w, h) {
    return { x: (x * this.terrainCentre) / (w / 2), y: ((h - y) * this.terrainCentre) / (h / 2) };
  }

  /** Signed turn in (−π, π] that makes the turtle at `pose` face `goal`; null if undefined. */
  steeringError(goal, pose) {
    const target = this.pixelToTerrain(goal.x, goal.y, goal.w, goal.h);
    return this.#headingError(target.x, target.y, pose);
  }

  #headingError(tx, ty, pose) {
    const dx = tx - pose.x;
    const dy = ty - pose.y;
    if (Math.hypot(dx, dy) < this.minTargetDistanceM) return null;
    return wrapAngle(Math.atan2(dy, dx) - pose.theta);
  }

  /** The profile's angular velocity for a steering error. */
  angularCommand(error, profile) {
    if (Math.abs(error) < profile.deadband) return 0;
    return clamp(profile.gain * error, -profile.maxAngular, profile.maxAngular);
  }

  /** Metres the turtle can travel straight ahead (or straight back) before a wall. */
  wallClearance(pose, forward) {
    const sign = forward ? 1 : -1;
    let clearance = Infinity;
    for (const [position, component] of [
      [pose.x, sign * Math.cos(pose.theta)],
      [pose.y, sign * Math.sin(pose.theta)],
    ]) {
      if (component > 1e-12)
        clearance = Math.min(clearance, (this.worldSize - position) / component);
      else if (component < -1e-12) clearance = Math.min(clearance, -position / component);
    }
    return Math.max(0, clearance);
  }

  /**
   * The command {linear, angular, topShare} that takes the turtle to `profile.standoffM` from
   * terrain point (tx, ty): turn towards it, drive as much as it faces it, slow near walls (when
   * `profile.walls`).
   */
  followCommand(tx, ty, pose, profile) {
    const margin = profile.wallMarginM;
    // A target at the edge of the frame would lead the turtle into the wall; aim inside (where
    // the walls are known: a turtlesim's terrain).
    const x = profile.walls ? clamp(tx, margin, this.worldSize - margin) : tx;
    const y = profile.walls ? clamp(ty, margin, this.worldSize - margin) : ty;
    const error = this.#headingError(x, y, pose);
    if (error === null) return command(0, 0);
    const angular = this.angularCommand(error, profile);
    const distance = Math.hypot(x - pose.x, y - pose.y);
    // Only the part of the heading that points at the target is worth driving along; facing
    // away, the turtle turns first. The share holds for the robot's top speed too.
    const facing = Math.max(0, Math.cos(error));
    const linear = profile.linearGain * (distance - profile.standoffM) * facing;
    if (!profile.walls) return command(linear, angular, facing);
    // Slower with less clearance ahead (behind, when backing off); zero at the wall margin.
    const allowed = Math.max(
      0,
      profile.wallGain * (this.wallClearance(pose, linear >= 0) - margin),
    );
    return command(clamp(linear, -allowed, allowed), angular, facing);
  }

  /** The rotate law: turn in place to face the goal's terrain point. */
  rotate(goal, pose, profile) {
    const error = this.steeringError(goal, pose);
    // No defined heading: hold still rather than keep the last turn going.
    return command(0, error === null ? 0 : this.angularCommand(error, profile));
  }

  /** The follow law: drive to the profile's standoff from the goal's terrain point. */
  follow(goal, pose, profile) {
    const target = this.pixelToTerrain(goal.x, goal.y, goal.w, goal.h);
    return this.followCommand(target.x, target.y, pose, profile);
  }

  /**
   * The bearing (rad) of pixel column x of a frame w wide seen by a camera hfov across, from
   * the camera's axis: positive to the left, so a target right of the centre is negative.
   */
  pixelBearing(x, w, hfov) {
    return -Math.atan((x - w / 2) / focalPx(w, hfov));
  }

  /** The distance (m) at which something heightM high spans boxH pixels: f · H / h. */
  targetRange(boxH, heightM, w, hfov) {
    return (focalPx(w, hfov) * heightM) / boxH;
  }

  /**
   * The onboard law: turn the target's bearing toward zero, and drive to the standoff from it
   * as much as the vehicle faces it. The bearing is the goal pixel's less how far the vehicle
   * has turned since its frame was taken, or since it arrived when that is not known
   * (`goal.heading`). A target that moves round the vehicle (`goal.drift`, rad/s) has moved on
   * by its drift times the frame's age (`goal.age`, s), and the vehicle turns at its drift
   * besides: a turn in proportion to the bearing alone would trail it by the drift over the
   * gain. The range comes from the box's height, and without a box or a real height the
   * vehicle only turns.
   */
  onboard(goal, pose, profile) {
    if (!(profile.hfov > 0)) return command(0, 0);
    const drift = goal.drift ?? 0;
    let bearing = this.pixelBearing(goal.x, goal.w, profile.hfov) + drift * (goal.age ?? 0);
    if (goal.heading !== null && goal.heading !== undefined)
      bearing = wrapAngle(bearing - wrapAngle(pose.theta - goal.heading));
    // A non-finite goal or pose has no direction: hold still (NaN would pass every clamp).
    if (!Number.isFinite(bearing)) return command(0, 0);
    let angular = this.angularCommand(bearing, profile);
    if (drift !== 0) angular = clamp(angular + drift, -profile.maxAngular, profile.maxAngular);
    if (goal.boxH == null || goal.targetHeightM == null) return command(0, angular);
    const distance = this.targetRange(goal.boxH, goal.targetHeightM, goal.w, profile.hfov);
    // Full speed facing the target, none at `slowBearing` off it: turn first, then drive. The
    // share holds for the robot's top speed too.
    const facing = Math.max(0, 1 - Math.abs(bearing) / profile.slowBearing);
    return command(profile.linearGain * (distance - profile.standoffM) * facing, angular, facing);
  }

  /**
   * The control law `profile.law` names, as a function (goal, pose, profile) -> {linear,
   * angular, topShare}: the laws of vehicle_agent/core/control.py's LAWS. A new law is a method
   * here, an entry below and its Python twin.
   */
  lawOf(profile) {
    const laws = { rotate: this.rotate, follow: this.follow, onboard: this.onboard };
    const law = laws[profile.law];
    if (law === undefined) throw new Error(`no control law ${profile.law}`);
    return law.bind(this);
  }
}

export const ZERO_TWIST = Object.freeze({ linear: 0, angular: 0, seq: null, frame: null });

/**
 * Turns goals into Twists with one profile and the law it names (or `law`, a function
 * (goal, pose, profile) -> {linear, angular, topShare?}). Call `goal` for each goal, `pose` for
 * each pose update and `tick` every few tens of milliseconds, each with the time now (seconds,
 * one clock); each returns the Twist to publish now, or null. Closed-loop profiles answer a new
 * goal at once (rate-capped by `minIntervalS`) and pose updates every `periodS`; the thesis
 * profile publishes on its own clock. After a goal timeout or `stop` exactly one zero Twist
 * comes back, then nothing until the next goal. The searching profiles (follow, onboard) stop
 * driving and turn in place when no goal came for `searchAfterS`, toward the side the target
 * was last seen on, until a goal comes back (`searchSince` says since when) or the goal timeout
 * stops the search.
 */
export class Controller {
  #goal = null;
  #goalAt = 0;
  #unanswered = false;
  #lastSide = 1;
  #pose = null;
  #headings = []; // the headings of the last headingMemoryS, oldest first: [time, theta]
  #lastPublish = null;
  #searchSince = null; // when the search under way began (its first Twist), null when none is
  #captured = 0; // when the current goal's frame was taken (or it arrived, when not known)
  // The target's recent sightings, oldest first: [when its frame was taken, its bearing in the
  // room's frame, unwrapped], for its drift (profile.driftWindowS).
  #sightings = [];

  constructor(controlLaw, profile, law = null) {
    this.profile = profile;
    this.headingMemoryS = controlLaw.headingMemoryS;
    this.controlLaw = controlLaw;
    this.law = law ?? controlLaw.lawOf(profile);
  }

  /** When the search under way began (its first Twist went out), null when none is. */
  get searchSince() {
    return this.#searchSince;
  }

  /** The side the target was last seen on, +1 left or −1 right: where a search turns. */
  get lastSide() {
    return this.#lastSide;
  }

  /** True while goals are arriving. */
  get active() {
    return this.#goal !== null;
  }

  /** True while the follow profile has lost its target and turns to find it. */
  searching(now) {
    return this.#goal !== null && this.#lost(now);
  }

  /**
   * Take a new goal and answer it now when the profile's timing allows; it ends a search.
   * `capturedAt`: when its frame was taken, on `now`'s clock, if known.
   */
  goal(goal, now, capturedAt = null) {
    const captured = capturedAt ?? now;
    const heading = this.#headingAt(captured);
    this.#goal = { ...goal, heading, drift: this.#drift(goal, heading, captured), age: 0 };
    this.#captured = captured;
    this.#goalAt = now;
    this.#unanswered = true;
    this.#searchSince = null;
    return this.#due(now);
  }

  pose(pose, now) {
    this.#pose = pose;
    this.#headings.push([now, pose.theta]);
    while (this.#headings[0][0] < now - this.headingMemoryS) this.#headings.shift();
    return this.#checkTimeout(now) ?? (this.profile.onPose ? this.#due(now) : null);
  }

  tick(now) {
    return this.#checkTimeout(now) ?? (this.profile.onPose ? null : this.#due(now));
  }

  // The heading at `t`: the last pose's at or before it (the oldest remembered for an earlier
  // `t`), null before any pose.
  #headingAt(t) {
    if (this.#headings.length === 0) return null;
    let heading = this.#headings[0][1];
    for (const [at, theta] of this.#headings) {
      if (at > t) break;
      heading = theta;
    }
    return heading;
  }

  /**
   * How fast the target turns about the vehicle (rad/s, room frame), from its sightings of the
   * last driftWindowS once they span half of it; 0 before, and when the profile does not
   * measure it. A sighting that moved faster than the vehicle can turn is a jump (another
   * target, a detection astray), not a walk: the measure starts again from it.
   */
  #drift(goal, heading, captured) {
    const profile = this.profile;
    if (!(profile.driftWindowS > 0) || !(profile.hfov > 0) || heading === null) return 0;
    let seen = heading + this.controlLaw.pixelBearing(goal.x, goal.w, profile.hfov);
    const sightings = this.#sightings;
    if (!Number.isFinite(seen)) {
      sightings.length = 0;
      return 0;
    }
    if (sightings.length > 0) {
      const [lastAt, last] = sightings[sightings.length - 1];
      seen = last + wrapAngle(seen - last);
      if (Math.abs(seen - last) > profile.maxAngular * Math.max(0, captured - lastAt)) {
        sightings.length = 0;
      }
    }
    // A frame seen before (or an older one) adds nothing to the measure.
    if (sightings.length === 0 || captured > sightings[sightings.length - 1][0]) {
      sightings.push([captured, seen]);
    }
    while (sightings[0][0] < captured - profile.driftWindowS) sightings.shift();
    const [firstAt, first] = sightings[0];
    const [lastAt, last] = sightings[sightings.length - 1];
    const span = lastAt - firstAt;
    return span < profile.driftWindowS / 2 ? 0 : (last - first) / span;
  }

  stop() {
    if (this.#goal === null) return null;
    this.#goal = null;
    this.#unanswered = false;
    this.#lastPublish = null;
    this.#searchSince = null;
    this.#sightings.length = 0;
    return ZERO_TWIST;
  }

  #lost(now) {
    return now - this.#goalAt > this.profile.searchAfterS;
  }

  /**
   * Seconds until the goal timeout stops the turtle (0 when due), null with no goal. A caller
   * that ticks on a coarse period wakes up at this moment too, so the stop goes out on time.
   */
  untilTimeout(now) {
    if (this.#goal === null) return null;
    return Math.max(0, this.#goalAt + this.profile.goalTimeoutS - now);
  }

  #checkTimeout(now) {
    if (this.#goal !== null && now - this.#goalAt >= this.profile.goalTimeoutS) {
      return this.stop();
    }
    return null;
  }

  #due(now) {
    const goal = this.#goal;
    const pose = this.#pose;
    if (goal === null || pose === null) return null;
    const last = this.#lastPublish;
    const profile = this.profile;
    if (profile.onPose) {
      const gap = this.#unanswered ? profile.minIntervalS : profile.periodS;
      if (last !== null && now - last < gap) return null;
      this.#lastPublish = now;
    } else {
      if (last !== null && now - last < profile.periodS) return null;
      // The clock-driven profile keeps a fixed cadence (like the thesis's setInterval) instead
      // of drifting by the tick granularity; after a pause it starts a new grid.
      this.#lastPublish =
        last !== null && now - last < 2 * profile.periodS ? last + profile.periodS : now;
    }
    const answersGoal = this.#unanswered;
    this.#unanswered = false;
    if (this.#lost(now)) {
      if (this.#searchSince === null) this.#searchSince = now;
      return { linear: 0, angular: this.#lastSide * profile.searchAngular, seq: null, frame: null };
    }
    const wanted = this.law({ ...goal, age: now - this.#captured }, pose, profile);
    // Where the goal put the target, not where the turns since have left the estimate: a vehicle
    // that turned past a target that left by the right must still search right.
    if (answersGoal && wanted.angular !== 0) this.#lastSide = wanted.angular > 0 ? 1 : -1;
    return { ...wanted, seq: goal.seq ?? null, frame: goal.frame ?? null };
  }
}
