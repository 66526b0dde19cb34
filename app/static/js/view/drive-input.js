// The operator's console on the client page (docs/architecture.md, "The data path of a drive
// command"): drive commands from the keyboard, the on-screen joystick and a gamepad, sent to the
// relay, which forwards them to the vehicle. A held key, pad or stick resends its command every
// `repeatS` (the vehicle's dead-man stops the turtle when they stop coming); letting go sends one
// zero command at once.
import { stickAxis } from '../core/joystick.js';

const KEYS = Object.freeze({
  ArrowUp: { linear: 1, angular: 0 },
  ArrowDown: { linear: -1, angular: 0 },
  ArrowLeft: { linear: 0, angular: 1 }, // counter-clockwise: θ increases
  ArrowRight: { linear: 0, angular: -1 },
});
// The W3C "standard" gamepad mapping, driven as teleop_twist_joy drives a joystick: hold the
// enable button (the left shoulder button) as a dead-man, the left stick for linear/angular.
const ENABLE_BUTTON = 4;
const LINEAR_AXIS = 1; // left stick, up is −1
const ANGULAR_AXIS = 0; // left stick, left is −1

const ZERO = Object.freeze({ linear: 0, angular: 0 });

/** The command of the arrow keys held (opposite keys cancel). */
function keyCommand(held) {
  let linear = 0;
  let angular = 0;
  for (const key of held) {
    linear += KEYS[key].linear;
    angular += KEYS[key].angular;
  }
  return { linear, angular };
}

/** The command of a gamepad, or null unless its enable button is held. */
function padCommand(pad) {
  if (!pad || pad.mapping !== 'standard' || !pad.buttons[ENABLE_BUTTON]?.pressed) return null;
  const axis = (index) => stickAxis(-(pad.axes[index] ?? 0));
  return { linear: axis(LINEAR_AXIS), angular: axis(ANGULAR_AXIS) };
}

const isZero = (command) => command.linear === 0 && command.angular === 0;

/**
 * Turns keys, the joystick and gamepads into drive commands while `enabled` (this client holds
 * the wheel), in that order of precedence. `send({linear, angular})` carries one to the relay.
 */
export class DriveInput {
  #held = new Set();
  #stick = null; // the joystick's command while a finger holds it
  #last = ZERO;
  #timer = null;

  constructor({ send, repeatS, gamepads = () => navigator.getGamepads?.() ?? [] }) {
    this.send = send;
    this.repeatS = repeatS;
    this.gamepads = gamepads;
    this.enabled = false;
    this.sent = 0;
    addEventListener('keydown', (event) => this.#key(event, true));
    addEventListener('keyup', (event) => this.#key(event, false));
    // A key released while the page had no focus never sends its keyup: let go of all of them.
    addEventListener('blur', () => this.#releaseAll());
  }

  /** On: keys, joystick and gamepads drive; off: a zero command if moving, then silence. */
  setEnabled(on) {
    if (on === this.enabled) return;
    this.enabled = on;
    if (on) {
      this.#timer = setInterval(() => this.#update(true), this.repeatS * 1000);
    } else {
      clearInterval(this.#timer);
      this.#timer = null;
      this.#releaseAll();
    }
  }

  /** The joystick's command while a finger holds it; null when it lifts (sent at once). */
  setStick(command) {
    this.#stick = command;
    this.#update(false);
  }

  #key(event, down) {
    if (!this.enabled || event.target?.closest?.('input, select, textarea')) return;
    if (event.key === ' ') {
      // Space: stop, whatever is held.
      event.preventDefault();
      this.#held.clear();
      this.#emit(ZERO);
      return;
    }
    if (!(event.key in KEYS)) return;
    event.preventDefault(); // the arrows would scroll the page
    if (down) this.#held.add(event.key);
    else this.#held.delete(event.key);
    this.#update(false);
  }

  #releaseAll() {
    this.#held.clear();
    this.#stick = null;
    if (!isZero(this.#last)) this.#emit(ZERO);
  }

  /**
   * The keys', else the joystick's, else a gamepad's command: sent when it changed, and again
   * when `repeat`.
   */
  #update(repeat) {
    if (!this.enabled) return;
    let command = this.#held.size > 0 ? keyCommand(this.#held) : this.#stick;
    if (command === null) {
      for (const pad of this.gamepads()) {
        command = padCommand(pad);
        if (command !== null) break;
      }
    }
    command ??= ZERO;
    const changed = command.linear !== this.#last.linear || command.angular !== this.#last.angular;
    if (changed || (repeat && !isZero(command))) this.#emit(command);
  }

  #emit(command) {
    this.#last = command;
    this.sent += 1;
    this.send(command);
  }
}
