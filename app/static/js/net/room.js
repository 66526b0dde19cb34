// One page's membership of a signaling room: Connect / Join Room / Leave Room, the roster of
// the other peers, the unattended mode (?auto=1) that joins by itself and rejoins after the
// server goes away, and the token's renewal: the server ends a session when its token expires,
// so the page asks for a fresh one (`renew`) when the server said to (`renewIn`), and keeps it.
import { PROTOCOL } from '../config.js';
import { LoginRefused, Signaling } from './signaling.js';
import { button, byTestId } from '../view/ui.js';

const RETRY_MIN_MS = 500;
const RETRY_MAX_MS = 5000;

/**
 * Events: `phase` (disconnected → connected → joined), `roster` (detail: the other peers),
 * `problem` (detail: why this page cannot join, also in `describe()`),
 * `peerleft` (detail: name), `renewed` (detail: the fresh token, now `token`),
 * `signal` (detail: any other message from the server, e.g. offer).
 */
export class RoomSession extends EventTarget {
  #retryMs = RETRY_MIN_MS;
  #autoRunning = false;
  #renewal = null; // the timer of the next renewal

  constructor(config, log) {
    super();
    this.config = config;
    this.role = config.role;
    this.log = log;
    this.signaling = new Signaling();
    this.phase = 'disconnected';
    this.name = null;
    this.room = null;
    this.roster = [];
    this.auto = false;
    // The token from the URL's fragment, then each renewal's: what the next login sends.
    this.token = config.token;
    this.renewals = 0; // tokens renewed since the page opened
    // Why this page cannot join, in words for the state line (a refused login, a misplaced
    // token); cleared by a successful join.
    this.problem = null;
    if (config.tokenInQuery) {
      this.#setProblem(
        'the token is in the query (?token=…): put it after # instead (…#token=…), ' +
          'where it never leaves the browser',
      );
    }
    this.signaling.addEventListener('message', (event) => this.#onMessage(event.detail));
    this.signaling.addEventListener('close', (event) => this.#onClose(event.detail));
    this.signaling.addEventListener('protocolerror', (event) => this.log.error(event.detail));
  }

  /** The signaling URL on the server that served this page. */
  get url() {
    const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
    return `${scheme}//${location.host}${this.config.wsPath}`;
  }

  /** The room's relay from the roster, or undefined. */
  get relay() {
    return this.roster.find((peer) => peer.role === 'relay');
  }

  async connect() {
    this.#setPhase('connecting');
    try {
      await this.signaling.connect(this.url);
    } catch (err) {
      this.#setPhase('disconnected');
      throw err;
    }
    this.log.info(`connected to ${this.url}`);
    this.#setPhase('connected');
  }

  async join(name, room) {
    let reply;
    try {
      reply = await this.signaling.login({ name, role: this.role, room, token: this.token });
    } catch (err) {
      if (err instanceof LoginRefused)
        this.#setProblem(`login refused: ${err.message}`, { log: false });
      throw err;
    }
    this.problem = null;
    this.name = name;
    this.room = reply.room || room;
    // ICE for this login (TURN credentials minted for it); every new connection uses it.
    this.ice = {
      iceServers: reply.iceServers || [],
      iceTransportPolicy: reply.iceTransportPolicy || 'all',
    };
    this.log.info(`joined room ${this.room} as ${this.role} ${name}`);
    this.#renewAfter(reply.renewIn);
    // Roster first, so that listeners of the `joined` phase already see who is there.
    this.#setRoster(reply.peers || []);
    this.#setPhase('joined');
  }

  /** Leave the room on purpose: tell the others, close the socket, stop rejoining. */
  leave() {
    this.auto = false;
    if (this.phase === 'joined') this.signaling.send({ type: 'leave' });
    this.signaling.close();
    this.log.info('left the room');
    this.#reset();
  }

  /** Send a message to the server; throws if not connected. */
  send(msg) {
    this.signaling.send(msg);
  }

  /** Connect and join with no clicks, retrying with backoff until it works (and after drops). */
  async autoJoin() {
    this.auto = true;
    if (this.#autoRunning) return;
    this.#autoRunning = true;
    while (this.auto && this.phase !== 'joined') {
      try {
        if (!this.signaling.open) await this.connect();
        await this.join(this.#chosenName(), this.#chosenRoom());
        this.#retryMs = RETRY_MIN_MS;
      } catch (err) {
        this.log.warn(`${err.message}; retrying in ${(this.#retryMs / 1000).toFixed(1)} s`);
        if (err instanceof LoginRefused) this.signaling.close();
        await new Promise((resolve) => setTimeout(resolve, this.#retryMs));
        this.#retryMs = Math.min(this.#retryMs * 2, RETRY_MAX_MS);
      }
    }
    this.#autoRunning = false;
  }

  /** Wire the Connect / Join Room / Leave Room buttons and the room and name inputs. */
  bindControls() {
    const connect = button('connect');
    const join = button('join');
    const leave = button('leave');
    const run = (action) => action().catch((err) => this.log.error(err.message));
    connect.addEventListener('click', () => run(() => this.connect()));
    join.addEventListener('click', () =>
      run(() => this.join(this.#chosenName(), this.#chosenRoom())),
    );
    leave.addEventListener('click', () => this.leave());
    const update = () => {
      connect.disabled = this.phase !== 'disconnected';
      join.disabled = this.phase !== 'connected';
      leave.disabled = this.phase !== 'joined';
    };
    this.addEventListener('phase', update);
    update();
  }

  /** A one-line description of where this page stands, for the state line. */
  describe({ withRoster = true } = {}) {
    if (this.phase === 'joined') {
      const others =
        this.roster.map((peer) => `${peer.role} ${peer.name}`).join(', ') || 'nobody else yet';
      return `joined room ${this.room} as ${this.name}${withRoster ? ` · with ${others}` : ''}`;
    }
    const where = this.phase === 'connected' ? 'connected, not in a room' : this.phase;
    return this.problem === null ? where : `${where} · ${this.problem}`;
  }

  /**
   * The state line's parts for a page that talks to the room's relay (client and vehicle):
   * `describe()` without the roster, then the relay seat (`relayConnected`: this page's own
   * channel to it is open).
   */
  describeWithRelay(relayConnected) {
    const parts = [this.describe({ withRoster: false })];
    if (this.phase !== 'joined') return parts;
    const relay = this.relay;
    if (relay === undefined) parts.push('waiting for a relay');
    else
      parts.push(
        relayConnected ? `relay ${relay.name} connected` : `connecting to relay ${relay.name}`,
      );
    return parts;
  }

  #chosenName() {
    const input = byTestId('name');
    if (!input.value.trim()) {
      input.value = this.config.name || `${this.role}-${Math.random().toString(36).slice(2, 6)}`;
    }
    return input.value.trim();
  }

  #chosenRoom() {
    return byTestId('room').value.trim() || PROTOCOL.defaultRoom;
  }

  #onMessage(msg) {
    switch (msg.type) {
      case 'login':
        break; // answered inside Signaling.login
      case 'peers':
        this.#setRoster(msg.peers || []);
        break;
      case 'leave':
        this.log.info(`${msg.from} left the room`);
        this.#setRoster(this.roster.filter((peer) => peer.name !== msg.from));
        break;
      case 'renewed':
        this.#onRenewed(msg);
        break;
      case 'error':
        if (msg.ref === 'login') break; // the refused login's own error, reported by join()
        this.log.error(`signaling server: ${msg.reason}${msg.ref ? ` (about ${msg.ref})` : ''}`);
        break;
      default:
        this.dispatchEvent(new CustomEvent('signal', { detail: msg }));
    }
  }

  #onClose({ code, reason } = {}) {
    if (this.phase === 'disconnected' || this.phase === 'connecting') return;
    // The server says why it closed (login deadline, too slow, abusive, server full ...).
    const why = reason ? ` (${code}: ${reason})` : code ? ` (${code})` : '';
    this.log.warn(`signaling connection closed${why}`);
    this.#reset();
    if (this.auto) setTimeout(() => this.autoJoin(), this.#retryMs);
  }

  /** Ask for a fresh token in `seconds` (none: the server asks for no tokens). */
  #renewAfter(seconds) {
    clearTimeout(this.#renewal);
    this.#renewal = null;
    if (typeof seconds !== 'number') return;
    this.#renewal = setTimeout(() => {
      this.#renewal = null;
      if (this.phase !== 'joined') return;
      try {
        this.signaling.send({ type: 'renew' });
      } catch (err) {
        this.log.warn(`cannot renew the token: ${err.message}`);
      }
    }, seconds * 1000);
  }

  #onRenewed(msg) {
    if (typeof msg.token !== 'string' || typeof msg.renewIn !== 'number') {
      this.log.error('signaling server: a renewal without a token or a time');
      return;
    }
    // The next login (a rejoin after the server went away) uses the fresh token too.
    this.token = msg.token;
    this.renewals += 1;
    this.log.info(`token renewed; next renewal in ${Math.round(msg.renewIn)} s`);
    this.dispatchEvent(new CustomEvent('renewed', { detail: msg.token }));
    this.#renewAfter(msg.renewIn);
  }

  #reset() {
    this.#renewAfter(null);
    const others = this.roster;
    this.roster = [];
    this.#setPhase('disconnected');
    for (const peer of others)
      this.dispatchEvent(new CustomEvent('peerleft', { detail: peer.name }));
    this.dispatchEvent(new CustomEvent('roster', { detail: [] }));
  }

  #setRoster(peers) {
    const before = new Set(this.roster.map((peer) => peer.name));
    this.roster = peers.filter((peer) => peer.name !== this.name);
    const now = new Set(this.roster.map((peer) => peer.name));
    for (const name of before) {
      if (!now.has(name)) this.dispatchEvent(new CustomEvent('peerleft', { detail: name }));
    }
    this.dispatchEvent(new CustomEvent('roster', { detail: this.roster }));
  }

  /** Show `text` on the state line until a join succeeds (and log it, unless the caller does). */
  #setProblem(text, { log = true } = {}) {
    this.problem = text;
    if (log) this.log.warn(text);
    this.dispatchEvent(new CustomEvent('problem', { detail: text }));
  }

  #setPhase(phase) {
    this.phase = phase;
    this.dispatchEvent(new CustomEvent('phase', { detail: phase }));
  }
}
