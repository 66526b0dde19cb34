// The parity harness page, driven by `autopilot parity` through window.runImage (and by the
// windowed-path tests and the bench through window.runPixels and window.analyzer; the
// analyzer tests also use its window.toBase64 and window.fromBase64).
import { createAnalyzer } from '../worker/vision.js';
import { largest } from '../core/tracking-window.js';

const state = document.getElementById('state');

/**
 * Base64 of a byte array, by the browser's own encoder (a data: URL of a Blob): native code over
 * the whole buffer at once, where btoa needs a string built from the bytes in chunks, which is
 * slow for a full-HD RGBA frame.
 */
function toBase64(bytes) {
  return new Promise((resolve, reject) => {
    const reader = new FileReader();
    reader.onload = () => resolve(reader.result.slice(reader.result.indexOf(',') + 1));
    reader.onerror = () => reject(reader.error);
    reader.readAsDataURL(new Blob([bytes]));
  });
}

/** The bytes of a base64 string (decoded here: the page's CSP allows no fetch of data: URLs). */
function fromBase64(text) {
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i += 1) bytes[i] = binary.charCodeAt(i);
  return bytes;
}

/**
 * SHA-256 of a byte array in hex, or null where the page has no WebCrypto (not a secure
 * context: the harness runs on loopback, which is one).
 */
async function sha256Hex(bytes) {
  if (!window.crypto?.subtle) return null;
  const digest = new Uint8Array(await crypto.subtle.digest('SHA-256', bytes));
  return Array.from(digest, (b) => b.toString(16).padStart(2, '0')).join('');
}

/**
 * Decode an image (base64 file bytes) in the browser and run each op on it; each op of
 * `windowOps` that found something runs again on the window around its largest box (the
 * detect-then-track path). Returns {width, height, rgba, results: {opId: {boxes, scores,
 * target, window?: {around, boxes, scores, target}}}}, or {unreadable: reason} when the
 * browser cannot decode the bytes. `rgba` is the base64 of the pixels analysed, except where
 * `pixelsWanted` says otherwise: 'none' returns none; a SHA-256 in hex (the caller's own
 * decoding of the file) returns none when the analysed pixels have that digest (`sameDigest:
 * true`), so that megabytes of identical pixels need not cross the DevTools protocol.
 */
async function runImage(base64, opIds, profile, windowOps = [], pixelsWanted = 'base64') {
  let decoded;
  try {
    const blob = new Blob([fromBase64(base64)]);
    decoded = await createImageBitmap(blob, { colorSpaceConversion: 'none' });
  } catch (error) {
    return { unreadable: error.message };
  }
  // The analyzer takes each bitmap it is given (transferred): each call gets a copy of the one
  // decoded image, which costs a copy where decoding a large photo again cost tens of ms.
  const copy = () => createImageBitmap(decoded);
  const results = {};
  let pixels = null;
  try {
    for (const opId of opIds) {
      const result = await window.analyzer.analyze(await copy(), opId, {
        profile,
        returnPixels: pixels === null && pixelsWanted !== 'none',
      });
      if (pixels === null) pixels = { width: result.w, height: result.h, rgba: result.rgba };
      results[opId] = { boxes: result.boxes, scores: result.scores, target: result.target };
      const around = largest(result.boxes);
      if (windowOps.includes(opId) && around !== null) {
        const windowed = await window.analyzer.analyze(await copy(), opId, { profile, around });
        results[opId].window = {
          around,
          boxes: windowed.boxes,
          scores: windowed.scores,
          target: windowed.target,
        };
      }
    }
  } finally {
    decoded.close();
  }
  const out = { width: pixels.width, height: pixels.height, results };
  if (pixelsWanted === 'none') return out;
  if (pixelsWanted !== 'base64' && (await sha256Hex(pixels.rgba)) === pixelsWanted) {
    return { ...out, sameDigest: true };
  }
  return { ...out, rgba: await toBase64(pixels.rgba) };
}

/**
 * Run one op on raw RGBA pixels (base64) exactly as given, with the analyzer's options
 * (around: the windowed search; track: detect, then track). Returns the analyzer's result.
 */
async function runPixels(base64, width, height, opId, options) {
  const data = new Uint8ClampedArray(fromBase64(base64).buffer);
  const { boxes, scores, target, scan, region } = await window.analyzer.analyze(
    { width, height, data },
    opId,
    options,
  );
  return { boxes, scores, target, scan, region };
}

createAnalyzer().then(
  (analyzer) => {
    window.analyzer = analyzer;
    window.runImage = runImage;
    window.runPixels = runPixels;
    window.toBase64 = toBase64;
    window.fromBase64 = fromBase64;
    const ops = analyzer.ops.map((op) => op.id).join(', ');
    state.textContent = `ready (OpenCV.js ${analyzer.build}): ${ops}`;
    document.body.dataset.opencv = analyzer.build;
    document.body.dataset.ready = 'true';
  },
  (error) => {
    state.textContent = `failed: ${error.message}`;
    document.body.dataset.ready = 'failed';
  },
);
