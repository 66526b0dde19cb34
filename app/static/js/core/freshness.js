// Latest-wins for goals on the lossy channel: the same rule as vehicle_agent/freshness.py.
// A goal is applied when its seq is newer than every goal applied before and it is not stale.
// Stale, without synchronised clocks: offset = receive time - goal.t; the smallest offset over
// the last `windowS` stands for the path's base delay; a goal more than `maxAgeS` above that
// base waited too long on the way. The numbers come from the page config (one source: Python).

export class GoalGate {
  /** @param {{maxAgeS: number, windowS: number}} rule */
  constructor(rule) {
    this.rule = rule;
    this.lastSeq = null;
    this.offsets = []; // [receivedAtS, offsetS], offsets increasing: the head is the minimum
  }

  /** Forget everything (a new link: the relay's seq starts again). */
  reset() {
    this.lastSeq = null;
    this.offsets = [];
  }

  /**
   * @param {number} seq the goal's sequence number
   * @param {number} sentMs the sender's clock when it sent the goal, ms
   * @param {number} nowS this side's clock, s
   * @returns {'fresh' | 'old' | 'stale'}
   */
  admit(seq, sentMs, nowS) {
    const offset = nowS - sentMs / 1000;
    while (this.offsets.length && this.offsets[0][0] < nowS - this.rule.windowS)
      this.offsets.shift();
    while (this.offsets.length && this.offsets[this.offsets.length - 1][1] >= offset)
      this.offsets.pop();
    this.offsets.push([nowS, offset]);
    if (this.lastSeq !== null && seq <= this.lastSeq) return 'old';
    if (offset - this.offsets[0][1] > this.rule.maxAgeS) return 'stale';
    this.lastSeq = seq;
    return 'fresh';
  }
}
