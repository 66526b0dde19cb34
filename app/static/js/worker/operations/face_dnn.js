// Faces through OpenCV's DNN module: BlazeFace (the vendored TFLite model the worker wrote into
// the Emscripten FS), run on the whole frame and on tiles at the model's scale, decoded by
// core/blazeface.js. The target is the centre of the largest face.
//
// The steps match app/vision/reference.py (_detect_dnn) call for call: RGBA -> RGB, each part of
// the frame resized into the square input's top-left corner (INTER_AREA down, INTER_LINEAR up),
// the rest black, blobFromImage to [-1, 1], one forward pass, decoded, then NMS over all passes.
import { anchors, around, decode, letterbox, passes, suppress } from '../../core/blazeface.js';
import { centreOf, largestBox } from './haar.js';

// The model's outputs: one score logit per anchor, then COORDS numbers per anchor.
const OUTPUTS = ['classificators', 'regressors'];

export function create(cv, spec, files) {
  const p = spec.params;
  if (!files.includes(p.model)) throw new Error(`model ${p.model} was not loaded`);
  const net = cv.readNet(p.model);
  const centres = anchors(p.inputSize, p.anchors);
  const rgb = new cv.Mat();
  const part = new cv.Mat();
  const input = new cv.Mat();
  const black = new cv.Scalar(0, 0, 0, 0);
  const mean = new cv.Scalar(127.5, 127.5, 127.5);
  const size = new cv.Size(p.inputSize, p.inputSize);

  /** The faces of one forward pass over the part `region` [x, y, w, h] of the RGB frame. */
  function forward(region) {
    const fit = letterbox(region, p.inputSize);
    const [x, y, w, h] = region;
    const view = rgb.roi(new cv.Rect(x, y, w, h));
    const interpolation = fit.scale < 1 ? cv.INTER_AREA : cv.INTER_LINEAR;
    let blob = null;
    const outputs = [];
    try {
      cv.resize(view, part, new cv.Size(fit.width, fit.height), 0, 0, interpolation);
      const [bottom, right] = [p.inputSize - fit.height, p.inputSize - fit.width];
      cv.copyMakeBorder(part, input, 0, bottom, 0, right, cv.BORDER_CONSTANT, black);
      blob = cv.blobFromImage(input, 1.0 / 127.5, size, mean, false, false);
      net.setInput(blob);
      for (const name of OUTPUTS) outputs.push(net.forward(name));
      const [scores, raw] = outputs;
      return decode(scores.data32F, raw.data32F, centres, fit, p.scoreThreshold);
    } finally {
      view.delete();
      blob?.delete();
      for (const m of outputs) m.delete();
    }
  }

  /** Every part's faces, suppressed together; boxes sorted as Python sorts tuples. */
  function detectParts(rgba, parts, region) {
    cv.cvtColor(rgba, rgb, cv.COLOR_RGBA2RGB);
    const faces = suppress(parts.flatMap(forward), p.nmsThreshold, p.minBoxSize);
    faces.sort(
      (a, b) =>
        a.box[0] - b.box[0] || a.box[1] - b.box[1] || a.box[2] - b.box[2] || a.box[3] - b.box[3],
    );
    const boxes = faces.map((face) => face.box);
    const largest = largestBox(boxes);
    return {
      boxes,
      scores: faces.map((face) => face.score),
      target: centreOf(largest),
      targetBox: largest,
      region,
    };
  }

  return {
    /**
     * Boxes [x, y, w, h] in full-frame pixels, sorted, their scores, the target point and its
     * box (the largest) or null, and the part searched or null. `around`: a full-frame box whose
     * square surroundings alone are searched (one pass), or null for a full scan.
     */
    detect(rgba, around_ = null) {
      if (around_ === null) {
        return detectParts(rgba, passes(rgba.cols, rgba.rows, p.tileFraction, p.tileOverlap), null);
      }
      const region = around(around_, p.windowMargin, rgba.cols, rgba.rows);
      if (region === null) return { boxes: [], scores: [], target: null, targetBox: null, region };
      return detectParts(rgba, [region], region);
    },
    /** Search `region` [x, y, w, h] of the frame as a full scan searches a frame (a click near no
     * box, lock.js clickWindow). */
    searchIn(rgba, region) {
      const [x, y, w, h] = region;
      const parts = passes(w, h, p.tileFraction, p.tileOverlap).map(([px, py, pw, ph]) => [
        px + x,
        py + y,
        pw,
        ph,
      ]);
      return detectParts(rgba, parts, region);
    },
    delete() {
      net.delete();
      for (const m of [rgb, part, input]) m.delete();
    },
  };
}
