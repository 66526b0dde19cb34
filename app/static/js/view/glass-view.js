// The client's glass-to-glass figure: reads the frame tag of every frame its <video> presents
// (requestVideoFrameCallback; the tag's top rows drawn into a small canvas), matches it with
// the vehicle's capture time (core/glass-to-glass.js) and shows the figure, or a dash once it
// is stale (no frame measured lately: the camera or the link stopped). The tag's blocks scale
// with the picture, so a forward at half size (the relay's re-encoding fallback) reads as well
// as the vehicle's own size (the pass-through). The tag stays in the stream, for the
// measurement, but the operator does not see it: while the video carries one, its rows are
// masked off the picture (a clip of the <video>; the canvas still reads the whole frame).
import { GlassToGlass } from '../core/glass-to-glass.js';
import { decodeFrameTag, tagBlockSize } from '../core/frame-tag.js';
import { fmt, FIGURES_PERIOD_MS, throttle } from './ui.js';

// Presented frames after which a video with no tag is said to have none.
const UNTAGGED_AFTER = 30;
// How often the figure is looked at when no frame comes: a stopped camera presents none.
const STALE_CHECK_MS = 500;

export class GlassView {
  #callback = null;
  #clip = ''; // the clip on the video (the browser may write it back in its own words)

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
    setInterval(this.show, STALE_CHECK_MS);
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
    // Another video may carry no tag: nothing of its picture is hidden until one is read.
    this.#setClip('');
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
      this.#maskTag(metadata.width, metadata.height);
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

  /**
   * Hide the tag's rows of a `width`×`height` picture from the operator: the clip runs from the
   * element's top to below the tag as the picture is laid out (object-fit: contain may put a
   * band above it).
   */
  #maskTag(width, height) {
    const { clientWidth, clientHeight } = this.video;
    const scale = Math.min(clientWidth / width, clientHeight / height);
    const top = (clientHeight - height * scale) / 2;
    const below = Math.ceil(top + tagBlockSize(this.layout, width) * scale);
    this.#setClip(`inset(${below}px 0px 0px)`);
  }

  #setClip(clip) {
    if (this.#clip === clip) return;
    this.#clip = clip;
    this.video.style.clipPath = clip;
  }

  #show() {
    const summary = this.glass.summary();
    // Short enough to stay on one line beside its name on a phone; the title says more.
    let [text, title] = ['–', ''];
    const now = performance.timeOrigin + performance.now();
    if (summary !== null && this.glass.stale(now))
      [text, title] = ['–', 'stale: no frame measured lately (the camera or the link stopped)'];
    else if (summary !== null) text = `${fmt(summary.p50Ms, 0)} ms (p95 ${fmt(summary.p95Ms, 0)})`;
    else if (this.tagged > 0)
      [text, title] = ['waiting for capture times', "the vehicle's capture times have not come"];
    else if (this.presented >= UNTAGGED_AFTER)
      [text, title] = ['no frame tag', 'not measured: the video carries no frame tag'];
    if (this.figure.textContent !== text) this.figure.textContent = text;
    if (this.figure.title !== title) this.figure.title = title;
  }
}
