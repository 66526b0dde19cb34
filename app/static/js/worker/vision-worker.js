// The relay's image pipeline, off the main thread. A classic worker, because opencv.js is a UMD
// script (importScripts), while operation modules are ES modules loaded with import().
//
// Protocol (vision.js is the only other side):
//   worker -> page  {type: 'ready', ops, defaultOp, build: 'simd'|'official'}
//                   | {type: 'failed', error}
//   page -> worker  {type: 'analyze', id, source, opId, profile, returnPixels, track, around, at,
//                    robotSearching}
//                   | {type: 'lock', id, x, y, at} | {type: 'unlock', id}
//                   | {type: 'memory', id} | {type: 'reset', id}
//   worker -> page  {type: 'result', id, result} | {type: 'error', id, error}
//
// The worker owns the relay's target lock (core/lock.js): each of the relay's snapshots asks it
// what to follow, chooses and updates it in one step, as app/vision/lock.py's rule is applied;
// the page only asks for a lock or a release and hears the lock's state back.
'use strict';

// Two builds of OpenCV.js of the OpenCV pyproject.toml pins: the official one (npm) and ours with
// WebAssembly SIMD (scripts/build-opencv-js). `?opencv=simd|official` chooses (vision.js passes
// the page's choice or the relay's, app/protocol/opencv.py); SIMD only where the browser
// validates a module that uses a v128 instruction (wasm-feature-detect's probe), else official.
const SIMD_PROBE = new Uint8Array([
  0, 97, 115, 109, 1, 0, 0, 0, 1, 5, 1, 96, 0, 1, 123, 3, 2, 1, 0, 10, 10, 1, 8, 0, 65, 0, 253, 15,
  253, 98, 11,
]);
const OPENCV_BUILDS = { simd: '/static/opencv-simd.js', official: '/static/opencv.js' };
const OPENCV_BUILD = (() => {
  const asked = new URLSearchParams(self.location.search).get('opencv');
  if (asked === 'simd' && WebAssembly.validate(SIMD_PROBE)) {
    try {
      importScripts(OPENCV_BUILDS.simd);
      return 'simd';
    } catch (error) {
      // A server without the SIMD file (or a browser refusing it) still gets a working relay.
      console.warn(
        `the SIMD build of OpenCV.js did not load (${error.message}); using the official one`,
      );
    }
  }
  importScripts(OPENCV_BUILDS.official);
  return 'official';
})();

// From app/protocol through vision.js: {frameTag: {blocksPerWidth, markerBlocks, bits},
// defaultProfile, lock: the target lock's rule}.
const PROTOCOL = JSON.parse(new URLSearchParams(self.location.search).get('protocol'));

/** Everything the worker holds, in one place. */
const session = {
  cv: null,
  spec: null,
  modules: new Map(), // module file -> imported ES module
  // `${opId}:${profile}` -> {op: operation instance, windowed: whether it can search a window,
  // tracker: its window.js Tracker for the snapshots analysed with `track`}
  instances: new Map(),
  window: null, // the imported window.js (detect, then track)
  lock: null, // the imported lock.js (target lock)
  target: null, // the relay's TargetLock (lock.js), followed by the snapshots analysed `at` a time
  lastBoxes: [], // the boxes of the last such snapshot, where a click is looked up
  // Between full scans the tracker searches a window around the target, so the last snapshot's
  // boxes may lack the one a person clicks: the last full scan's has it (the candidates).
  lastFullScanBoxes: [],
  lastInstance: null, // the operation instance of the last such snapshot (a click's search)
  frameTag: null, // the imported frame-tag.js (the frame number stamped into its pixels)
  files: [], // cascade and model files written to the Emscripten FS
  canvas: null,
  ctx: null,
  frame: null, // cv.Mat CV_8UC4 reused while the frame size stays the same
  yuv: null, // cv.Mat CV_8UC1 of a VideoFrame's I420 planes as they are (convertsInOpenCv)
  unconverted: false, // whether the frame Mat still waits for parts of `yuv` (ensurePixels)
  converted: 0, // pixels of the current frame converted into the frame Mat so far
  queue: Promise.resolve(), // the message being handled; the next waits for it
};

