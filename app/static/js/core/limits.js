// Every command within the robot's limits: clamped to its top speeds (the one place they hold a
// command: the laws ask for the speeds they want, and for linear the share of the top speed they
// allow), ramped within its accelerations. A port of vehicle_agent/core/limits.py (the rules are
// stated there, and tested in tests/vehicle_agent/core/test_limits.py); both run the pilot's
// shared sequences (tests/vehicle_agent/core/pilot_sequences.py, e2e/test_pilot_js.py). The
// limits are the robot description's (app/protocol/robot.py), through the page's embedded config
// (`config.robot`); a null there is "no limit".
//
// A stop (a zero Twist that answers no goal: stop, goal timeout, dead-man, lost link, mode
// change, released stick) is published at once, never ramped: the robot's base controller
// brakes within what its motors can do, and the dead-man's contract is a stop within 0.3 s.

/** True for a stop: a zero Twist that answers no goal. */
function isStop(twist) {
  return twist.linear === 0 && twist.angular === 0 && twist.seq === null;
}

const unbounded = (value) => (value === null ? Infinity : value);
const clamp = (value, limit) => Math.max(-limit, Math.min(limit, value));

// `current` moved toward `target` by at most accel·dt (exactly onto it when that reaches).
function toward(current, target, accel, dt) {
  const reach = accel === Infinity ? Infinity : accel * dt;
  if (Math.abs(target - current) <= reach) return target;
  return current + Math.sign(target - current) * reach;
}

export class Limiter {
  #current = { linear: 0, angular: 0, seq: null, frame: null };
  #target = this.#current;
  #at = null; // when the last Twist went out

  /**
   * @param {{maxLinear: number|null, maxAngular: number|null, linearAccel: number|null,
   *   angularAccel: number|null}} limits the robot's (`config.robot.description.limits`)
   * @param {number} stepS the longest time one ramp step may count (the pilot's tick)
   */
  constructor(limits, stepS) {
    this.limits = {
      maxLinear: unbounded(limits.maxLinear),
      maxAngular: unbounded(limits.maxAngular),
      linearAccel: unbounded(limits.linearAccel),
      angularAccel: unbounded(limits.angularAccel),
    };
    this.stepS = stepS;
  }

  /** True while the published Twist has not reached the command yet. */
  get ramping() {
    return (
      this.#current.linear !== this.#target.linear || this.#current.angular !== this.#target.angular
    );
  }

  /**
   * The Twist to publish now for the command `twist` ({linear, angular, seq, frame, topShare?}:
   * linear is held to that share of the top speed, 1 when it names none).
   */
  command(twist, now) {
    if (isStop(twist)) {
      this.#current = this.#target = twist;
      this.#at = now;
      return twist;
    }
    // A share of 0 reaches nothing, even of a robot without a top speed (Infinity · 0 is NaN).
    const share = twist.topShare ?? 1;
    this.#target = {
      linear: clamp(twist.linear, share > 0 ? this.limits.maxLinear * share : 0),
      angular: clamp(twist.angular, this.limits.maxAngular),
      seq: twist.seq,
      frame: twist.frame,
    };
    return this.#step(now);
  }

  /** The ramp's next step while the command is out of reach, else null. */
  tick(now) {
    if (!this.ramping || (this.#at !== null && now <= this.#at)) return null;
    return this.#step(now);
  }

  #step(now) {
    const dt = this.#at === null ? this.stepS : Math.min(Math.max(0, now - this.#at), this.stepS);
    const current = this.#current;
    const target = this.#target;
    this.#current = {
      linear: toward(current.linear, target.linear, this.limits.linearAccel, dt),
      angular: toward(current.angular, target.angular, this.limits.angularAccel, dt),
      seq: target.seq,
      frame: target.frame,
    };
    this.#at = now;
    return this.#current;
  }
}
