// Fire tracking: an entirely different philosophy, no cascade. Flame colours are segmented in
// HSV, cleaned with morphology, and the largest region wins; the target is its centroid.
//
// The steps match app/vision/reference.py (_detect_colour) call for call: RGBA -> RGB, reduce to
// detectWidth with INTER_AREA, RGB -> HSV, OR of inRange masks, open then close with an
// elliptic kernel, connectedComponentsWithStats (8-connected), region scaled back.
import { reduce, scaleBox } from './haar.js';

export function create(cv, spec) {
  const p = spec.params;
  const rgb = new cv.Mat();
  const small = new cv.Mat();
  const hsv = new cv.Mat();
  const mask = new cv.Mat();
  const part = new cv.Mat();
  const labels = new cv.Mat();
  const stats = new cv.Mat();
  const centroids = new cv.Mat();
  const kernel = cv.getStructuringElement(cv.MORPH_ELLIPSE, new cv.Size(p.kernel, p.kernel));
  // inRange bounds as 3x1 CV_64F Mats, OpenCV's shape for a per-channel scalar. (A 1x1
  // three-channel Mat would be read as one value repeated on every channel.)
  const scalar = (values) => cv.matFromArray(3, 1, cv.CV_64F, values);
  const bounds = p.hsvRanges.map((r) => [scalar(r.lower), scalar(r.upper)]);
  const anchor = new cv.Point(-1, -1);

  function morph(op, iterations) {
    if (iterations === 0) return;
    cv.morphologyEx(
      mask,
      mask,
      op,
      kernel,
      anchor,
      iterations,
      cv.BORDER_CONSTANT,
      cv.morphologyDefaultBorderValue(),
    );
  }

  return {
    detect(rgba) {
      cv.cvtColor(rgba, rgb, cv.COLOR_RGBA2RGB);
      const { input, factor } = reduce(cv, rgb, small, p.detectWidth);
      cv.cvtColor(input, hsv, cv.COLOR_RGB2HSV);
      bounds.forEach(([lower, upper], i) => {
        if (i === 0) {
          cv.inRange(hsv, lower, upper, mask);
        } else {
          cv.inRange(hsv, lower, upper, part);
          cv.bitwise_or(mask, part, mask);
        }
      });
      morph(cv.MORPH_OPEN, p.openIterations);
      morph(cv.MORPH_CLOSE, p.closeIterations);
      const count = cv.connectedComponentsWithStats(mask, labels, stats, centroids, 8, cv.CV_32S);
      // Label 0 is the background; a strict '>' keeps the first of equal areas, like argmax.
      let best = 0;
      for (let label = 1; label < count; label += 1) {
        const area = stats.intAt(label, cv.CC_STAT_AREA);
        if (best === 0 || area > stats.intAt(best, cv.CC_STAT_AREA)) best = label;
      }
      if (best === 0 || stats.intAt(best, cv.CC_STAT_AREA) < p.minArea) {
        return { boxes: [], target: null, targetBox: null };
      }
      const box = scaleBox(
        [0, 1, 2, 3].map((c) => stats.intAt(best, c)),
        factor,
      );
      return {
        boxes: [box],
        targetBox: box,
        target: {
          x: centroids.doubleAt(best, 0) * factor,
          y: centroids.doubleAt(best, 1) * factor,
        },
      };
    },
    delete() {
      for (const m of [rgb, small, hsv, mask, part, labels, stats, centroids, kernel]) m.delete();
      for (const [lower, upper] of bounds) {
        lower.delete();
        upper.delete();
      }
    },
  };
}