/**
 * Wait for the OpenCV.js runtime. `self.cv` is a Promise in some builds and an Emscripten
 * module with its own `then` in others; the latter must never be returned from an async
 * function or resolved as a value, or the promise machinery follows its `then` forever.
 */
async function loadOpenCv() {
  if (self.cv instanceof Promise) {
    session.cv = await self.cv;
    return;
  }
  if (!self.cv.Mat) {
    await new Promise((resolve) => {
      self.cv.onRuntimeInitialized = resolve;
    });
  }
  session.cv = self.cv;
}

async function fetchOk(url) {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return response;
}

async function init() {
  await loadOpenCv();
  session.spec = await (await fetchOk('/operations.json')).json();
  const cascades = new Set();
  for (const op of session.spec.operations) {
    for (const params of Object.values(op.paramsByProfile)) {
      for (const name of params.cascades ?? []) cascades.add(name);
    }
  }
  // DNN models (vendored, app/static/vendor): written once per worker, read by cv.readNet.
  const models = new Set();
  for (const op of session.spec.operations) {
    for (const params of Object.values(op.paramsByProfile)) {
      if (params.model) models.add(params.model);
    }
  }
  const urls = [
    ...[...cascades].map((name) => [name, `/cascades/${name}`]),
    ...[...models].map((name) => [name, `/static/vendor/${name}`]),
  ];
  for (const [name, url] of urls) {
    const bytes = new Uint8Array(await (await fetchOk(url)).arrayBuffer());
    session.cv.FS_createDataFile('/', name, bytes, true, false, false);
    session.files.push(name);
  }
  session.window = await import('../core/tracking-window.js');
  session.lock = await import('../core/lock.js');
  session.target = new session.lock.TargetLock(PROTOCOL.lock);
  session.frameTag = await import('../core/frame-tag.js');
  for (const op of session.spec.operations) {
    if (!session.modules.has(op.module)) {
      session.modules.set(op.module, await import(`./operations/${op.module}`));
    }
  }
  // Build every default-profile instance now so a broken module fails at start, not mid-flight.
  for (const op of session.spec.operations) instanceFor(op.id, PROTOCOL.defaultProfile);
  return {
    ops: session.spec.operations.map(({ id, label, description }) => ({ id, label, description })),
    defaultOp: session.spec.default,
    build: OPENCV_BUILD,
  };
}

function instanceFor(opId, profile) {
  const key = `${opId}:${profile}`;
  let instance = session.instances.get(key);
  if (instance) return instance;
  const op = session.spec.operations.find((o) => o.id === opId);
  if (!op) throw new Error(`unknown operation "${opId}"`);
  // The server merged each profile's parameters (app/vision/spec.py); nothing is merged here.
  const params = op.paramsByProfile[profile];
  if (!params) throw new Error(`unknown profile "${profile}"`);
  const spec = { ...op, params };
  // Cascade and DNN operations search a window around the last target between full scans.
  const windowed = op.kind === 'cascade' || op.kind === 'dnn';
  instance = {
    op: session.modules.get(op.module).create(session.cv, spec, session.files),
    // What the operation's box spans, in metres: goals carry it for the onboard law's range.
    targetHeightM: op.targetHeightM,
    windowed,
    tracker: new session.window.Tracker(windowed ? params.fullScanEvery : 1),
  };
  session.instances.set(key, instance);
  return instance;
}

/** The reused RGBA frame Mat, reallocated only when the frame size changes. */
function frameMat(width, height) {
  const { cv } = session;
  if (!session.frame || session.frame.cols !== width || session.frame.rows !== height) {
    session.frame?.delete();
    session.frame = new cv.Mat(height, width, cv.CV_8UC4);
  }
  return session.frame;
}

// The YUV matrices OpenCV's COLOR_YUV2RGBA_I420 implements (BT.601, limited range): a decoded
// frame tagged with one of them converts in OpenCV as Chromium converts it (within a level).
const OPENCV_YUV_MATRICES = ['smpte170m', 'bt470bg'];

