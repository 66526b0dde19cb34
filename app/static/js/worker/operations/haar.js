// Shared Haar-cascade pipeline for the cascade operations (face.js, body.js).
//
// The steps match app/vision/reference.py (_detect_cascade) call for call, so Python OpenCV on the
// same RGBA pixels finds the same rectangles: RGBA -> gray, reduce to detectWidth with
// INTER_AREA, detectMultiScale per cascade, boxes scaled back to full-frame pixels. Given a box
// to search around (detect, then track: ../window.js), only that window of the detection image
// is searched, for sizes near the box's own, and its boxes are moved back by the window's origin
// before scaling; where the reduction's grid allows it, only the window's part of the frame is
// converted and reduced (the same pixels for a fraction of the work: sourceRect).
import { searchRegion, searchSizes, sourceRect } from '../../core/tracking-window.js';

/** Size of the detection image, or null when the frame is used as it is (see _reduction). */
function reduction(width, height, detectWidth) {
  if (detectWidth == null || width <= detectWidth) return null;
  return { width: detectWidth, height: Math.floor((height * detectWidth) / width + 0.5) };
}

/** What scales detection-image coordinates back to a frame `width` wide (see _factor). */
function factorOf(width, size) {
  return size === null ? 1 : width / size.width;
}

/**
 * Reduce `src` into `dst` (INTER_AREA) when it is wider than `detectWidth`: the detection image
 * and the factor that scales its coordinates back to the full frame.
 */
export function reduce(cv, src, dst, detectWidth) {
  const size = reduction(src.cols, src.rows, detectWidth);
  if (size === null) return { input: src, factor: 1 };
  cv.resize(src, dst, new cv.Size(size.width, size.height), 0, 0, cv.INTER_AREA);
  return { input: dst, factor: factorOf(src.cols, size) };
}

/** Scale a detection-image box back to the full frame, rounding halves up as Python does. */
export function scaleBox([x, y, w, h], factor) {
  const r = (v) => Math.floor(v * factor + 0.5);
  return [r(x), r(y), r(w), r(h)];
}

/** Boxes in the order Python's list.sort() gives tuples. */
function sortBoxes(boxes) {
  return boxes.sort((a, b) => a[0] - b[0] || a[1] - b[1] || a[2] - b[2] || a[3] - b[3]);
}

/** The largest box (first of equal areas), or null. */
export function largestBox(boxes) {
  let best = null;
  for (const b of boxes) if (best === null || b[2] * b[3] > best[2] * best[3]) best = b;
  return best;
}

/** The centre {x, y} of box [x, y, w, h], or null for none. */
export function centreOf(box) {
  return box === null ? null : { x: box[0] + box[2] / 2, y: box[1] + box[3] / 2 };
}

/**
 * An operation over every cascade of `spec.params`: the union of their boxes, and the centre of
 * the largest box as the target. Mats are reused across frames and freed by delete().
 */
