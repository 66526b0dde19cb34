// The client's glass-to-glass figure: reads the frame tag of every frame its <video> presents
// (requestVideoFrameCallback; the tag's top rows drawn into a small canvas), matches it with
// the vehicle's capture time (core/glass-to-glass.js) and shows the figure. The tag's blocks
// scale with the picture, so a forward at half size (the relay's re-encoding fallback) reads as
// well as the vehicle's own size (the pass-through).
import { GlassToGlass } from '../core/glass-to-glass.js';
import { decodeFrameTag, tagBlockSize } from '../core/frame-tag.js';
import { fmt, FIGURES_PERIOD_MS, throttle } from './ui.js';

// Presented frames after which a video with no tag is said to have none.
const UNTAGGED_AFTER = 30;

export class GlassView {
  #callback = null;

  /**
   * @param {object} options
   * @param {HTMLVideoElement} options.video the relayed video
   * @param {{blocksPerWidth: number, markerBlocks: number, bits: number}} options.layout the
   *   frame tag's (config.protocol.frameTag)
   * @param {HTMLElement} options.figure where the figure is shown
   */
  constructor({ video, layout, figure }) {
    this.video = video;
    this.layout = layout;
    this.figure = figure;
    this.glass = new GlassToGlass();
    this.presented = 0; // frames presented since the last new video
    this.tagged = 0; // of which with a frame tag
    this.canvas = document.createElement('canvas');
    this.context = this.canvas.getContext('2d', { willReadFrequently: true });
    this.show = throttle(FIGURES_PERIOD_MS, () => this.#show());
  }

  /** A `frameTimes` message: when the vehicle captured its latest frames. */
  captured(msg) {
    for (const { frame, t } of msg.frames) this.glass.captured(frame, t);
    this.show();
  }

  /** A new video arrived (or the link went): its frames are numbered afresh. */
  newVideo() {
    this.glass.reset();
    this.presented = 0;
    this.tagged = 0;
    if (this.#callback === null)
      this.#callback = this.video.requestVideoFrameCallback(this.#onFrame);
    this.show();
  }

  #onFrame = (_now, metadata) => {
    this.#callback = this.video.requestVideoFrameCallback(this.#onFrame);
    // When this frame is expected on the screen, on the wall clock the vehicle's times use.
    const shownAt = performance.timeOrigin + metadata.expectedDisplayTime;
    this.presented += 1;
    const frame = this.#readTag(metadata.width);
    if (frame !== null) {
      this.tagged += 1;
      this.glass.presented(frame, shownAt);
    }
    this.show();
  };

  /** The tag of the frame being presented (drawImage draws it, in this callback), or null. */
  #readTag(width) {
    const rows = tagBlockSize(this.layout, width);
    if (rows < 2) return null;
    if (this.canvas.width !== width) this.canvas.width = width;
    if (this.canvas.height !== rows) this.canvas.height = rows;
    this.context.drawImage(this.video, 0, 0, width, rows, 0, 0, width, rows);
    const pixels = this.context.getImageData(0, 0, width, rows).data;
    return decodeFrameTag(this.layout, width, rows, pixels);
  }

  #show() {
    const summary = this.glass.summary();
    // Short enough to stay on one line beside its name on a phone; the title says more.
    let [text, title] = ['–', ''];
    if (summary !== null) text = `${fmt(summary.p50Ms, 0)} ms (p95 ${fmt(summary.p95Ms, 0)})`;
    else if (this.tagged > 0)
      [text, title] = ['waiting for capture times', "the vehicle's capture times have not come"];
    else if (this.presented >= UNTAGGED_AFTER)
      [text, title] = ['no frame tag', 'not measured: the video carries no frame tag'];
    if (this.figure.textContent !== text) this.figure.textContent = text;
    if (this.figure.title !== title) this.figure.title = title;
  }
}