/**
 * Whether the frame's I420 planes can be copied as they are and converted by OpenCV, part by
 * part: Chromium's own conversion into RGBA converts the whole frame however little of it an
 * operation reads, while the planes' copy is a fraction of that (docs/bench/relay-cost.md).
 */
function convertsInOpenCv(frame) {
  const { format, colorSpace, visibleRect: r } = frame;
  return (
    format === 'I420' &&
    colorSpace?.fullRange === false &&
    OPENCV_YUV_MATRICES.includes(colorSpace?.matrix) &&
    [r.x, r.y, r.width, r.height].every((v) => v % 2 === 0)
  );
}

/** The reused I420 Mat for a width×height frame: Y, then U, then V, packed as OpenCV wants. */
function yuvMat(width, height) {
  const { cv } = session;
  if (!session.yuv || session.yuv.cols !== width || session.yuv.rows !== (height * 3) / 2) {
    session.yuv?.delete();
    session.yuv = new cv.Mat((height * 3) / 2, width, cv.CV_8UC1);
  }
  return session.yuv;
}

/**
 * Put the source's RGBA pixels into the frame Mat and return it. A VideoFrame of a BT.601
 * I420 video leaves its planes in `session.yuv`, converted later where an operation reads
 * (ensurePixels); another VideoFrame converts itself straight into the Mat's WASM memory (one
 * copy, no canvas); an ImageBitmap is drawn on a canvas and read back; raw RGBA is copied as it
 * is. Frames and bitmaps are closed.
 */
async function readPixels(source) {
  session.unconverted = false;
  const mat = await framePixels(source);
  session.converted = session.unconverted ? 0 : mat.cols * mat.rows;
  return mat;
}

/** readPixels' copy, by the kind of source. */
async function framePixels(source) {
  if (source.data) {
    const mat = frameMat(source.width, source.height);
    mat.data.set(source.data);
    return mat;
  }
  try {
    if (source instanceof VideoFrame) {
      const { width, height } = source.visibleRect;
      const mat = frameMat(width, height);
      if (convertsInOpenCv(source)) {
        const yuv = yuvMat(width, height);
        const luma = width * height;
        const layout = [
          { offset: 0, stride: width },
          { offset: luma, stride: width / 2 },
          { offset: luma + luma / 4, stride: width / 2 },
        ];
        await source.copyTo(yuv.data, { layout });
        session.unconverted = true;
        return mat;
      }
      await source.copyTo(mat.data, { format: 'RGBA', colorSpace: 'srgb' });
      return mat;
    }
    const { width, height } = source;
    if (!session.canvas) {
      session.canvas = new OffscreenCanvas(width, height);
      session.ctx = session.canvas.getContext('2d', { willReadFrequently: true });
    } else if (session.canvas.width !== width || session.canvas.height !== height) {
      session.canvas.width = width;
      session.canvas.height = height;
    }
    session.ctx.drawImage(source, 0, 0, width, height);
    const mat = frameMat(width, height);
    mat.data.set(session.ctx.getImageData(0, 0, width, height).data);
    return mat;
  } finally {
    source.close();
  }
}

/**
 * Make `rect` ({x, y, width, height}; null: all) of the frame Mat hold the current frame's
 * pixels, converting that part of `session.yuv` when the frame came as planes. A part from even
 * coordinates converts exactly as the whole frame does (each 2×2 pixels share their chroma).
 */
