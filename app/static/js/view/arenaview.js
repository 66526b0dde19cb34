// The simulated arena from above, for the client: its walls, the billboards (faces and the
// flame, the walker's path dotted), the robot from its forwarded odometry with the wedge its
// camera sees, and the route it drove. The layout comes from the page config (`config.arenaMap`,
// app/diffdrive/arenamap.py); the billboards' places now from GET /arena/state.
import { Route } from './route.js';
import { throttle } from './ui.js';

const FLOOR = '#c9b79c';
const WALL = '#4a3f35';
const WALL_PX = 6;
const ROUTE = 'rgba(40, 90, 200, 0.55)';
const WEDGE = 'rgba(255, 230, 120, 0.35)';
const ROBOT = '#2f6fd0';
const FACE = '#b0508f';
const FLAME = '#ff7a1a';
// How far the camera's wedge is drawn (m): about where the face operations still find a face.
const WEDGE_M = 4;
// Poses arrive 30 to 60 times a second: redrawn at most 20 times a second, as the turtle view.
const REDRAW_PERIOD_MS = 50;

/** Draws the arena `map` ({width, depth, robotRadius, hfov, billboards}) on `canvas`. */
export class ArenaView {
  #route = new Route();
  #pose = null;
  #placed = new Map(); // billboard name -> {x, y, yaw}, from the arena's state
  #redraw = throttle(REDRAW_PERIOD_MS, () => this.draw());

  constructor(canvas, map) {
    this.canvas = canvas;
    this.map = map;
    // The canvas keeps its width and takes the arena's proportions (the page's stylesheet
    // makes the turtle's terrain square).
    canvas.height = Math.round((canvas.width * map.depth) / map.width);
    canvas.style.aspectRatio = `${map.width} / ${map.depth}`;
    for (const b of map.billboards) this.#placed.set(b.name, { x: b.x, y: b.y, yaw: b.yaw });
    this.draw();
  }

  /** Metres driven since the view opened. */
  get routeLength() {
    return this.#route.length;
  }

  /** Points of the drawn route. */
  get routePoints() {
    return this.#route.points.length;
  }

  /** Where each billboard is drawn now: {name: {x, y, yaw}}. */
  get placed() {
    return Object.fromEntries(this.#placed);
  }

  /** Add the robot's pose {x, y, theta} (arena metres, radians). */
  addPose(pose) {
    this.#route.add(pose);
    this.#pose = pose;
    this.#redraw();
  }

  /** The billboards' places now: [{name, x, y, yaw}] (names the map lacks are ignored). */
  setBillboards(placed) {
    for (const b of placed) if (this.#placed.has(b.name)) this.#placed.set(b.name, b);
    this.#redraw();
  }

  /** The turtle view's goal marker: a goal pixel is no place in this arena (the camera moves). */
  setTarget() {}

  draw() {
    const { canvas, map } = this;
    const ctx = canvas.getContext('2d');
    const scale = canvas.width / map.width;
    const toCanvas = (p) => [p.x * scale, canvas.height - p.y * scale];
    ctx.fillStyle = FLOOR;
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.strokeStyle = WALL;
    ctx.lineWidth = WALL_PX;
    ctx.strokeRect(WALL_PX / 2, WALL_PX / 2, canvas.width - WALL_PX, canvas.height - WALL_PX);
    for (const b of map.billboards) if (b.walk.length > 1) drawWalk(ctx, b.walk, toCanvas);
    this.#route.draw(ctx, toCanvas, ROUTE, 2);
    if (this.#pose !== null) drawWedge(ctx, this.#pose, map.hfov, scale, toCanvas);
    for (const b of map.billboards)
      drawBillboard(ctx, b, this.#placed.get(b.name), scale, toCanvas);
    if (this.#pose !== null) drawRobot(ctx, this.#pose, map.robotRadius, scale, toCanvas);
  }
}

function drawWalk(ctx, walk, toCanvas) {
  ctx.save();
  ctx.setLineDash([4, 6]);
  ctx.strokeStyle = 'rgba(80, 60, 40, 0.6)';
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  ctx.moveTo(...toCanvas({ x: walk[0][0], y: walk[0][1] }));
  for (const [x, y] of walk.slice(1)) ctx.lineTo(...toCanvas({ x, y }));
  ctx.closePath();
  ctx.stroke();
  ctx.restore();
}

/** The camera's field of view: a wedge from the robot, half the field each side of its heading. */
function drawWedge(ctx, pose, hfov, scale, toCanvas) {
  const [cx, cy] = toCanvas(pose);
  // Canvas y points down: a heading θ counter-clockwise is −θ on the canvas.
  ctx.fillStyle = WEDGE;
  ctx.beginPath();
  ctx.moveTo(cx, cy);
  ctx.arc(cx, cy, WEDGE_M * scale, -pose.theta - hfov / 2, -pose.theta + hfov / 2);
  ctx.closePath();
  ctx.fill();
}

/** A billboard seen from above: its picture as a line across, a tick the way it faces. */
function drawBillboard(ctx, mark, place, scale, toCanvas) {
  const half = mark.width / 2;
  // The picture's edges: along (−sin yaw, cos yaw) from its centre.
  const dx = -Math.sin(place.yaw) * half;
  const dy = Math.cos(place.yaw) * half;
  const colour = mark.kind === 'flame' ? FLAME : FACE;
  ctx.strokeStyle = colour;
  ctx.lineWidth = 4;
  ctx.beginPath();
  ctx.moveTo(...toCanvas({ x: place.x - dx, y: place.y - dy }));
  ctx.lineTo(...toCanvas({ x: place.x + dx, y: place.y + dy }));
  ctx.stroke();
  const [x, y] = toCanvas(place);
  const [fx, fy] = toCanvas({
    x: place.x + 0.2 * Math.cos(place.yaw),
    y: place.y + 0.2 * Math.sin(place.yaw),
  });
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y);
  ctx.lineTo(fx, fy);
  ctx.stroke();
  ctx.fillStyle = colour;
  ctx.beginPath();
  ctx.arc(x, y, Math.max(3, 0.1 * scale), 0, 2 * Math.PI);
  ctx.fill();
  ctx.fillStyle = '#222';
  ctx.font = '11px sans-serif';
  // The name beside it, on the side with room for it.
  const label = ctx.measureText(mark.name).width;
  const left = x + 6 + label > ctx.canvas.width;
  ctx.fillText(mark.name, left ? x - 6 - label : x + 6, y - 6);
}

function drawRobot(ctx, pose, radius, scale, toCanvas) {
  const [x, y] = toCanvas(pose);
  const r = radius * scale;
  ctx.fillStyle = ROBOT;
  ctx.strokeStyle = '#123';
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  ctx.arc(x, y, r, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  ctx.strokeStyle = '#fff';
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y);
  ctx.lineTo(x + r * Math.cos(-pose.theta), y + r * Math.sin(-pose.theta));
  ctx.stroke();
}
