// Small DOM helpers shared by the role pages: the log, text fields, the overlay.
import { shownBoxes } from '../core/shown-boxes.js';

/** The element with `data-testid=id` (throws if the template lacks it: a bug, not bad input). */
export function byTestId(id) {
  const el = document.querySelector(`[data-testid="${id}"]`);
  if (el === null) throw new Error(`page has no element data-testid=${id}`);
  return el;
}

/** The button with `data-action=action`. */
export function button(action) {
  const el = document.querySelector(`button[data-action="${action}"]`);
  if (el === null) throw new Error(`page has no button data-action=${action}`);
  return el;
}

/**
 * Set the text of a `data-testid` element. Unchanged text is left alone: some fields are fed
 * many times a second (a still turtle's pose at 60 Hz), and each write costs a layout and a
 * repaint even when the text is the same.
 */
export function show(id, text) {
  const el = byTestId(id);
  if (el.textContent !== text) el.textContent = text;
}

const LOG_LIMIT = 300;

/** The page's log area; every line also goes to the console (kept by the e2e tests). */
export class Log {
  constructor(list) {
    this.list = list;
  }

  info(text) {
    this.#add('info', text);
  }

  warn(text) {
    this.#add('warn', text);
  }

  error(text) {
    this.#add('error', text);
  }

  #add(level, text) {
    const stamp = new Date().toISOString().slice(11, 23);
    (level === 'info' ? console.info : level === 'warn' ? console.warn : console.error)(
      `[${stamp}] ${text}`,
    );
    const item = document.createElement('li');
    item.className = level;
    const time = document.createElement('time');
    time.textContent = stamp;
    item.append(time, text);
    this.list.prepend(item);
    while (this.list.childElementCount > LOG_LIMIT) this.list.lastElementChild.remove();
  }
}

/** Format a number of milliseconds or a rate for the figures. */
export function fmt(value, digits = 1) {
  return value == null || Number.isNaN(value) ? '–' : value.toFixed(digits);
}

/**
 * A vehicle's search for a lost target (its pose's `search`: 'left', 'right', 'timed_out' or
 * null), in words, as the vehicle and client pages show it.
 */
export function searchText(search) {
  if (search === null || search === undefined) return 'not searching';
  if (search === 'timed_out') return 'target lost: the search ran out, the robot stopped';
  return `target lost: searching to the ${search}`;
}

// The role pages redraw their figures at most this often: a person reads a few changes a
// second, and every redraw costs a layout, a paint and the compositor.
export const FIGURES_PERIOD_MS = 250;

/**
 * `fn` called at most once every `periodMs`: a call within the period is deferred to its end
 * rather than dropped, so the last state always shows.
 */
export function throttle(periodMs, fn) {
  let shownAt = -Infinity;
  let timer = null;
  const run = () => {
    timer = null;
    shownAt = performance.now();
    fn();
  };
  return () => {
    if (timer !== null) return;
    const wait = shownAt + periodMs - performance.now();
    if (wait <= 0) run();
    else timer = setTimeout(run, wait);
  };
}

// How each kind of box (core/shown-boxes.js) is drawn: what the autopilot follows stands out,
// the other boxes a click may lock are drawn faintly.
const BOX_STYLES = {
  tracked: { colour: '#39ff88', width: 3, dash: [], alpha: 1, label: null },
  locked: { colour: '#ffd23f', width: 5, dash: [], alpha: 1, label: 'locked' },
  candidate: { colour: '#39ff88', width: 1.5, dash: [6, 4], alpha: 0.55, label: null },
};

/**
 * Draw a detections message's boxes, each by its kind (shownBoxes: the tracked or locked target,
 * and the candidates a click may lock), and the target on the canvas laid over a video; returns
 * the boxes drawn. Boxes are in the detection frame's pixels (`w` × `h`); the canvas covers the
 * <video>, whose picture is letterboxed (object-fit: contain).
 */
export function drawDetections(canvas, detections) {
  const rect = canvas.getBoundingClientRect();
  const dpr = window.devicePixelRatio || 1;
  // Sizing a canvas, even to the size it has, reallocates and clears it: only when it changed.
  const width = Math.round(rect.width * dpr);
  const height = Math.round(rect.height * dpr);
  if (canvas.width !== width) canvas.width = width;
  if (canvas.height !== height) canvas.height = height;
  const ctx = canvas.getContext('2d');
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  if (detections === null || !detections.w || !detections.h) return [];
  const scale = Math.min(canvas.width / detections.w, canvas.height / detections.h);
  const ox = (canvas.width - detections.w * scale) / 2;
  const oy = (canvas.height - detections.h * scale) / 2;
  ctx.font = `${13 * dpr}px system-ui, sans-serif`;
  const boxes = shownBoxes(detections);
  for (const { x, y, w, h, kind } of boxes) {
    const style = BOX_STYLES[kind];
    ctx.globalAlpha = style.alpha;
    ctx.lineWidth = style.width * dpr;
    ctx.setLineDash(style.dash.map((v) => v * dpr));
    ctx.strokeStyle = style.colour;
    ctx.strokeRect(ox + x * scale, oy + y * scale, w * scale, h * scale);
    if (style.label) {
      ctx.fillStyle = style.colour;
      ctx.fillText(style.label, ox + x * scale, oy + y * scale - 4 * dpr);
    }
  }
  ctx.globalAlpha = 1;
  ctx.setLineDash([]);
  ctx.lineWidth = 3 * dpr;
  if (detections.target) {
    const tx = ox + detections.target.x * scale;
    const ty = oy + detections.target.y * scale;
    const r = 9 * dpr;
    ctx.strokeStyle = '#ff4f6d';
    ctx.beginPath();
    ctx.moveTo(tx - r, ty);
    ctx.lineTo(tx + r, ty);
    ctx.moveTo(tx, ty - r);
    ctx.lineTo(tx, ty + r);
    ctx.stroke();
  }
  ctx.fillStyle = '#39ff88';
  if (detections.op) ctx.fillText(detections.op, ox + 6 * dpr, oy + 16 * dpr);
  return boxes;
}
