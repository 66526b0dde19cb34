// Client side of the /ws signaling protocol (docs/architecture.md, "Signaling protocol"): JSON text
// frames, one `message` event per message, login as a promise.

/** Thrown by `login` when the server refuses it; `message` is the server's reason. */
export class LoginRefused extends Error {}

/** A WebSocket to the signaling server that speaks JSON and dispatches events. */
export class Signaling extends EventTarget {
  #ws = null;

  /** True while the socket is open. */
  get open() {
    return this.#ws !== null && this.#ws.readyState === WebSocket.OPEN;
  }

  /** Open the socket; resolves once open, rejects with an Error in words if it cannot. */
  connect(url) {
    this.close();
    return new Promise((resolve, reject) => {
      const ws = new WebSocket(url);
      this.#ws = ws;
      let opened = false;
      ws.addEventListener('open', () => {
        opened = true;
        resolve();
      });
      ws.addEventListener('close', (event) => {
        if (!opened) reject(new Error(`cannot reach the signaling server at ${url}`));
        if (this.#ws === ws) this.#ws = null;
        this.dispatchEvent(
          new CustomEvent('close', { detail: { code: event.code, reason: event.reason } }),
        );
      });
      ws.addEventListener('message', (event) => this.#receive(event.data));
    });
  }

  /** Send `login` and wait for the answer; resolves with it, rejects with LoginRefused. */
  login({ name, role, room, token }) {
    return new Promise((resolve, reject) => {
      const onMessage = (event) => {
        const msg = event.detail;
        if (msg.type === 'login') {
          this.removeEventListener('message', onMessage);
          if (msg.success) resolve(msg);
          else reject(new LoginRefused(msg.reason || 'login refused'));
        } else if (msg.type === 'error' && msg.ref === 'login') {
          this.removeEventListener('message', onMessage);
          reject(new LoginRefused(msg.reason || 'login refused'));
        }
      };
      this.addEventListener('message', onMessage);
      const login = { type: 'login', name, role, room };
      if (token) login.token = token;
      try {
        this.send(login);
      } catch (err) {
        this.removeEventListener('message', onMessage);
        reject(err);
      }
    });
  }

  /** Send one message; throws if the socket is not open. */
  send(msg) {
    if (!this.open) throw new Error('not connected to the signaling server');
    this.#ws.send(JSON.stringify(msg));
  }

  /** Close the socket (no-op when already closed). */
  close() {
    if (this.#ws !== null) {
      this.#ws.close();
      this.#ws = null;
    }
  }

  #receive(text) {
    let msg;
    try {
      msg = JSON.parse(text);
    } catch {
      const detail = `server sent malformed JSON: ${String(text).slice(0, 80)}`;
      this.dispatchEvent(new CustomEvent('protocolerror', { detail }));
      return;
    }
    if (msg === null || typeof msg !== 'object' || typeof msg.type !== 'string') {
      this.dispatchEvent(
        new CustomEvent('protocolerror', { detail: 'server sent a message without a type' }),
      );
      return;
    }
    this.dispatchEvent(new CustomEvent('message', { detail: msg }));
  }
}
