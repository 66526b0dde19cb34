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

/**
 * How far pixel (x, y) is from box [x, y, w, h] in the box's own size: the larger of the
 * horizontal gap over its width and the vertical gap over its height (0 inside, edges included).
 */
export function gap([bx, by, bw, bh], x, y) {
  const dx = Math.max(bx - x, 0, x - (bx + bw));
  const dy = Math.max(by - y, 0, y - (by + bh));
  return Math.max(dx / bw, dy / bh);
}

/**
 * The box clicked at (x, y): the smallest containing it (first of equal areas); else the box it
 * is nearest to in that box's own size (gap, first of equal gaps), when at most `near`; or null.
 */
export function pick(x, y, boxes, near) {
  let best = null;
  for (const b of boxes) {
    if (contains(b, x, y) && (best === null || b[2] * b[3] < best[2] * best[3])) best = b;
  }
  if (best !== null) return best;
  let bestGap = near;
  for (const b of boxes) {
    const g = gap(b, x, y);
    if (g <= bestGap && (best === null || g < bestGap)) {
      best = b;
      bestGap = g;
    }
  }
  return best;
}

/**
 * The boxes the operator sees and may click: a snapshot's `boxes`, then those of the last full
 * scan's `candidates` that overlap none of them (the others are the same targets, seen earlier).
 */
export function lockable(boxes, candidates) {
  return [...boxes, ...candidates.filter((c) => boxes.every((b) => overlap(c, b) === 0))];
}

/**
 * Where a click near no box is searched at full resolution: a square `share` of the `width` ×
 * `height` frame's shorter side centred on (x, y), moved inside the frame, as [x, y, w, h]; null
 * for a click outside the frame.
 */
export function clickWindow(x, y, width, height, share) {
  if (!(x >= 0 && x <= width && y >= 0 && y <= height)) return null;
  const side = Math.floor(share * Math.min(width, height));
  const x0 = Math.min(Math.max(0, Math.floor(x - side / 2)), width - side);
  const y0 = Math.min(Math.max(0, Math.floor(y - side / 2)), height - side);
  return [x0, y0, side, side];
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
function similar(box, locked, maxScale) {
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
   * @param {{searchAfterS: number, releaseAfterS: number, maxScale: number, reach: number,
   *   near: number, clickSearch: number}} rule
   */
  constructor(rule) {
    this.rule = rule;
    this.box = null; // the locked target's box when last seen
    this.seenAt = 0;
    this.state = 'none';
    this.epoch = 0; // bumped by every lock and release
    this.fine = false; // found by a full-resolution search: followed at full resolution
  }

  /**
   * A click at (x, y) on a snapshot that found `boxes`: lock the box clicked (or near the
   * click), or release when there is none. A click on the target locked already keeps it
   * followed as it was (at full resolution or not).
   */
  lock(x, y, boxes, now) {
    const box = pick(x, y, boxes, this.rule.near);
    if (box === null) {
      this.release();
      return false;
    }
    const same = this.box !== null && overlap(box, this.box) > 0;
    this.hold(box, now, this.fine && same);
    return true;
  }

  /** Lock on `box`, seen at `now`; `fine`: found at full resolution. */
  hold(box, now, fine = false) {
    this.box = box;
    this.seenAt = now;
    this.state = 'locked';
    this.fine = fine;
    this.epoch += 1;
  }

  /** Back to the default choice (the largest box). */
  release() {
    this.box = null;
    this.state = 'none';
    this.fine = false;
    this.epoch += 1;
  }

  /**
   * What the next snapshot follows, {box, anywhere, epoch, fine}, or null for the default
   * choice.
   */
  query(now) {
    if (this.box === null) return null;
    return {
      box: this.box,
      anywhere: now - this.seenAt > this.rule.searchAfterS,
      epoch: this.epoch,
      fine: this.fine,
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

/**
 * A click at (x, y) of a `width` × `height` frame on which the operator saw `boxes` (lockable):
 * lock the box picked there; else, when the operation can (`search` not null), search the
 * click's window (clickWindow) at full resolution, `search(window) -> boxes`, and lock the box
 * picked among what it finds (a fine lock); else release. Returns how it locked, 'picked' or
 * 'searched', or null when it released. The Python twin is lock.py's lock_at.
 */
export function lockAt(target, x, y, boxes, search, width, height, now) {
  if (target.lock(x, y, boxes, now)) return 'picked';
  const window = clickWindow(x, y, width, height, target.rule.clickSearch);
  if (search === null || window === null) return null;
  const found = pick(x, y, search(window), target.rule.near);
  if (found === null) return null;
  target.hold(found, now, true);
  return 'searched';
}
