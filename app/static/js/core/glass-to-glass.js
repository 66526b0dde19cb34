// Glass to glass at the client: from the moment the vehicle captured a frame to the moment this
// client showed it. The vehicle sends each tagged frame's capture time (`frameTimes`, forwarded
// by the relay); the client reads the frame tag of each frame it presents. Either may come
// first, so each waits here for the other, a bounded while. The two times are on the vehicle's
// and the client's wall clocks: one machine's clock in the bench, NTP-synchronised clocks in a
// deployment, whose offset the figure then carries (docs/contracts.md, "Glass to glass").
// Pure: times are given, no DOM, no WebRTC.

import { SampleRing } from './relay-stats.js';

/** Samples kept for a reader that polls (the bench): a minute at 30 frames/s. */
const KEPT_SAMPLES = 2000;
/** The live figure is the median and 95th percentile of this many latest samples. */
const RECENT_SAMPLES = 90;
/** Frames waiting for their other half: ten seconds at 30 frames/s. */
const WAITING = 300;
/**
 * A capture and a presentation this far apart are not the same frame (a vehicle that restarted
 * numbers its frames from 0 again), and make no sample.
 */
const SAME_FRAME_WITHIN_MS = 10_000;
/**
 * The figure is stale once no frame has been measured for this long (the camera stopped, or
 * the link): it speaks of frames that are no longer coming, so it is not shown as live.
 */
const STALE_AFTER_MS = 2000;

/** The `q`-quantile (0..1) of `values`, interpolated between the nearest ranks; null if none. */
function quantile(values, q) {
  if (values.length === 0) return null;
  const sorted = [...values].sort((a, b) => a - b);
  const at = (sorted.length - 1) * q;
  const lo = Math.floor(at);
  const hi = Math.min(lo + 1, sorted.length - 1);
  return sorted[lo] + (sorted[hi] - sorted[lo]) * (at - lo);
}

/** Capture times and presentation times of frames, matched by frame number. */
export class GlassToGlass {
  #captured = new Map(); // frame -> capture time, Unix ms (vehicle clock)
  #presented = new Map(); // frame -> presentation time, Unix ms (client clock)

  constructor({ kept = KEPT_SAMPLES, recent = RECENT_SAMPLES, waiting = WAITING } = {}) {
    this.waiting = waiting;
    this.samples = new SampleRing(kept);
    this.recent = new SampleRing(recent);
    /** Frames measured so far. */
    this.count = 0;
    this.last = null;
    this.lastShownAt = null; // when the last frame measured was shown, Unix ms (client clock)
  }

  /** The vehicle captured frame number `frame` at `tMs`. */
  captured(frame, tMs) {
    const shownAt = this.#presented.get(frame);
    if (shownAt === undefined) remember(this.#captured, frame, tMs, this.waiting);
    else {
      this.#presented.delete(frame);
      this.#measure(tMs, shownAt);
    }
  }

  /** This client presented frame number `frame` at `tMs`. */
  presented(frame, tMs) {
    const capturedAt = this.#captured.get(frame);
    if (capturedAt === undefined) remember(this.#presented, frame, tMs, this.waiting);
    else {
      this.#captured.delete(frame);
      this.#measure(capturedAt, tMs);
    }
  }

  /** Forget the frames still waiting (a new video: its frames are numbered afresh). */
  reset() {
    this.#captured.clear();
    this.#presented.clear();
  }

  /** The live figure, {p50Ms, p95Ms, lastMs, frames} over the latest samples, or null. */
  summary() {
    const recent = this.recent.toArray();
    if (recent.length === 0) return null;
    return {
      p50Ms: quantile(recent, 0.5),
      p95Ms: quantile(recent, 0.95),
      lastMs: this.last,
      frames: this.count,
    };
  }

  /** True when no frame has been measured for STALE_AFTER_MS before `nowMs` (or none ever). */
  stale(nowMs) {
    return this.lastShownAt === null || nowMs - this.lastShownAt > STALE_AFTER_MS;
  }

  #measure(capturedAt, shownAt) {
    const ms = shownAt - capturedAt;
    if (Math.abs(ms) > SAME_FRAME_WITHIN_MS) return;
    this.lastShownAt = Math.max(this.lastShownAt ?? shownAt, shownAt);
    this.count += 1;
    this.last = ms;
    this.samples.push(ms);
    this.recent.push(ms);
  }
}

/** Keep `frame` -> `t` in `waiting`, dropping the oldest entry once it holds `limit`. */
function remember(waiting, frame, t, limit) {
  waiting.delete(frame); // re-inserted last: a Map iterates in insertion order
  waiting.set(frame, t);
  if (waiting.size > limit) waiting.delete(waiting.keys().next().value);
}
