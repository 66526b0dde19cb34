// The relay's snapshot → goal loop, with no DOM and no WebRTC: fed frames (VideoFrame,
// ImageBitmap or raw RGBA) by whoever owns the video, it analyses one at a time with the
// current operation and emits what the relay sends on: a `goal` for the vehicle when the
// operation found a target, and `detections` (with the statistics riding along) for the
// clients. The relay page schedules the frames; a test can feed synthetic ones. The target lock
// (lock.js) is the analyzer's: each snapshot follows it at the loop's time, and while a target is
// locked the goal is that target's, not the largest box's. The loop passes clicks and releases
// on and tells the clients what the lock became, and holds the lock while the vehicle says it is
// searching for the target.
//
// Every frame the vehicle sends is offered; one is analysed at a time, and the freshest frame
// that came meanwhile waits for it and is analysed next (an older one waiting is skipped). The
// snapshots follow the target in a window around it between full scans (tracking-window.js), so
// most take a fraction of a frame's time and a goal goes out for nearly every frame
// (docs/performance.md, "Goals at the camera's frame rate").

import { robotSearching } from './lock.js';
import { RelayStats } from './relay-stats.js';

/**
 * Events (CustomEvent detail):
 *   `goal`        the goal message ({type: 'goal', seq, op, x, y, w, h, t, frame?, boxW?,
 *                 boxH?, targetHeightM?, locked}) once sent
 *   `detections`  the detections message ({type: 'detections', op, boxes, target, w, h, ms,
 *                 goalsPerS, locked: the locked target's box or null, candidates: the last
 *                 full scan's boxes})
 *   `lock`        the lockState message ({type: 'lockState', state, box, reason}) when the lock
 *                 changed
 *   `failure`     an analysis error's message, once until a snapshot succeeds again
 */
export class SnapshotLoop extends EventTarget {
  #busy = false;
  #lastFailure = null;
  #waiting = null; // {source, resolve}: the freshest frame offered while one is analysed
  #robotSearching = false;

  /**
   * @param {object} options
   * @param {{analyze: Function, lockAt: Function, unlock: Function}} options.analyzer from
   *   vision.js createAnalyzer()
   * @param {string} options.profile relay profile, passed to the analyzer
   * @param {string} options.op the operation to run (change it with `op` at any time)
   * @param {boolean} [options.track] detect, then track: the analyzer searches a window around
   *   the last target between full scans (window.js)
   * @param {(goal: object) => boolean} options.sendGoal sends a goal; false when it could not
   * @param {() => number} [options.clock] ms, for delays and rates (performance.now)
   * @param {() => number} [options.wallClock] ms since the epoch, the goal's `t` (Date.now)
   */
  constructor({
    analyzer,
    profile,
    op,
    sendGoal,
    track = false,
    clock = () => performance.now(),
    wallClock = () => Date.now(),
  }) {
    super();
    this.analyzer = analyzer;
    this.profile = profile;
    this.op = op;
    this.sendGoal = sendGoal;
    this.track = track;
    this.clock = clock;
    this.wallClock = wallClock;
    this.stats = new RelayStats();
    this.running = false;
    this.lastGoal = null;
    this.lastDetections = null;
    // The lock as the analyzer last told it: {state, box}.
    this.lock = { state: 'none', box: null };
  }

  /**
   * A click at frame pixel (x, y): lock on the target at or near it (on the last snapshot, the
   * last full scan, or found by a full-resolution search around it), or release the lock when
   * there is none (the analyzer's lockAt). Resolves to whether it locked.
   */
  async lockAt(x, y) {
    const answer = await this.analyzer.lockAt(x, y, this.clock() / 1000);
    this.#lockIs(answer, answer.reason);
    return answer.locked;
  }

  /** Release the lock, if there is one, saying why. */
  async unlock(reason) {
    const answer = await this.analyzer.unlock();
    if (answer.released) this.#lockIs(answer, reason);
  }

  /** The lockState message for the lock as it stands. */
  lockMessage(reason = null) {
    return { type: 'lockState', state: this.lock.state, box: this.lock.box, reason };
  }

