// Latest-wins for goals on the lossy channel: the same rule as vehicle_agent/core/freshness.py.
// A goal is applied when its seq is newer than every goal applied before and it is not stale.
// Stale, without synchronised clocks: offset = receive time - goal.t; the smallest offset over
// the last `windowS` stands for the path's base delay; a goal more than `maxAgeS` above that
// base waited too long on the way. Goals from the future are refused first: a seq beyond what
// the link can have reached since the last goal applied (`seqBurst` plus `seqRateHz` per
// second), or a t more than `maxSkewS` ahead of this side's wall clock; a refused goal changes
// nothing. The numbers come from the page config (one source: Python); both twins run the shared
// sequences of tests/vehicle_agent/core/freshness_sequences.py.

export class GoalGate {
  /**
   * @param {{maxAgeS: number, windowS: number, maxSkewS: number, seqRateHz: number,
   *   seqBurst: number}} rule
   * @param {() => number} [wallClock] this side's wall clock, Unix ms (injected by tests)
   */
  constructor(rule, wallClock = () => Date.now()) {
    this.rule = rule;
    this.wallClock = wallClock;
    this.lastSeq = null;
    this.lastAt = null; // when the last goal was applied (receiver's clock, s)
    this.offsets = []; // [receivedAtS, offsetS], offsets increasing: the head is the minimum
  }

  /** Forget everything (a new link: the relay's seq starts again). */
  reset() {
    this.lastSeq = null;
    this.lastAt = null;
    this.offsets = [];
  }

  /**
   * @param {number} seq the goal's sequence number
   * @param {number} sentMs the sender's clock when it sent the goal, ms
   * @param {number} nowS this side's clock, s
   * @returns {'fresh' | 'old' | 'stale' | 'future'}
   */
  admit(seq, sentMs, nowS) {
    if (this.#beyondReach(seq, nowS) || sentMs > this.wallClock() + this.rule.maxSkewS * 1000)
      return 'future';
    const offset = nowS - sentMs / 1000;
    while (this.offsets.length && this.offsets[0][0] < nowS - this.rule.windowS)
      this.offsets.shift();
    while (this.offsets.length && this.offsets[this.offsets.length - 1][1] >= offset)
      this.offsets.pop();
    this.offsets.push([nowS, offset]);
    if (this.lastSeq !== null && seq <= this.lastSeq) return 'old';
    if (offset - this.offsets[0][1] > this.rule.maxAgeS) return 'stale';
    this.lastSeq = seq;
    this.lastAt = nowS;
    return 'fresh';
  }

  #beyondReach(seq, nowS) {
    if (this.lastSeq === null) return false;
    const reach = this.rule.seqBurst + this.rule.seqRateHz * Math.max(nowS - this.lastAt, 0);
    return seq - this.lastSeq > reach;
  }
}
