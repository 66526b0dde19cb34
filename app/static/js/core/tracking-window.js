// Detect, then track: the search window around the last target, and when to scan it all.
//
// Once an operation has found its target, the next snapshots search only a window around the
// last target box, in the same detection image (same reduction, same cascade, same
// parameters), for sizes near the target's own. The whole frame is scanned again every
// `fullScanEvery` snapshots, and at once, on the same snapshot, when the window finds nothing.
// The vision worker holds one Tracker per operation and profile; cascade operations take the
// window through detect(rgba, around).
//
// The Python side is app/vision/window.py: the same window from the same doubles and the same
// decisions, so `autopilot parity` compares the windowed path box for box.

/**
 * The window {x, y, width, height} in detection-image pixels around `around` (a full-frame box
 * [x, y, w, h]), grown by `margin` of its size on each side and clipped to the `width` ×
 * `height` detection image; null when empty. `factor` scales detection pixels to the full frame.
 */
export function searchRegion(around, factor, width, height, margin) {
  const [x, y, w, h] = around.map((v) => v / factor);
  const x0 = Math.max(0, Math.floor(x - w * margin));
  const y0 = Math.max(0, Math.floor(y - h * margin));
  const x1 = Math.min(width, Math.ceil(x + w + w * margin));
  const y1 = Math.min(height, Math.ceil(y + h + h * margin));
  if (x1 <= x0 || y1 <= y0) return null;
  return { x: x0, y: y0, width: x1 - x0, height: y1 - y0 };
}

/**
 * The smallest and largest object sizes a window search looks for, {min: [w, h], max: [w, h]}
 * in detection-image pixels: the last target's (`around`, full-frame) shorter side divided by
 * `ratio` and longer side multiplied by it, within the operation's own `minSize` and `maxSize`
 * ([0, 0]: no limit). The small scales are the cascade's costly ones; a target that grew or
 * shrank past the range leaves the window empty, and the full scan that follows finds it.
 */
export function searchSizes(around, factor, ratio, minSize, maxSize) {
  const shortest = Math.floor(Math.min(around[2], around[3]) / factor / ratio);
  const longest = Math.ceil((Math.max(around[2], around[3]) / factor) * ratio);
  const min = [Math.max(minSize[0], shortest), Math.max(minSize[1], shortest)];
  if (maxSize[0] === 0 || maxSize[1] === 0) return { min, max: [longest, longest] };
  return { min, max: [Math.min(maxSize[0], longest), Math.min(maxSize[1], longest)] };
}

/**
 * Where to reduce only the window: {reduced, source}, the window `region` ({x, y, width,
 * height}, detection-image pixels) grown to the reduction's grid, and the part of the `width` ×
 * `height` frame that reduces to exactly it; null when the grid is not exact in doubles (then
 * the whole frame is reduced and the window cropped from it). `size` is the detection image's
 * {width, height}. Why this holds: app/vision/window.py source_rect.
 */
export function sourceRect(region, width, height, size) {
  const x = onGrid(region.x, region.x + region.width, width, size.width);
  const y = onGrid(region.y, region.y + region.height, height, size.height);
  if (x === null || y === null) return null;
  return {
    reduced: { x: x.lo, y: y.lo, width: x.hi - x.lo, height: y.hi - y.lo },
    source: { x: x.from, y: y.from, width: x.to - x.from, height: y.to - y.from },
  };
}

function gcd(a, b) {
  return b === 0 ? a : gcd(b, a % b);
}

/** One axis of sourceRect: [start, end) grown to the grid, and the frame pixels under it. */
function onGrid(start, end, frame, reduced) {
  const common = gcd(frame, reduced);
  const period = reduced / common;
  const stride = frame / common;
  if ((period & (period - 1)) !== 0) return null;
  const lo = Math.floor(start / period) * period;
  const hi = Math.min(reduced, Math.ceil(end / period) * period);
  return { lo, hi, from: (lo / period) * stride, to: (hi / period) * stride };
}

/** The largest box, the first of equal areas (the one whose centre is the target). */
export function largest(boxes) {
  let best = null;
  for (const b of boxes) if (best === null || b[2] * b[3] > best[2] * best[3]) best = b;
  return best;
}

/** When to search a window and when the whole frame; fullScanEvery 1 turns tracking off. */
export class Tracker {
  constructor(fullScanEvery) {
    this.fullScanEvery = fullScanEvery;
    this.reset();
  }

  /** The full-frame box to search around on the next snapshot, or null for a full scan. */
  window() {
    if (this.last === null || this.windowed >= this.fullScanEvery - 1) return null;
    return this.last;
  }

  /** The target box a snapshot's search chose (null: none), and how ('full' or 'window'). */
  record(box, scan) {
    this.last = box;
    this.windowed = scan === 'window' ? this.windowed + 1 : 0;
  }

  /** Forget the target: the next snapshot is a full scan. */
  reset() {
    this.last = null; // full-frame box of the last target
    this.windowed = 0; // snapshots searched in a window since the last full scan
  }
}

/**
 * One snapshot: search the window if there is one, the whole frame when it finds nothing.
 * `detect(around)` runs the operation around a full-frame box, or on the whole frame for null.
 * `choose(boxes)` picks the target box: the largest, or the locked target's (lock.js); a window
 * where it picks none is a miss. `keep`: where a target that the whole-frame scan cannot find was
 * last seen (a lock found at full resolution), or null: when the full scan does not find it
 * either, the window around `keep` is searched last, and a target found there is the
 * snapshot's (scan 'window'). Returns {found, scan}.
 */
export function step(tracker, detect, choose = largest, keep = null) {
  const around = tracker.window();
  if (around !== null) {
    const found = detect(around);
    const box = choose(found.boxes);
    if (box !== null) {
      tracker.record(box, 'window');
      return { found, scan: 'window' };
    }
  }
  const found = detect(null);
  const box = choose(found.boxes);
  // A full scan ran, found or not: the next one is due in fullScanEvery snapshots.
  tracker.record(box, 'full');
  if (box === null && keep !== null && !sameBox(keep, around)) {
    const kept = detect(keep);
    const keptBox = choose(kept.boxes);
    if (keptBox !== null) {
      tracker.last = keptBox;
      return { found: kept, scan: 'window' };
    }
  }
  return { found, scan: 'full' };
}

function sameBox(a, b) {
  return b !== null && a.every((v, i) => v === b[i]);
}