  #lockIs({ state, box }, reason) {
    this.lock = { state, box };
    this.#emit('lock', this.lockMessage(reason));
  }

  /**
   * What the vehicle's pose says of its search for a lost target ('left', 'right', 'timed_out',
   * or null: none): while it searches, the lock holds (lock.js robotSearching).
   */
  vehicleSearch(search) {
    this.#robotSearching = robotSearching(search);
  }

  /** Whether a snapshot is being analysed (a frame offered meanwhile waits for it). */
  get busy() {
    return this.#busy;
  }

  start() {
    this.running = true;
  }

  /** Stop: a snapshot still in flight is dropped when it comes back, a waiting frame skipped. */
  stop() {
    this.running = false;
    this.#skipWaiting();
  }

  /**
   * Offer one frame. It is analysed at once when no other is; else it waits for the one being
   * analysed and is analysed next, unless a fresher frame comes meanwhile (then it is closed and
   * skipped), or the loop is stopped. Resolves to {goal, detections} (goal null when nothing was
   * found), or null when the frame was skipped, failed, or piloting stopped meanwhile.
   */
  frame(source) {
    if (!this.running) {
      source.close?.();
      return Promise.resolve(null);
    }
    if (!this.#busy) return this.#run(source);
    this.#skipWaiting();
    return new Promise((resolve) => {
      this.#waiting = { source, resolve };
    });
  }

  #skipWaiting() {
    if (this.#waiting === null) return;
    this.#waiting.source.close?.();
    this.#waiting.resolve(null);
    this.#waiting = null;
  }

  async #run(source) {
    this.#busy = true;
    try {
      const outcome = await this.#analyze(source);
      this.#lastFailure = null;
      return outcome;
    } catch (err) {
      // Every frame would repeat it: say it once until something succeeds again.
      if (err.message !== this.#lastFailure) this.#emit('failure', err.message);
      this.#lastFailure = err.message;
      return null;
    } finally {
      this.#busy = false;
      const next = this.#waiting;
      this.#waiting = null;
      if (next !== null) this.#run(next.source).then(next.resolve);
    }
  }

  async #analyze(source) {
    const started = this.clock();
    const result = await this.analyzer.analyze(source, this.op, {
      profile: this.profile,
      track: this.track,
      at: started / 1000,
      robotSearching: this.#robotSearching,
    });
    // The lock followed this snapshot (its box moves with the target) whether or not piloting
    // goes on; the clients hear of it when its state changed.
    const { state, box, changed, reason } = result.lock;
    this.lock = { state, box };
    if (changed !== null) this.#emit('lock', this.lockMessage(reason));
    if (!this.running) return null;
    let goal = null;
    if (result.target) {
      goal = {
        type: 'goal',
        seq: this.stats.goalsSent + 1,
        op: result.op,
        x: result.target.x,
        y: result.target.y,
        w: result.w,
        h: result.h,
        t: this.wallClock(),
        // The target is the operator's lock, not the largest box (the vehicle records it).
        locked: state === 'locked',
      };
      if (result.frame !== null && result.frame !== undefined) goal.frame = result.frame;
      // The target's box and real height: a camera the vehicle carries reads its range from
      // them (the onboard law).
      if (result.targetBox) {
        [goal.boxW, goal.boxH] = result.targetBox.slice(2);
        goal.targetHeightM = result.targetHeightM;
      }
      if (this.sendGoal(goal)) {
        this.stats.goalSent(this.clock());
        this.lastGoal = goal;
        this.#emit('goal', goal);
      } else {
        goal = null;
      }
    }
    const now = this.clock();
    const ms = now - started;
    this.stats.snapshot({ processingMs: ms, workMs: result.workMs, detectMs: result.ms });
    const detections = {
      type: 'detections',
      op: result.op,
      boxes: result.boxes,
      target: result.target,
      w: result.w,
      h: result.h,
      ms,
      goalsPerS: this.stats.goalsPerS(now),
      locked: this.lock.state === 'locked' ? this.lock.box : null,
      candidates: result.candidates ?? [],
    };
    this.lastDetections = detections;
    this.#emit('detections', detections);
    return { goal, detections };
  }

  #emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }
}