function ensurePixels(mat, rect) {
  if (!session.unconverted) return;
  const { cv } = session;
  if (rect === null) {
    cv.cvtColor(session.yuv, mat, cv.COLOR_YUV2RGBA_I420);
    session.unconverted = false;
    session.converted += mat.cols * mat.rows;
    return;
  }
  if (rect.width <= 0 || rect.height <= 0) return;
  const x = rect.x - (rect.x % 2);
  const y = rect.y - (rect.y % 2);
  const w = Math.min(mat.cols, rect.x + rect.width + ((rect.x + rect.width) % 2)) - x;
  const h = Math.min(mat.rows, rect.y + rect.height + ((rect.y + rect.height) % 2)) - y;
  const planes = new cv.Mat((h * 3) / 2, w, cv.CV_8UC1);
  const rgba = new cv.Mat();
  const view = mat.roi(new cv.Rect(x, y, w, h));
  try {
    // The views of WASM memory are taken after the last allocation, which may move it.
    copyPlanesPart(session.yuv.data, mat.cols, mat.rows, planes.data, { x, y, w, h });
    cv.cvtColor(planes, rgba, cv.COLOR_YUV2RGBA_I420);
    rgba.copyTo(view);
    session.converted += w * h;
  } finally {
    planes.delete();
    rgba.delete();
    view.delete();
  }
}

/** Copy the part {x, y, w, h} (even) of a width×height frame's I420 planes, packed, into `dst`. */
function copyPlanesPart(src, width, height, dst, { x, y, w, h }) {
  for (let r = 0; r < h; r += 1) {
    const from = (y + r) * width + x;
    dst.set(src.subarray(from, from + w), r * w);
  }
  const [cw, pw] = [width / 2, w / 2];
  const [uFrom, uTo] = [width * height, w * h];
  const [vFrom, vTo] = [uFrom + cw * (height / 2), uTo + pw * (h / 2)];
  for (let r = 0; r < h / 2; r += 1) {
    const from = (y / 2 + r) * cw + x / 2;
    dst.set(src.subarray(uFrom + from, uFrom + from + pw), uTo + r * pw);
    dst.set(src.subarray(vFrom + from, vFrom + from + pw), vTo + r * pw);
  }
}

/** Words for an error; OpenCV's C++ exceptions reach JS as bare pointers. */
function describe(error) {
  if (typeof error === 'number' && session.cv?.exceptionFromPtr) {
    return `OpenCV: ${session.cv.exceptionFromPtr(error).msg}`;
  }
  return String(error?.message ?? error);
}

/**
 * Run the operation on the frame: with `track`, its tracker picks a window around the last
 * target (chosen by `choose`) or a full scan (window.js step); with `around` (a full-frame box,
 * parity checks), the window around it alone is searched; otherwise the whole frame. A lock
 * found at full resolution (`query.fine`) is searched for in windows of the full-resolution
 * frame, and around where it was last seen when the full scan does not find it (lock.js).
 * Returns {found, scan, fullScan: the boxes of the full scan run, or null}.
 */
function detectIn(instance, frame, track, around, choose, query) {
  const fine = query?.fine === true;
  let fullScan = null;
  const search = (box) => {
    const options = { fullResolution: fine && box !== null };
    // Only what the operation reads of the frame is converted (an operation without `reads`
    // reads it all).
    ensurePixels(frame, instance.op.reads?.(frame.cols, frame.rows, box, options) ?? null);
    const found = instance.op.detect(frame, box, options);
    if (box === null) fullScan = found.boxes;
    return found;
  };
  let outcome;
  if (around != null) {
    if (!instance.windowed) throw new Error('this operation has no windowed search');
    outcome = { found: search(around), scan: 'window' };
  } else if (track) {
    const keep = fine && instance.windowed ? query.box : null;
    outcome = session.window.step(instance.tracker, search, choose, keep);
  } else {
    outcome = { found: search(null), scan: 'full' };
  }
  return { ...outcome, fullScan };
}

