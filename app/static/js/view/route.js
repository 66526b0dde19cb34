// The route a robot drove, from its poses: what the turtle's and the room's maps draw behind it.

const TRAIL_LIMIT = 20000;
// A point is added only when the robot moved this far (m): turning in place adds nothing.
const MIN_STEP_M = 0.005;

/** Poses in, the points of the route and its length out; the oldest points go past the limit. */
export class Route {
  #points = [];
  #lengthM = 0;

  /** Metres driven since the first pose. */
  get length() {
    return this.#lengthM;
  }

  /** The route's points, oldest first: [{x, y}] in metres. */
  get points() {
    return this.#points;
  }

  /** Add the place of a pose {x, y} (metres). */
  add(pose) {
    const last = this.#points.at(-1);
    const step = last === undefined ? 0 : Math.hypot(pose.x - last.x, pose.y - last.y);
    if (last !== undefined && step <= MIN_STEP_M) return;
    this.#lengthM += step;
    this.#points.push({ x: pose.x, y: pose.y });
    if (this.#points.length > TRAIL_LIMIT) {
      this.#points.splice(0, this.#points.length - TRAIL_LIMIT);
    }
  }

  /** Stroke the route on `ctx` through `toCanvas` ({x, y} metres → [px, py]). */
  draw(ctx, toCanvas, colour, width) {
    if (this.#points.length < 2) return;
    ctx.strokeStyle = colour;
    ctx.lineWidth = width;
    ctx.lineJoin = 'round';
    ctx.beginPath();
    ctx.moveTo(...toCanvas(this.#points[0]));
    for (const p of this.#points.slice(1)) ctx.lineTo(...toCanvas(p));
    ctx.stroke();
  }
}
