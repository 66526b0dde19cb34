// Target lock: follow the object a person clicked, not the largest one. The rule and its
// numbers are written once, in app/protocol/lock.py; they reach the page as
// `config.protocol.lock` ({searchAfterS, releaseAfterS, maxScale, reach}), passed in here.
//
// The relay's vision worker owns the lock (worker/vision-worker.js): it asks, chooses and
// updates on each snapshot.
//
// The Python twin is app/vision/lock.py: the same decisions from the same doubles, checked on
// the same sequences (e2e/test_lock_js.py). Pure, no DOM; times in seconds, given.
import { largest } from './tracking-window.js';

/** Whether pixel (x, y) is inside box [x, y, w, h], edges included. */
export function contains([bx, by, bw, bh], x, y) {
  return bx <= x && x <= bx + bw && by <= y && y <= by + bh;
}

/** The box clicked at (x, y): the smallest containing it (first of equal areas), or null. */
export function pick(x, y, boxes) {
  let best = null;
  for (const b of boxes) {
    if (contains(b, x, y) && (best === null || b[2] * b[3] < best[2] * best[3])) best = b;
  }
  return best;
}

/** Intersection over union of two boxes. */
export function overlap(a, b) {
  const w = Math.min(a[0] + a[2], b[0] + b[2]) - Math.max(a[0], b[0]);
  const h = Math.min(a[1] + a[3], b[1] + b[3]) - Math.max(a[1], b[1]);
  if (w <= 0 || h <= 0) return 0;
  const inter = w * h;
  return inter / (a[2] * a[3] + b[2] * b[3] - inter);
}

/** Neither side of `box` is more than maxScale times the locked box's, nor less than 1/maxScale. */
export function similar(box, locked, maxScale) {
  return [2, 3].every((i) => box[i] <= maxScale * locked[i] && locked[i] <= maxScale * box[i]);
}

/**
 * The box among `boxes` that continues the track of `locked`, or null: of the boxes of a similar
 * size, the one that overlaps it most; when none overlaps, the nearest centre within `rule.reach`
 * times its longer side, unless `anywhere`. Ties go to the first box, as in lock.py.
 */
export function associate(locked, boxes, anywhere, rule) {
  const candidates = boxes.filter((b) => similar(b, locked, rule.maxScale));
  let best = null;
  let bestOverlap = 0;
  for (const b of candidates) {
    const iou = overlap(b, locked);
    if (iou > bestOverlap) {
      best = b;
      bestOverlap = iou;
    }
  }
  if (best !== null) return best;
  const lx = locked[0] + locked[2] / 2;
  const ly = locked[1] + locked[3] / 2;
  const reach = rule.reach * Math.max(locked[2], locked[3]);
  const limit = anywhere ? Infinity : reach * reach;
  let bestD2 = Infinity;
  for (const b of candidates) {
    const dx = b[0] + b[2] / 2 - lx;
    const dy = b[1] + b[3] / 2 - ly;
    const d2 = dx * dx + dy * dy;
    if (d2 <= limit && (best === null || d2 < bestD2)) {
      best = b;
      bestD2 = d2;
    }
  }
  return best;
}

/**
 * The relay's lock on one target. `state`: 'none' (the largest box is the target), 'locked'
 * (seen on the last snapshot), 'lost' (looked for near where it was), 'searching' (lost long
 * enough to look in the whole frame).
 */
export class TargetLock {
  /**
   * @param {{searchAfterS: number, releaseAfterS: number, maxScale: number, reach: number}} rule
   */
  constructor(rule) {
    this.rule = rule;
    this.box = null; // the locked target's box when last seen
    this.seenAt = 0;
    this.state = 'none';
    this.epoch = 0; // bumped by every lock and release
  }

  /** A click at (x, y) on a snapshot that found `boxes`: lock the box clicked, or release. */
  lock(x, y, boxes, now) {
    const box = pick(x, y, boxes);
    if (box === null) {
      this.release();
      return false;
    }
    this.box = box;
    this.seenAt = now;
    this.state = 'locked';
    this.epoch += 1;
    return true;
  }

  /** Back to the default choice (the largest box). */
  release() {
    this.box = null;
    this.state = 'none';
    this.epoch += 1;
  }

  /** What the next snapshot follows, {box, anywhere, epoch}, or null for the default choice. */
  query(now) {
    if (this.box === null) return null;
    return {
      box: this.box,
      anywhere: now - this.seenAt > this.rule.searchAfterS,
      epoch: this.epoch,
    };
  }

  /** The outcome of the snapshot asked with `query`: the box chosen or null; the new state, if
   * it changed. */
  update(query, chosen, now) {
    if (query === null || query.epoch !== this.epoch) return null;
    const before = this.state;
    if (chosen !== null) {
      this.box = chosen;
      this.seenAt = now;
      this.state = 'locked';
    } else if (now - this.seenAt > this.rule.releaseAfterS) {
      this.release();
    } else if (now - this.seenAt > this.rule.searchAfterS) {
      this.state = 'searching';
    } else {
      this.state = 'lost';
    }
    return this.state !== before ? this.state : null;
  }
}

/** The rule that picks the target among a snapshot's boxes: the locked one's track, or the
 * largest. */
export function chooser(lock, rule) {
  if (lock === null) return largest;
  return (boxes) => associate(lock.box, boxes, lock.anywhere, rule);
}
