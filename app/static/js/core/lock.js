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
function contains([bx, by, bw, bh], x, y) {
  return bx <= x && x <= bx + bw && by <= y && y <= by + bh;
}

/**
 * How far pixel (x, y) is from box [x, y, w, h] in the box's own size: the larger of the
 * horizontal gap over its width and the vertical gap over its height (0 inside, edges included).
 */
function gap([bx, by, bw, bh], x, y) {
  const dx = Math.max(bx - x, 0, x - (bx + bw));
  const dy = Math.max(by - y, 0, y - (by + bh));
  return Math.max(dx / bw, dy / bh);
}

/**
 * The box clicked at (x, y): the smallest containing it (first of equal areas); else the box it
 * is nearest to in that box's own size (gap, first of equal gaps), when at most `near`; or null.
 */
function pick(x, y, boxes, near) {
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
function clickWindow(x, y, width, height, share) {
  if (!(x >= 0 && x <= width && y >= 0 && y <= height)) return null;
  const side = Math.floor(share * Math.min(width, height));
  const x0 = Math.min(Math.max(0, Math.floor(x - side / 2)), width - side);
  const y0 = Math.min(Math.max(0, Math.floor(y - side / 2)), height - side);
  return [x0, y0, side, side];
}

/** Intersection over union of two boxes. */
function overlap(a, b) {
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
function associate(locked, boxes, anywhere, rule) {
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
    this.look = null; // the target's look, from the first snapshot that followed it
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
    this.look = null;
    this.epoch += 1;
  }

  /** Back to the default choice (the largest box). */
  release() {
    this.box = null;
    this.state = 'none';
    this.fine = false;
    this.look = null;
    this.epoch += 1;
  }

  /**
   * What the next snapshot follows, {box, anywhere, epoch, fine, look, anySize}, or null for the
   * default choice: once the target's look is known (`look`, else null), by its look (chooser),
   * of any size while the vehicle searches (`searching`).
   */
  query(now, searching = false) {
    if (this.box === null) return null;
    return {
      box: this.box,
      anywhere: now - this.seenAt > this.rule.searchAfterS,
      epoch: this.epoch,
      fine: this.fine,
      look: this.look,
      anySize: searching,
    };
  }

  /** Whether the box the snapshot asked with `query` chose is to give the target's look: the
   * first one after a lock. */
  needsLook(query) {
    return query !== null && query.epoch === this.epoch && this.look === null;
  }

  /** The target's look (needsLook). */
  remember(look) {
    this.look = look;
  }

  /**
   * The outcome of the snapshot asked with `query`: the box chosen or null; the new state, if
   * it changed. `searching`: the vehicle says it is turning to search for the target (its
   * pose's `search`), and the lock holds until that search ends.
   */
  update(query, chosen, now, searching = false) {
    if (query === null || query.epoch !== this.epoch) return null;
    const before = this.state;
    if (chosen !== null) {
      this.box = chosen;
      this.seenAt = now;
      this.state = 'locked';
    } else if (now - this.seenAt > this.rule.releaseAfterS && !searching) {
      this.release();
    } else if (now - this.seenAt > this.rule.searchAfterS) {
      this.state = 'searching';
    } else {
      this.state = 'lost';
    }
    return this.state !== before ? this.state : null;
  }
}

/**
 * Whether a vehicle whose pose says `search` ('left', 'right', 'timed_out'; null or undefined:
 * none) is turning to search for its lost target. lock.py's robot_searching is its twin.
 */
export function robotSearching(search) {
  return search !== null && search !== undefined && search !== 'timed_out';
}

/**
 * The pixels a look is taken from: box [x, y, w, h] grown to whole pixels and clipped to the
 * `width` × `height` frame, as {x, y, width, height} (empty when the box is outside it).
 */
export function lookRect([x, y, w, h], width, height) {
  const x0 = Math.min(Math.max(0, Math.floor(x)), width);
  const y0 = Math.min(Math.max(0, Math.floor(y)), height);
  const x1 = Math.min(Math.max(x0, Math.ceil(x + w)), width);
  const y1 = Math.min(Math.max(y0, Math.ceil(y + h)), height);
  return { x: x0, y: y0, width: x1 - x0, height: y1 - y0 };
}

/** How alike two looks (normalised histograms) are: their Bhattacharyya coefficient. */
function likeness(a, b) {
  if (a.length !== b.length) throw new Error('looks of different sizes');
  let sum = 0;
  for (let i = 0; i < a.length; i += 1) sum += Math.sqrt(a[i] * b[i]);
  return sum;
}

/** The box of any size most like the target (`alike(box)`), when at least `rule.minLikeness`
 * alike; the first of equal likeness. */
function recognise(boxes, alike, rule) {
  let best = null;
  let bestLikeness = rule.minLikeness;
  for (const b of boxes) {
    const value = alike(b);
    if (value >= bestLikeness && (best === null || value > bestLikeness)) {
      best = b;
      bestLikeness = value;
    }
  }
  return best;
}

/**
 * The rule that picks the target among a snapshot's boxes: the locked one's track, or the
 * largest. When the query gives the target's look and `lookOf(box)` each box's, a box of a
 * similar size that overlaps the locked one continues its track (the one overlapping most); else
 * the box that looks most like the target (recognise) among those of a similar size, of any size
 * while the vehicle searches, wherever it is in the frame. The twin of lock.py's chooser.
 */
export function chooser(query, rule, lookOf = null) {
  if (query === null) return largest;
  const { look } = query;
  if (look === null || look === undefined || lookOf === null) {
    return (boxes) => associate(query.box, boxes, query.anywhere, rule);
  }
  const alike = (b) => likeness(lookOf(b), look);
  return (boxes) => {
    const similarBoxes = boxes.filter((b) => similar(b, query.box, rule.maxScale));
    const overlapping = similarBoxes.filter((b) => overlap(b, query.box) > 0);
    if (overlapping.length > 0) return associate(query.box, overlapping, false, rule);
    return recognise(query.anySize ? boxes : similarBoxes, alike, rule);
  };
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
