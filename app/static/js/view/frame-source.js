// How the vehicle's video reaches the relay's snapshot loop (core/snapshot-loop.js), one of
// three ways, chosen once per page:
// - 'period': a relay profile with a snapshot period (thesis) takes the frame the video element
//   shows, every period;
// - 'decoded': each frame straight from the decoder (MediaStreamTrackProcessor), without waiting
//   for the video element to present it;
// - 'presented': where the browser has no MediaStreamTrackProcessor, each frame the video
//   element presents (requestVideoFrameCallback).
// Every frame goes to the loop: one that comes while the loop analyses another waits for it,
// replacing an older one waiting, so the next snapshot is always the freshest frame.

export class FrameSource {
  #running = false;
  #track = null;
  #timer = null;
  #callback = null;
  #reader = null;

  /**
   * @param {object} options
   * @param {HTMLVideoElement} options.video the element showing the vehicle's video
   * @param {number|null} options.periodMs a snapshot every this many ms, or null: every frame
   * @param {(err: Error) => void} options.onError a frame reader that failed
   */
  constructor({ video, periodMs, onError }) {
    this.video = video;
    this.periodMs = periodMs;
    this.onError = onError;
    this.loop = null; // the SnapshotLoop fed, once there is one
    if (periodMs !== null) this.kind = 'period';
    else if (typeof MediaStreamTrackProcessor === 'function') this.kind = 'decoded';
    else this.kind = 'presented';
  }

  /** Whether the frames are read off the video element (which must then show the video). */
  get readsVideoElement() {
    return this.kind !== 'decoded';
  }

  /** Feed the loop from now on. */
  start() {
    this.#running = true;
    if (this.kind === 'period') this.#timer = setInterval(() => this.#takeShown(), this.periodMs);
    else if (this.kind === 'decoded') this.#readDecoded();
    else this.#awaitPresented();
  }

  /** Feed it no more. */
  stop() {
    this.#running = false;
    if (this.#timer !== null) clearInterval(this.#timer);
    if (this.#callback !== null) this.video.cancelVideoFrameCallback(this.#callback);
    this.#reader?.cancel().catch(() => {}); // the stream may have ended with its track
    this.#timer = null;
    this.#callback = null;
    this.#reader = null;
  }

  /** The vehicle's video track (null: none): a new one is read from its first frame. */
  setTrack(track) {
    this.#track = track;
    if (this.#running && this.kind !== 'period') {
      this.stop();
      this.start();
    }
  }

  async #readDecoded() {
    if (this.#track === null) return;
    const reader = new MediaStreamTrackProcessor({ track: this.#track }).readable.getReader();
    this.#reader = reader;
    try {
      for (;;) {
        const { value: frame, done } = await reader.read();
        if (done) return;
        if (this.loop === null || this.#reader !== reader) frame.close();
        // A VideoFrame wraps the decoded picture without copying it; the worker converts it to
        // RGBA straight into OpenCV's memory.
        else this.loop.frame(frame);
      }
    } catch (err) {
      this.onError(err);
    }
  }

  #awaitPresented() {
    const onFrame = () => {
      if (!this.#running) return;
      this.#callback = this.video.requestVideoFrameCallback(onFrame);
      this.#takeShown();
    };
    this.#callback = this.video.requestVideoFrameCallback(onFrame);
  }

  /** The frame the video element shows, unless there is none yet. */
  #takeShown() {
    if (this.loop === null || this.video.videoWidth === 0) return;
    this.loop.frame(new VideoFrame(this.video));
  }
}
