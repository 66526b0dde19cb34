// A turtlesim look-alike drawn from pose telemetry: the blue terrain (the world size comes from
// the page config, 45 px per metre at 500 px), the pen trail (the route), and the turtle itself.
import { Route } from './route.js';
import { throttle } from './ui.js';

const BACKGROUND = 'rgb(69, 86, 255)'; // turtlesim's default background
const PEN = 'rgb(179, 184, 255)'; // turtlesim's default pen
// Poses and goals arrive 30 to 60 times a second, and each redraw paints the whole route: the
// view is redrawn at most 20 times a second (a turtle at 2 m/s moves 4.5 px between two).
const REDRAW_PERIOD_MS = 50;

/** Draws the turtle and its route on a square canvas `worldSize` metres wide. */
export class TurtleView {
  #route = new Route();
  #pose = null;
  #target = null;
  #redraw = throttle(REDRAW_PERIOD_MS, () => this.draw());

  constructor(canvas, worldSize) {
    this.canvas = canvas;
    this.worldSize = worldSize;
    this.draw();
  }

  /** Metres driven since the view opened (turning in place adds nothing). */
  get routeLength() {
    return this.#route.length;
  }

  /** Points of the drawn route. */
  get routePoints() {
    return this.#route.points.length;
  }

  /** Add a pose {x, y, theta} (terrain metres, radians); redrawn within REDRAW_PERIOD_MS. */
  addPose(pose) {
    // The pen only draws when the turtle moves; rotating in place leaves no mark.
    this.#route.add(pose);
    this.#pose = pose;
    this.#redraw();
  }

  /** Show where the current goal lies on the terrain ({x, y} metres), or hide it with null. */
  setTarget(target) {
    this.#target = target;
    this.#redraw();
  }

  draw() {
    const { canvas } = this;
    const ctx = canvas.getContext('2d');
    const scale = canvas.width / this.worldSize;
    const px = (x) => x * scale;
    const py = (y) => canvas.height - y * scale;
    ctx.fillStyle = BACKGROUND;
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    this.#route.draw(ctx, (p) => [px(p.x), py(p.y)], PEN, 3);
    if (this.#pose !== null && this.#target !== null) {
      ctx.setLineDash([6, 6]);
      ctx.strokeStyle = 'rgba(255, 255, 255, 0.7)';
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      ctx.moveTo(px(this.#pose.x), py(this.#pose.y));
      ctx.lineTo(px(this.#target.x), py(this.#target.y));
      ctx.stroke();
      ctx.setLineDash([]);
      ctx.fillStyle = '#ff4f6d';
      ctx.beginPath();
      ctx.arc(px(this.#target.x), py(this.#target.y), 6, 0, 2 * Math.PI);
      ctx.fill();
    }
    if (this.#pose !== null)
      drawTurtle(ctx, px(this.#pose.x), py(this.#pose.y), this.#pose.theta, scale);
  }
}

/** A top-down turtle heading along +x before rotation; canvas y points down, hence −theta. */
function drawTurtle(ctx, x, y, theta, scale) {
  const s = scale * 1.1; // about the size of turtlesim's 45 px sprite on its 500 px window
  ctx.save();
  ctx.translate(x, y);
  ctx.rotate(-theta);
  ctx.fillStyle = '#7fb069';
  ctx.strokeStyle = '#2d4a22';
  ctx.lineWidth = 1.5;
  for (const [lx, ly] of [
    [0.35, 0.42],
    [0.35, -0.42],
    [-0.35, 0.42],
    [-0.35, -0.42],
  ]) {
    ctx.beginPath();
    ctx.ellipse(lx * s, ly * s, 0.16 * s, 0.1 * s, 0, 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
  }
  ctx.beginPath();
  ctx.ellipse(0.62 * s, 0, 0.18 * s, 0.15 * s, 0, 0, 2 * Math.PI); // head, in front
  ctx.fill();
  ctx.stroke();
  ctx.fillStyle = '#4f7a3a';
  ctx.beginPath();
  ctx.ellipse(0, 0, 0.5 * s, 0.4 * s, 0, 0, 2 * Math.PI); // shell
  ctx.fill();
  ctx.stroke();
  ctx.strokeStyle = '#a9d18e';
  ctx.beginPath();
  ctx.ellipse(0, 0, 0.28 * s, 0.2 * s, 0, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.restore();
}
