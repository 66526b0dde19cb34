// The relay's statistics: per-snapshot timings in bounded rings and goals per second over a
// sliding window. No DOM, no WebRTC; time comes from the caller.

const RATE_WINDOW_MS = 2000;
const MS_SAMPLES = 2000;

/**
 * The latest `capacity` samples, in storage allocated once: a ring that fills up must not look
 * like heap growth to a memory check. `toArray()` gives them oldest first.
 */
export class SampleRing {
  constructor(capacity) {
    this.values = new Float64Array(capacity);
    this.count = 0;
    this.next = 0;
  }

  push(value) {
    this.values[this.next] = value;
    this.next = (this.next + 1) % this.values.length;
    this.count = Math.min(this.count + 1, this.values.length);
  }

  toArray() {
    const start = (this.next - this.count + this.values.length) % this.values.length;
    return Array.from(
      { length: this.count },
      (_, i) => this.values[(start + i) % this.values.length],
    );
  }
}

/** What the relay measures of its snapshots, goals included. */
export class RelayStats {
  constructor({ samples = MS_SAMPLES, rateWindowMs = RATE_WINDOW_MS } = {}) {
    this.rateWindowMs = rateWindowMs;
    this.snapshots = 0;
    this.goalsSent = 0;
    /** Snapshot taken -> goal sent (or analysis done when nothing was found), ms. */
    this.processing = new SampleRing(samples);
    /** Of which in the vision worker: pixels read and detection. */
    this.work = new SampleRing(samples);
    /** Of which the operation's detect() alone. */
    this.detect = new SampleRing(samples);
    /** Clock times of the goals sent within the rate window, oldest first. */
    this.goalTimes = [];
  }

  /** Count a sent goal at clock time `now` (ms). */
  goalSent(now) {
    this.goalsSent += 1;
    this.goalTimes.push(now);
  }

  /** Record one analysed snapshot's delays (ms). */
  snapshot({ processingMs, workMs, detectMs }) {
    this.snapshots += 1;
    this.processing.push(processingMs);
    this.work.push(workMs);
    this.detect.push(detectMs);
  }

  /** Goals per second over the window ending at clock time `now` (ms). */
  goalsPerS(now) {
    while (this.goalTimes.length && now - this.goalTimes[0] > this.rateWindowMs)
      this.goalTimes.shift();
    return this.goalTimes.length / (this.rateWindowMs / 1000);
  }
}
