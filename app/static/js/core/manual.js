// The operator's wheel at the vehicle: mode, drive commands and the dead-man (docs/architecture.md,
// "Who holds the wheel"). A port of vehicle_agent/manual.py, checked against it
// (e2e/test_manual_js.py); its numbers come from app/protocol/control.py through the page's
// embedded config (`config.control`).
import { ZERO_TWIST } from './control.js';

const unit = (value) => Math.max(-1, Math.min(1, value));

/**
 * While manual, goals are the caller's to ignore (`manual`) and only drive commands move the
 * turtle, scaled to the profile's manual speeds; moving on a command and hearing none for
 * `deadmanS` stops it (one zero Twist from `tick`). Times are seconds.
 */
export class ManualDrive {
  #lastSeq = 0;
  #lastAt = 0;
  #moving = false;

  constructor(profile, deadmanS, clock = () => performance.now() / 1000) {
    this.profile = profile;
    this.deadmanS = deadmanS;
    this.clock = clock;
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

  /** A drive command's Twist, or null when not manual or not the newest command. */
  drive(seq, linear, angular) {
    if (!this.manual || seq <= this.#lastSeq) return null;
    this.#lastSeq = seq;
    this.#lastAt = this.clock();
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
  tick() {
    if (this.#moving && this.clock() - this.#lastAt >= this.deadmanS) {
      this.#moving = false;
      return ZERO_TWIST;
    }
    return null;
  }

  /** Seconds until the dead-man stops the turtle, null while it is not moving. */
  untilDeadman() {
    if (!this.#moving) return null;
    return Math.max(0, this.#lastAt + this.deadmanS - this.clock());
  }
}
