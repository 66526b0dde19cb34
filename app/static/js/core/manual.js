// The operator's wheel at the vehicle: mode, drive commands and the dead-man (docs/architecture.md,
// "Who holds the wheel"). A port of vehicle_agent/core/manual.py, checked against it on shared
// sequences (tests/vehicle_agent/core/manual_sequences.py, e2e/test_manual_js.py); its numbers, the
// dead-man time among them, come from app/protocol/control.py through the page's embedded config
// (`config.control`).
import { ZERO_TWIST } from './control.js';

const unit = (value) => Math.max(-1, Math.min(1, value));

/**
 * While manual, goals are the caller's to ignore (`manual`) and only drive commands move the
 * turtle, scaled to the profile's manual speeds; moving on a command and hearing none for
 * `deadmanS` stops it (one zero Twist from `tick`). Times are seconds, given with each call.
 */
export class ManualDrive {
  #lastSeq = 0;
  #lastAt = 0;
  #moving = false;

  constructor(profile, deadmanS) {
    this.profile = profile;
    this.deadmanS = deadmanS;
    this.mode = 'auto';
    this.operator = null;
  }

  get manual() {
    return this.mode === 'manual';
  }

  /** The relay's mode; a change of mode stops the turtle first (zero Twist), else null. */
  setMode(mode, operator) {
    const changed = mode !== this.mode;
    this.mode = mode;
    this.operator = mode === 'manual' ? operator : null;
    if (!changed) return null;
    this.#lastSeq = 0; // the relay numbers each operator's commands afresh
    this.#moving = false;
    return ZERO_TWIST;
  }

  /** A new link to a relay: back to auto (a new relay knows of no operator), seq afresh. */
  resetLink() {
    this.mode = 'auto';
    this.operator = null;
    this.#lastSeq = 0;
    this.#moving = false;
  }

  /** A drive command's Twist at `now`, or null when not manual or not the newest command. */
  drive(seq, linear, angular, now) {
    if (!this.manual || seq <= this.#lastSeq) return null;
    this.#lastSeq = seq;
    this.#lastAt = now;
    const twist = {
      linear: unit(linear) * this.profile.manualLinear,
      angular: unit(angular) * this.profile.manualAngular,
      seq: null,
      frame: null,
    };
    this.#moving = twist.linear !== 0 || twist.angular !== 0;
    return twist;
  }

  /** The dead-man: the zero Twist once no command came for `deadmanS` while moving. */
  tick(now) {
    if (this.#moving && now - this.#lastAt >= this.deadmanS) {
      this.#moving = false;
      return ZERO_TWIST;
    }
    return null;
  }

  /** Seconds until the dead-man stops the turtle, null while it is not moving. */
  untilDeadman(now) {
    if (!this.#moving) return null;
    return Math.max(0, this.#lastAt + this.deadmanS - now);
  }
}