async function analyze({
  source,
  opId,
  profile = PROTOCOL.defaultProfile,
  returnPixels = false,
  track = false,
  around = null,
  at = null,
  robotSearching = false,
}) {
  const started = performance.now();
  let instance;
  try {
    instance = instanceFor(opId, profile);
  } catch (error) {
    source.close?.();
    throw error;
  }
  const frame = await readPixels(source);
  const detectStarted = performance.now();
  // From here to the lock's update nothing waits, so no click or release comes in between.
  const query = at === null ? null : session.target.query(at, robotSearching);
  // Locked (lock.js): the target is the centre of the box that continues the locked track, or
  // while the vehicle searches, the box that looks like it.
  // Each box's look once per snapshot (the target is chosen twice: in the window's step and for
  // the goal).
  const looks = new Map();
  const lookOf = (box) => {
    if (!looks.has(box)) looks.set(box, lookIn(frame, box));
    return looks.get(box);
  };
  const choose = session.lock.chooser(query, PROTOCOL.lock, lookOf);
  const { found, scan, fullScan } = detectIn(instance, frame, track, around, choose, query);
  const { boxes, region = null } = found;
  const locked = query === null ? null : choose(boxes);
  // The target's box: the operation's own choice (an operation that names none gives no box).
  let { target, targetBox = null } = found;
  if (query !== null) {
    target =
      locked === null ? null : { x: locked[0] + locked[2] / 2, y: locked[1] + locked[3] / 2 };
    targetBox = locked;
  }
  if (locked !== null && session.target.needsLook(query)) session.target.remember(lookOf(locked));
  const lock =
    at === null ? null : followed(instance, query, locked, boxes, fullScan, at, robotSearching);
  const { cols: width, rows: height } = frame;
  // The tag's blocks are the top row's (frame-tag.js).
  const { decodeFrameTag, tagBlockSize } = session.frameTag;
  ensurePixels(frame, { x: 0, y: 0, width, height: tagBlockSize(PROTOCOL.frameTag, width) });
  const done = performance.now();
  const result = {
    op: opId,
    boxes,
    // Each box's score (0..1) for operations that score them (DNN), else null.
    scores: found.scores ?? null,
    target,
    targetBox,
    targetHeightM: instance.targetHeightM,
    w: width,
    h: height,
    ms: done - detectStarted,
    workMs: done - started,
    frame: decodeFrameTag(PROTOCOL.frameTag, width, height, frame.data),
    converted: session.converted,
    scan,
    region,
    locked,
    lock,
    // The relay's snapshots: the last full scan's boxes, which a click may lock.
    candidates: at === null ? null : session.lastFullScanBoxes,
  };
  if (returnPixels) result.rgba = new Uint8ClampedArray(frame.data);
  return result;
}

/**
 * The look of `box` (full-frame pixels) in the frame Mat: its hue × saturation histogram
 * (`PROTOCOL.lock.lookBins`, OpenCV's 8-bit HSV), normalised to sum 1 (all 0 for no pixels), as
 * app/vision/reference.py's look.
 */
function lookIn(frame, box) {
  const { cv } = session;
  const rect = session.lock.lookRect(box, frame.cols, frame.rows);
  const [hueBins, saturationBins] = PROTOCOL.lock.lookBins;
  if (rect.width === 0 || rect.height === 0) return new Array(hueBins * saturationBins).fill(0);
  ensurePixels(frame, rect);
  const roi = frame.roi(new cv.Rect(rect.x, rect.y, rect.width, rect.height));
  const rgb = new cv.Mat();
  const hsv = new cv.Mat();
  const planes = new cv.MatVector();
  const mask = new cv.Mat();
  const hist = new cv.Mat();
  try {
    cv.cvtColor(roi, rgb, cv.COLOR_RGBA2RGB);
    cv.cvtColor(rgb, hsv, cv.COLOR_RGB2HSV);
    planes.push_back(hsv);
    cv.calcHist(planes, [0, 1], mask, hist, [hueBins, saturationBins], [0, 180, 0, 256]);
    const counts = Array.from(hist.data32F);
    const total = counts.reduce((sum, c) => sum + c, 0);
    return counts.map((c) => c / total);
  } finally {
    roi.delete();
    rgb.delete();
    hsv.delete();
    planes.delete();
    mask.delete();
    hist.delete();
  }
}

/**
 * The relay's snapshot at `at` (s) with `instance` chose `locked` (null: not found) for the
 * lock's `query`: update the lock and keep the boxes a click is looked up in (`fullScan`: the
 * boxes of the full scan it ran, or null); `robotSearching`: the vehicle searches for the target,
 * and the lock holds. Returns {state, box, changed: the new state or null, reason: why it
 * changed, or null}.
 */
