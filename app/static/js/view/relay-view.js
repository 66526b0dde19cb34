// What the relay page shows a person: the vehicle's video with the detections drawn on it (when
// it shows the video at all), the autopilot's figures, the lock, who drives, and the peers.
import { byTestId, drawDetections, FIGURES_PERIOD_MS, fmt, show, throttle } from './ui.js';

export class RelayView {
  #latest = null; // the last detections message, for the throttled figures
  #goalsSent = 0;
  #showFigures;

  /** @param {{preview: boolean}} options preview: whether the page shows the vehicle's video */
  constructor({ preview }) {
    this.preview = preview;
    this.video = byTestId('video');
    this.overlay = byTestId('overlay');
    this.#showFigures = throttle(FIGURES_PERIOD_MS, () => {
      show('goals-sent', String(this.#goalsSent));
      show('ms-per-snapshot', fmt(this.#latest.ms));
      show('goals-per-s', fmt(this.#latest.goalsPerS));
    });
  }

  /** The vehicle's video track, or null when it left. */
  vehicleTrack(track) {
    if (track === null) this.video.srcObject = null;
    else if (this.preview) this.video.srcObject = new MediaStream([track]);
  }

  /** A snapshot's detections, and the goals sent so far. */
  detections(latest, goalsSent) {
    this.#latest = latest;
    this.#goalsSent = goalsSent;
    if (this.preview) drawDetections(this.overlay, latest);
    this.#showFigures();
  }

  piloting(on) {
    show('piloting', on ? 'yes' : 'no');
  }

  operation(op) {
    show('operation', op);
  }

  /** Who drives: the client holding the wheel, or null for the autopilot. */
  operator(name) {
    show('mode', name === null ? 'autopilot' : `manual: ${name}`);
  }

  lock(state) {
    show('lock', state === 'none' ? 'none (largest)' : state);
  }

  /** One line per connection. */
  peers(lines) {
    show('peers', lines.join('; ') || 'none');
  }

  /** The state line: the room, and what the relay does in it. */
  state(text) {
    show('state', text);
  }
}
