// Reads the simulated arena's state (GET config.arenaMap.statePath: where its billboards stand
// now) every statePeriodMs for the client's map, with the page's token when it has one.

/**
 * Poll the arena's state until `stop()` is called. `room()` and `token()` are read at each poll
 * (the page may join another room, renew its token); `onState` gets the parsed answer
 * ({t, billboards: [{name, x, y, yaw}]}), `onError` the reason a poll failed. `fetchFn` is the
 * browser's fetch unless a test gives another.
 */
export function pollArenaState({ path, periodMs, room, token, onState, onError, fetchFn = fetch }) {
  let timer = null;
  let stopped = false;
  let lastError = null;
  async function poll() {
    const headers = token() ? { Authorization: `Bearer ${token()}` } : {};
    const url = `${path}?room=${encodeURIComponent(room())}`;
    try {
      const response = await fetchFn(url, { cache: 'no-store', headers });
      if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
      onState(await response.json());
      lastError = null;
    } catch (err) {
      // Said once, not every poll, until a poll succeeds again.
      if (err.message !== lastError) onError(err.message);
      lastError = err.message;
    }
    if (!stopped) timer = setTimeout(poll, periodMs);
  }
  poll();
  return {
    stop() {
      stopped = true;
      clearTimeout(timer);
    },
  };
}
