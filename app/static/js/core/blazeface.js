// BlazeFace decoding: anchors, scores, boxes and keypoints back to frame pixels, and NMS.
//
// The twin of app/vision/blazeface.py (its docstring says what each step does and why), both
// checked on the sequences of tests/vision/blazeface_sequences.py (tests/vision/test_blazeface.py,
// e2e/test_blazeface_js.py). Pure: no OpenCV, no I/O. Rounding is written out (floor of x + 0.5)
// so both compute the same integers from the same doubles.

/** Numbers per anchor in the regressors output: box (dx, dy, w, h), then 6 keypoints (x, y). */
const COORDS = 16;
const KEYPOINTS = 6;

const round = (v) => Math.floor(v + 0.5);

/**
 * Anchor centres [x, y] in input pixels, in the model's output order, for `layers`
 * [{stride, perCell}] over a square input `inputSize` wide.
 */
export function anchors(inputSize, layers) {
  const centres = [];
  for (const { stride, perCell } of layers) {
    const cells = Math.ceil(inputSize / stride);
    for (let row = 0; row < cells; row += 1) {
      for (let col = 0; col < cells; col += 1) {
        const centre = [(col + 0.5) * stride, (row + 0.5) * stride];
        for (let k = 0; k < perCell; k += 1) centres.push(centre);
      }
    }
  }
  return centres;
}

/** How the part `region` [x, y, w, h] of the frame fits the square input: {region, scale,
 * width, height} (the scaled part, top-left, the rest padding). */
export function letterbox(region, inputSize) {
  const [, , w, h] = region;
  const scale = inputSize / Math.max(w, h);
  return {
    region,
    scale,
    width: Math.max(1, round(w * scale)),
    height: Math.max(1, round(h * scale)),
  };
}

/** Tile origins along one axis (blazeface.py _starts). */
function starts(length, side, overlap) {
  if (length <= side) return [0];
  const step = side * (1.0 - overlap);
  const count = 1 + Math.ceil((length - side) / step);
  return Array.from({ length: count }, (_, i) => round((i * (length - side)) / (count - 1)));
}

/** The parts [x, y, w, h] of a width×height frame a full scan searches: the whole frame, then
 * square tiles `tile` of the frame's width wide (0: none) overlapping by `overlap` of a tile. */
export function passes(width, height, tile, overlap) {
  const parts = [[0, 0, width, height]];
  const wanted = round(tile * width);
  if (wanted <= 0 || (width <= wanted && height <= wanted)) return parts;
  const side = Math.min(wanted, width, height);
  const xs = starts(width, side, overlap);
  for (const y of starts(height, side, overlap)) {
    for (const x of xs) parts.push([x, y, side, side]);
  }
  return parts;
}

/** The square part of the frame searched around the last target `box` (blazeface.py around),
 * or null when empty. */
export function around(box, margin, width, height) {
  const [x, y, w, h] = box;
  const side = Math.ceil(Math.max(w, h) * (1.0 + 2.0 * margin));
  const sw = Math.min(side, width);
  const sh = Math.min(side, height);
  const x0 = Math.min(Math.max(0, Math.floor(x + w / 2 - sw / 2)), width - sw);
  const y0 = Math.min(Math.max(0, Math.floor(y + h / 2 - sh / 2)), height - sh);
  if (sw <= 0 || sh <= 0) return null;
  return [x0, y0, sw, sh];
}

/** The score of a logit, clipped to ±100 as MediaPipe clips it. */
function sigmoid(logit) {
  const clipped = Math.min(100.0, Math.max(-100.0, logit));
  return 1.0 / (1.0 + Math.exp(-clipped));
}

/** An input-pixel point back in frame pixels. */
function toPoint(fit, x, y) {
  return [fit.region[0] + x / fit.scale, fit.region[1] + y / fit.scale];
}

/** An input-pixel box back in frame pixels, rounded. */
function toFrame(fit, x, y, w, h) {
  const [fx, fy] = toPoint(fit, x, y);
  return [round(fx), round(fy), round(w / fit.scale), round(h / fit.scale)];
}

/**
 * The faces {box, score, keypoints} of one forward pass: `scores` (a logit per anchor) and
 * `raw` (COORDS per anchor, flat), decoded against `centres`, kept from `threshold`, mapped
 * back to frame pixels through `fit`.
 */
export function decode(scores, raw, centres, fit, threshold) {
  const faces = [];
  for (let i = 0; i < centres.length; i += 1) {
    const score = sigmoid(scores[i]);
    if (score < threshold) continue;
    const [ax, ay] = centres[i];
    const o = i * COORDS;
    const [cx, cy, w, h] = [ax + raw[o], ay + raw[o + 1], raw[o + 2], raw[o + 3]];
    const box = toFrame(fit, cx - w / 2, cy - h / 2, w, h);
    const keypoints = [];
    for (let k = 0; k < KEYPOINTS; k += 1) {
      keypoints.push(toPoint(fit, ax + raw[o + 4 + 2 * k], ay + raw[o + 5 + 2 * k]));
    }
    faces.push({ box, score, keypoints });
  }
  return faces;
}

/** Intersection over union of two boxes (0 when either is empty). */
function iou(a, b) {
  const ix = Math.max(0, Math.min(a[0] + a[2], b[0] + b[2]) - Math.max(a[0], b[0]));
  const iy = Math.max(0, Math.min(a[1] + a[3], b[1] + b[3]) - Math.max(a[1], b[1]));
  const inter = ix * iy;
  const union = a[2] * a[3] + b[2] * b[3] - inter;
  return union > 0 ? inter / union : 0.0;
}

/** Greedy NMS (blazeface.py suppress): faces at least `minSize` tall, best score first (the
 * earlier of equal scores), each dropped when it overlaps a kept one by more than `overlap`. */
export function suppress(faces, overlap, minSize) {
  const order = faces
    .map((face, i) => i)
    .filter((i) => faces[i].box[3] >= minSize)
    .sort((i, j) => faces[j].score - faces[i].score || i - j);
  const kept = [];
  for (const i of order) {
    if (kept.every((k) => iou(faces[i].box, k.box) <= overlap)) kept.push(faces[i]);
  }
  return kept;
}
