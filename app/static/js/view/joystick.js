// The drive joystick on the client page (for touch screens): a round pad whose knob follows one
// finger; the finger's offset from the pad's centre is the drive command (core/joystick.js).
// It captures its pointer, so a drag that leaves the pad keeps driving, and takes every touch on
// it (app.css: touch-action none), so dragging never scrolls or zooms the page.
import { StickGesture } from '../core/joystick.js';

/** True when the device has a touch screen (the pad is shown only there). */
export function hasTouch() {
  return navigator.maxTouchPoints > 0 || matchMedia('(any-pointer: coarse)').matches;
}

/**
 * Wires the pad element (`.joystick` holding a `.knob`): `onCommand({linear, angular})` while a
 * finger holds it, `onCommand(null)` the moment it lifts, is cancelled, or the pad is disabled.
 */
export class Joystick {
  #gesture = new StickGesture();

  constructor(pad, onCommand) {
    this.pad = pad;
    this.knob = pad.querySelector('.knob');
    this.onCommand = onCommand;
    this.enabled = false;
    pad.addEventListener('pointerdown', (event) => this.#down(event));
    pad.addEventListener('pointermove', (event) => {
      if (this.#gesture.move(event.pointerId, event.clientX, event.clientY)) this.#changed();
    });
    // A cancelled pointer (the browser took the gesture, a call came in) is a lifted finger, and
    // so is one whose capture was lost some other way.
    for (const type of ['pointerup', 'pointercancel', 'lostpointercapture']) {
      pad.addEventListener(type, (event) => {
        if (this.#gesture.lift(event.pointerId)) this.#changed();
      });
    }
    pad.addEventListener('contextmenu', (event) => event.preventDefault());
    addEventListener('blur', () => this.#release());
  }

  /** Show the pad (on a touch screen). */
  show() {
    this.pad.hidden = false;
  }

  /** On while this client holds the wheel; off releases a finger still on the pad. */
  setEnabled(on) {
    this.enabled = on;
    this.pad.setAttribute('aria-disabled', String(!on));
    if (!on) this.#release();
  }

  #down(event) {
    if (!this.enabled) return;
    const pad = this.pad.getBoundingClientRect();
    const knob = this.knob.getBoundingClientRect();
    const centre = { x: pad.left + pad.width / 2, y: pad.top + pad.height / 2 };
    // Full speed where the knob's edge meets the rim.
    const travel = (pad.width - knob.width) / 2;
    if (!this.#gesture.press(event.pointerId, event.clientX, event.clientY, centre, travel)) {
      return;
    }
    event.preventDefault();
    this.pad.setPointerCapture(event.pointerId);
    this.#changed();
  }

  #release() {
    if (this.#gesture.release()) this.#changed();
  }

  #changed() {
    const { x, y } = this.#gesture.knob;
    this.knob.style.transform = `translate(${x}px, ${y}px)`;
    this.pad.classList.toggle('held', this.#gesture.held);
    this.onCommand(this.#gesture.command);
  }
}