function followed(instance, query, locked, boxes, fullScan, at, robotSearching) {
  session.lastInstance = instance;
  session.lastBoxes = boxes;
  if (fullScan !== null) session.lastFullScanBoxes = fullScan;
  const { target } = session;
  const changed = target.update(query, locked, at, robotSearching);
  const reason =
    changed === 'none'
      ? `not seen for more than ${PROTOCOL.lock.releaseAfterS} s, and the robot is not searching`
      : null;
  return { state: target.state, box: target.box, changed, reason };
}

/**
 * A click at (x, y) at time `at` (s): lock on the box at or near it among those the operator
 * saw (the last snapshot's and the last full scan's, lock.js lockable); else search around it
 * at full resolution in the last snapshot's frame and lock what is found there; else release.
 * Returns {locked, state, box, reason}.
 */
function lockAt({ x, y, at }) {
  const { target, lastBoxes, lastFullScanBoxes, lastInstance: instance, frame } = session;
  const boxes = session.lock.lockable(lastBoxes, lastFullScanBoxes);
  const canSearch = instance !== null && frame !== null && instance.op.searchIn !== undefined;
  const search = canSearch
    ? (region) => {
        const [rx, ry, width, height] = region;
        ensurePixels(frame, { x: rx, y: ry, width, height });
        return instance.op.searchIn(frame, region).boxes;
      }
    : null;
  const size = [frame?.cols ?? 0, frame?.rows ?? 0];
  const how = session.lock.lockAt(target, x, y, boxes, search, ...size, at);
  forgetTargets();
  let reason = null;
  if (how === 'searched') reason = 'found by a full-resolution search around the click';
  else if (how === null && canSearch)
    reason = 'nothing found at or near the click, even at full resolution';
  else if (how === null) reason = 'the click was on no detection box and near none';
  return { locked: how !== null, state: target.state, box: target.box, reason };
}

/** Release the lock, if there is one. Returns {released, state, box}. */
function unlock() {
  const { target } = session;
  const released = target.state !== 'none';
  if (released) {
    target.release();
    forgetTargets();
  }
  return { released, state: target.state, box: target.box };
}

/** The trackers' windows may hold another target than the lock's now: scan whole frames. */
function forgetTargets() {
  for (const instance of session.instances.values()) instance.tracker.reset();
}

async function handle(message) {
  switch (message.type) {
    case 'analyze': {
      try {
        const result = await analyze(message);
        const transfer = result.rgba ? [result.rgba.buffer] : [];
        self.postMessage({ type: 'result', id: message.id, result }, transfer);
      } catch (error) {
        self.postMessage({ type: 'error', id: message.id, error: describe(error) });
      }
      break;
    }
    case 'memory':
      self.postMessage({
        type: 'result',
        id: message.id,
        result: { wasmHeapBytes: session.cv.HEAPU8.length },
      });
      break;
    case 'reset':
      forgetTargets();
      self.postMessage({ type: 'result', id: message.id, result: {} });
      break;
    case 'lock':
      self.postMessage({ type: 'result', id: message.id, result: lockAt(message) });
      break;
    case 'unlock':
      self.postMessage({ type: 'result', id: message.id, result: unlock() });
      break;
    case 'close':
      for (const instance of session.instances.values()) instance.op.delete();
      session.instances.clear();
      session.frame?.delete();
      session.frame = null;
      session.yuv?.delete();
      session.yuv = null;
      self.close();
      break;
    default:
      self.postMessage({ type: 'error', id: message.id, error: `unknown message ${message.type}` });
  }
}

// Messages are handled one at a time, in order: an analysis awaits its pixel copy, and the
// next one must not overwrite the shared frame Mat meanwhile. A failure is answered and the
// queue goes on.
self.onmessage = ({ data: message }) => {
  session.queue = session.queue
    .then(() => handle(message))
    .catch((error) => self.postMessage({ type: 'error', id: message.id, error: describe(error) }));
};

init().then(
  (ready) => self.postMessage({ type: 'ready', ...ready }),
  (error) => self.postMessage({ type: 'failed', error: describe(error) }),
);
