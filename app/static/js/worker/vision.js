// The relay's image pipeline: OpenCV.js and every operation of the spec, in a Web Worker.
// The relay page and the parity page both use it, so parity checks the code path live frames
// take. Interface: docs/contracts.md, "The analyzer".

import { PROTOCOL } from '../config.js';

// The worker has no page config: what it needs of the protocol rides in its URL, and so does
// the OpenCV.js build to load: the page's `?opencv=simd|official`, else the relay's
// (`PROTOCOL.opencvBuild`), so that the parity page runs what the relay runs.
const WORKER_URL = `/static/js/worker/vision-worker.js?${new URLSearchParams({
  protocol: JSON.stringify({
    frameTag: PROTOCOL.frameTag,
    defaultProfile: PROTOCOL.defaultProfile,
    lock: PROTOCOL.lock,
  }),
  opencv:
    new URLSearchParams(globalThis.location?.search ?? '').get('opencv') ?? PROTOCOL.opencvBuild,
})}`;

/**
 * Start the worker and wait until OpenCV.js, the cascades and every operation module are loaded.
 * Resolves to {ops, defaultOp, build, analyze(source, opId, options), lockAt(x, y, at), unlock(),
 * resetTracking(), memory(), close()}.
 */
export async function createAnalyzer() {
  const worker = new Worker(WORKER_URL);
  const pending = new Map();
  let nextId = 1;
  let closed = false;

  const ready = await new Promise((resolve, reject) => {
    worker.onerror = (event) => reject(new Error(`vision worker failed: ${event.message}`));
    worker.onmessage = ({ data }) => {
      if (data.type === 'ready') resolve(data);
      else reject(new Error(`vision worker failed to start: ${data.error}`));
    };
  }).catch((error) => {
    worker.terminate();
    throw error;
  });

  worker.onmessage = ({ data }) => {
    const request = pending.get(data.id);
    if (!request) return;
    pending.delete(data.id);
    if (data.type === 'result') request.resolve(data.result);
    else request.reject(new Error(data.error));
  };
  worker.onerror = (event) => {
    const error = new Error(`vision worker crashed: ${event.message}`);
    for (const request of pending.values()) request.reject(error);
    pending.clear();
  };

  function call(message, transfer = []) {
    if (closed) return Promise.reject(new Error('analyzer is closed'));
    const id = nextId;
    nextId += 1;
    return new Promise((resolve, reject) => {
      pending.set(id, { resolve, reject });
      worker.postMessage({ ...message, id }, transfer);
    });
  }

  return {
    /** [{id, label, description}] in spec order. */
    ops: ready.ops,
    /** The spec's default operation id. */
    defaultOp: ready.defaultOp,
    /** The OpenCV.js build the worker loaded: 'simd' or 'official'. */
    build: ready.build,

    /**
     * Run operation `opId` on one frame. `source`: ImageBitmap or VideoFrame (transferred, so
     * the caller must not use it afterwards), or {width, height, data: Uint8ClampedArray RGBA}.
     * Options (each off by default): profile (one of PROTOCOL.profiles.relay, the protocol's
     * default profile by default); returnPixels adds `rgba` (the pixels
     * analysed: of a BT.601 VideoFrame searched in a window, only the parts read hold this
     * frame, the rest an earlier one); track: detect, then track (window.js) across the calls
     * that set it, per operation and profile; around: a full-frame box [x, y, w, h] whose
     * window alone is searched (parity); at: the snapshot's time in seconds, for the relay's
     * snapshots, which follow the worker's target lock (lock.js) instead of the largest box;
     * robotSearching: the vehicle says it is searching for the lost target (lock.js
     * robotSearching), and the lock holds until its search ends.
     * Resolves to {op, boxes, target, targetBox: the target's box [x, y, w, h] or null,
     * targetHeightM: the real height the operation declares for it, w, h, ms, workMs, frame,
     * scan: 'full' | 'window', region:
     * the window searched in detection-image pixels or null, locked: the locked target's box on
     * this snapshot or null, lock: with `at`, the lock after this snapshot {state, box, changed:
     * the new state or null, reason} (else null), converted: how many of the frame's pixels
     * were converted into RGBA (fewer than all for a windowed search of a BT.601
     * VideoFrame)[, rgba]}.
     */
    analyze(source, opId, options = {}) {
      const transfer = source.data ? [] : [source];
      // The worker applies the options' defaults (vision-worker.js `analyze`).
      return call({ ...options, type: 'analyze', source, opId }, transfer);
    },

    /**
     * A click at frame pixel (x, y) at time `at` (s, the snapshots' clock): lock on the target
     * whose box on the last snapshot (or else the last full scan) contains it, or release the
     * lock when it hit none. Resolves to {locked, state, box, reason}.
     */
    lockAt(x, y, at) {
      return call({ type: 'lock', x, y, at });
    },

    /** Release the target lock, if there is one. Resolves to {released, state, box}. */
    unlock() {
      return call({ type: 'unlock' });
    },

    /** Forget every tracked target: the next tracked snapshot scans the whole frame. */
    resetTracking() {
      return call({ type: 'reset' });
    },

    /** {wasmHeapBytes}: size of the OpenCV WASM heap, for leak checks and benchmarks. */
    memory() {
      return call({ type: 'memory' });
    },

    /** Free every OpenCV object and stop the worker. */
    close() {
      if (closed) return;
      closed = true;
      worker.postMessage({ type: 'close' });
      const error = new Error('analyzer is closed');
      for (const request of pending.values()) request.reject(error);
      pending.clear();
    },
  };
}
