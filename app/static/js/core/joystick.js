// The on-screen joystick's rule (the client page's console on a touch screen): where one finger
// holds the pad gives the drive command, on the same scale as the keys' and a gamepad stick's
// (view/drive-input.js): each axis a share of the profile's manual speed, in [−1, 1]. Pure: no
// DOM, no clock; view/joystick.js measures the pad and draws the knob. Its test:
// e2e/test_joystick_js.py.

/** An axis nearer the centre than this reads 0: a resting finger or stick wobbles. */
const STICK_DEADZONE = 0.1;
/**
 * The pad's commands move in steps of 1/STICK_STEPS: a finger resting on glass jitters by a
 * pixel or two, and every change of command is sent at once.
 */
const STICK_STEPS = 20;

/** One stick axis as a command axis: 0 within the dead zone, held to [−1, 1] beyond. */
export function stickAxis(value) {
  return Math.abs(value) < STICK_DEADZONE ? 0 : Math.max(-1, Math.min(1, value));
}

/**
 * The command of a finger `dx`, `dy` pixels from the pad's centre (screen axes: x right, y
 * down) on a pad whose knob travels `radius` pixels: up drives forward, left turns
 * counter-clockwise (θ increases), as ↑ and ←. At the rim an axis is at full speed, and beyond
 * it each axis stays at its limit, as a key's ±1 does.
 */
function dragCommand(dx, dy, radius) {
  const axis = (offset) => stickAxis(Math.round((offset / radius) * STICK_STEPS) / STICK_STEPS);
  return { linear: axis(-dy), angular: axis(-dx) };
}

/** Where the knob is drawn for a finger at (`dx`, `dy`): under it, held within the rim. */
function knobOffset(dx, dy, radius) {
  const distance = Math.hypot(dx, dy);
  if (distance <= radius) return { x: dx, y: dy };
  return { x: (dx * radius) / distance, y: (dy * radius) / distance };
}

/**
 * One finger drives the pad: the first pointer pressed on it, until that pointer lifts or is
 * cancelled. Another finger neither moves nor releases it. Each event method says whether it
 * changed the drive; `command` is then what to drive with (null once released).
 */
export class StickGesture {
  #pointer = null;
  #centre = { x: 0, y: 0 };
  #radius = 1;
  #offset = { x: 0, y: 0 };

  /** Whether a finger holds the pad. */
  get held() {
    return this.#pointer !== null;
  }

  /** The drive command ({linear, angular}) while held, else null. */
  get command() {
    return this.held ? dragCommand(this.#offset.x, this.#offset.y, this.#radius) : null;
  }

  /** The knob's offset from the pad's centre, in pixels (0, 0 when released). */
  get knob() {
    return this.held ? knobOffset(this.#offset.x, this.#offset.y, this.#radius) : { x: 0, y: 0 };
  }

  /**
   * Pointer `id` pressed at (`x`, `y`) on a pad centred at `centre` whose knob travels
   * `radius` pixels: it drives, unless another pointer already does.
   */
  press(id, x, y, centre, radius) {
    if (this.held) return false;
    this.#pointer = id;
    this.#centre = centre;
    this.#radius = radius;
    return this.move(id, x, y);
  }

  /** Pointer `id` moved to (`x`, `y`). */
  move(id, x, y) {
    if (!this.held || id !== this.#pointer) return false;
    this.#offset = { x: x - this.#centre.x, y: y - this.#centre.y };
    return true;
  }

  /** Pointer `id` lifted or was cancelled: released if it was the one driving. */
  lift(id) {
    if (!this.held || id !== this.#pointer) return false;
    this.#pointer = null;
    return true;
  }

  /** Let go, whoever holds it (the wheel went elsewhere, the page lost the focus). */
  release() {
    const was = this.held;
    this.#pointer = null;
    return was;
  }
}