export function createCascadeOperation(cv, spec, files) {
  const p = spec.params;
  const classifiers = p.cascades.map((name) => {
    if (!files.includes(name)) throw new Error(`cascade ${name} was not loaded`);
    const c = new cv.CascadeClassifier();
    if (!c.load(name)) {
      c.delete();
      throw new Error(`cascade ${name} failed to load`);
    }
    return c;
  });
  const gray = new cv.Mat();
  const small = new cv.Mat();
  const found = new cv.RectVector();
  const minSize = new cv.Size(p.minSize[0], p.minSize[1]);
  const maxSize = new cv.Size(p.maxSize[0], p.maxSize[1]);

  /**
   * How a search around the full-frame box `around` goes on a width×height frame: the detection
   * image's size (null: the frame as it is, always with `fullResolution`) and its factor, the
   * window in detection-image pixels (null: nothing to search), the parts window.js sourceRect
   * reduces alone (null: the grid does not allow it), and `reads`, the part of the frame the
   * search reads (null: all of it).
   */
  function windowPlan(width, height, around, fullResolution) {
    const size = fullResolution ? null : reduction(width, height, p.detectWidth);
    const factor = factorOf(width, size);
    const reduced = size ?? { width, height };
    const region = searchRegion(around, factor, reduced.width, reduced.height, p.windowMargin);
    const rects = region === null || size === null ? null : sourceRect(region, width, height, size);
    let reads = null;
    if (region === null) reads = { x: 0, y: 0, width: 0, height: 0 };
    else if (size === null) reads = region;
    else if (rects !== null) reads = rects.source;
    return { size, factor, region, rects, reads };
  }

  /**
   * The detection image's pixels inside the plan's window, as a new Mat header to delete:
   * converted and reduced from the window's own part of the frame where the reduction's grid
   * allows it (window.js sourceRect), else cropped from the whole frame's detection image.
   */
  function windowImage(rgba, { region, size, rects }) {
    const { x, y, width, height } = region;
    if (size === null) {
      grayOf(rgba, region);
      return gray.roi({ x: 0, y: 0, width, height });
    }
    if (rects === null) {
      cv.cvtColor(rgba, gray, cv.COLOR_RGBA2GRAY);
      cv.resize(gray, small, new cv.Size(size.width, size.height), 0, 0, cv.INTER_AREA);
      return small.roi(region);
    }
    const { reduced, source } = rects;
    grayOf(rgba, source);
    cv.resize(gray, small, new cv.Size(reduced.width, reduced.height), 0, 0, cv.INTER_AREA);
    return small.roi({ x: x - reduced.x, y: y - reduced.y, width, height });
  }

  /** `rect` of the RGBA frame, grey, into `gray`. */
  function grayOf(rgba, rect) {
    const view = rgba.roi(rect);
    try {
      cv.cvtColor(view, gray, cv.COLOR_RGBA2GRAY);
    } finally {
      view.delete();
    }
  }

  /**
   * Every cascade's boxes in `searched` (an image whose pixel (0, 0) is detection-image pixel
   * (ox, oy)), scaled to full-frame pixels by `factor`, sorted.
   */
  function cascades(searched, ox, oy, factor, sizeMin, sizeMax) {
    const boxes = [];
    for (const c of classifiers) {
      c.detectMultiScale(searched, found, p.scaleFactor, p.minNeighbors, 0, sizeMin, sizeMax);
      for (let i = 0; i < found.size(); i += 1) {
        const r = found.get(i);
        boxes.push(scaleBox([r.x + ox, r.y + oy, r.width, r.height], factor));
      }
    }
    return sortBoxes(boxes);
  }

  return {
    /**
     * Boxes [x, y, w, h] in full-frame pixels, sorted, the target point and its box (the
     * largest) or null, and the window searched (detection-image pixels) or null. `around`: a
     * full-frame box whose window alone is searched, or null for the whole frame;
     * `fullResolution`: that window of the frame as it is, not of the reduced detection image (a
     * target locked at full resolution, lock.js).
     */
    detect(rgba, around = null, { fullResolution = false } = {}) {
      let region = null;
      let searched;
      let factor;
      let [sizeMin, sizeMax] = [minSize, maxSize];
      if (around === null) {
        cv.cvtColor(rgba, gray, cv.COLOR_RGBA2GRAY);
        ({ input: searched, factor } = reduce(cv, gray, small, p.detectWidth));
      } else {
        const plan = windowPlan(rgba.cols, rgba.rows, around, fullResolution);
        ({ factor, region } = plan);
        if (region === null) return { boxes: [], target: null, targetBox: null, region };
        const sizes = searchSizes(around, factor, p.windowSizeRatio, p.minSize, p.maxSize);
        sizeMin = new cv.Size(...sizes.min);
        sizeMax = new cv.Size(...sizes.max);
        searched = windowImage(rgba, plan);
      }
      let boxes;
      try {
        boxes = cascades(searched, region?.x ?? 0, region?.y ?? 0, factor, sizeMin, sizeMax);
      } finally {
        if (region !== null) searched.delete();
      }
      const searchedBox = region && [region.x, region.y, region.width, region.height];
      const largest = largestBox(boxes);
      return { boxes, target: centreOf(largest), targetBox: largest, region: searchedBox };
    },
    /**
     * Search `region` ([x, y, w, h], full-frame pixels) at full resolution, for objects of every
     * size the operation looks for: where a click near no box looks (lock.js clickWindow). The
     * same boxes as app/vision/reference.py's search on the same pixels.
     */
    searchIn(rgba, region) {
      const [x, y, width, height] = region;
      grayOf(rgba, { x, y, width, height });
      const boxes = cascades(gray, x, y, 1, minSize, maxSize);
      const largest = largestBox(boxes);
      return { boxes, target: centreOf(largest), targetBox: largest, region };
    },
    /**
     * The part {x, y, width, height} of a width×height frame that detect(frame, around,
     * {fullResolution}) reads, or null for all of it: the worker converts no more of a frame
     * than that (vision-worker.js).
     */
    reads(width, height, around = null, { fullResolution = false } = {}) {
      return around === null ? null : windowPlan(width, height, around, fullResolution).reads;
    },
    delete() {
      for (const c of classifiers) c.delete();
      gray.delete();
      small.delete();
      found.delete();
    },
  };
}
