// The parity harness page, driven by `autopilot parity` through window.runImage.
import { createAnalyzer } from './vision.js';

const state = document.getElementById('state');

/** Base64 of a byte array, in chunks small enough for String.fromCharCode. */
function toBase64(bytes) {
  let text = '';
  for (let i = 0; i < bytes.length; i += 0x8000) {
    text += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  }
  return btoa(text);
}

/**
 * Decode an image (base64 file bytes) in the browser and run each op on it. Returns
 * {width, height, rgba: base64 of the pixels analysed, results: {opId: {boxes, target}}},
 * or {unreadable: reason} when the browser cannot decode the bytes.
 */
async function runImage(base64, opIds, profile) {
  const blob = await (await fetch(`data:application/octet-stream;base64,${base64}`)).blob();
  const decode = () => createImageBitmap(blob, { colorSpaceConversion: 'none' });
  try {
    (await decode()).close();
  } catch (error) {
    return { unreadable: error.message };
  }
  const results = {};
  let pixels = null;
  for (const opId of opIds) {
    const result = await window.analyzer.analyze(await decode(), opId, {
      profile,
      returnPixels: pixels === null,
    });
    if (pixels === null) pixels = { width: result.w, height: result.h, rgba: result.rgba };
    results[opId] = { boxes: result.boxes, target: result.target };
  }
  return { width: pixels.width, height: pixels.height, rgba: toBase64(pixels.rgba), results };
}

createAnalyzer().then(
  (analyzer) => {
    window.analyzer = analyzer;
    window.runImage = runImage;
    state.textContent = `ready: ${analyzer.ops.map((op) => op.id).join(', ')}`;
    document.body.dataset.ready = 'true';
  },
  (error) => {
    state.textContent = `failed: ${error.message}`;
    document.body.dataset.ready = 'failed';
  },
);
