// The boxes drawn over the video (the client's and the relay's preview), each with its kind:
// what the autopilot follows, and what else a click may lock (core/lock.js, the rule in
// app/protocol/lock.py). Pure, no DOM: the client exposes the result as window.autopilotView.
import { lockable } from './lock.js';
import { largest } from './tracking-window.js';

/**
 * The boxes a detections message shows, [{x, y, w, h, kind}] in the analysed frame's pixels:
 * 'locked' (the locked target, when this snapshot found it), 'tracked' (the target when nothing
 * is locked: the largest box) and 'candidate' (every other box a click may lock: the snapshot's
 * others, and the last full scan's that overlap none of the snapshot's).
 */
export function shownBoxes(detections) {
  if (!detections) return [];
  const boxes = detections.boxes ?? [];
  const locked = detections.locked ?? null;
  const followed = locked ?? (detections.target ? largest(boxes) : null);
  const shown = lockable(boxes, detections.candidates ?? []);
  if (followed !== null && !shown.some((box) => same(box, followed))) shown.unshift(followed);
  const kind = locked !== null ? 'locked' : 'tracked';
  return shown.map(([x, y, w, h]) => ({
    x,
    y,
    w,
    h,
    kind: followed !== null && same([x, y, w, h], followed) ? kind : 'candidate',
  }));
}

function same(a, b) {
  return a.every((v, i) => v === b[i]);
}
