// Requests that must not queue up: at most one runs, and of those that come meanwhile only the
// newest waits (the others are dropped). The relay runs a client's lock and unlock clicks through
// one of these: each goes to the analyzer's worker, whose snapshots would otherwise wait behind a
// burst of clicks -- 300 clicks stalled the goals for seconds -- while only the newest click
// matters. Tested in e2e/test_one_at_a_time_js.py and, with the relay's analyzer, in
// tests/vision/test_lock_burst.py.

export class OneAtATime {
  #running = null; // the promise of the request running, or null
  #waiting = null; // {job, resolve, reject} of the newest request waiting, or null

  /** How many requests were dropped for a newer one. */
  dropped = 0;

  /**
   * Run `job` (an async function) once the request running has finished; a request already
   * waiting is dropped for it (it resolves to null).
   * @template T
   * @param {() => Promise<T>} job
   * @returns {Promise<T | null>} what `job` resolved to, or null when a newer request replaced it
   */
  run(job) {
    if (this.#running === null) return this.#start(job);
    if (this.#waiting !== null) {
      this.#waiting.resolve(null);
      this.dropped += 1;
    }
    return new Promise((resolve, reject) => {
      this.#waiting = { job, resolve, reject };
    });
  }

  #start(job) {
    const running = (async () => job())();
    this.#running = running;
    const next = () => {
      this.#running = null;
      const waiting = this.#waiting;
      this.#waiting = null;
      if (waiting !== null) this.#start(waiting.job).then(waiting.resolve, waiting.reject);
    };
    running.then(next, next);
    return running;
  }
}
