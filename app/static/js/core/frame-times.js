// When the vehicle's own camera took its recent frames, by frame tag: a goal names the frame the
// relay found its target in, and a camera the vehicle carries had the heading of that moment. A
// port of vehicle_agent/core/frame_times.py; both run the pilot's shared sequences
// (tests/vehicle_agent/core/pilot_sequences.py), and
// tests/vehicle_agent/core/test_frame_times.py states the rule. How many frames are kept is
// `config.control.keptFrames`.

export class FrameTimes {
  #times = new Map(); // frame number -> when it was taken, oldest first

  constructor(kept) {
    this.kept = kept;
  }

  /** Frame number `frame` was taken at `at`. */
  add(frame, at) {
    this.#times.delete(frame);
    this.#times.set(frame, at);
    if (this.#times.size > this.kept) this.#times.delete(this.#times.keys().next().value);
  }

  /** When frame `frame` was taken, null when it is not one of the last frames. */
  capturedAt(frame) {
    return frame === null ? null : (this.#times.get(frame) ?? null);
  }
}
