// One RTCPeerConnection per remote peer, negotiated with the "perfect negotiation" pattern of
// webrtc/samples (peerconnection/perfect-negotiation), plus the JSON data-channel plumbing every
// role shares.
//
// The signaling server lets only vehicles and clients send `offer` and only the relay send `answer`
// (docs/architecture.md, "Signaling protocol"), so the relay is the polite side and never offers:
// it forwards video by replacing the track of the client's recvonly transceiver, which needs no
// renegotiation.
import { acceptedTypes, describeProblems, validate } from '../core/schema.js';

/**
 * Events: `track` (detail: RTCTrackEvent), `datachannel` (detail: RTCDataChannel),
 * `state` (detail: connectionState).
 */
export class Peer extends EventTarget {
  #makingOffer = false;
  #ignoreOffer = false;
  #settingRemoteAnswer = false;

  /**
   * @param {object} options
   * @param {string} options.remote name of the remote peer (signaling `to`)
   * @param {boolean} options.polite the polite side yields on offer collisions
   * @param {boolean} options.mayOffer false on the relay: the server refuses its offers
   * @param {{iceServers: RTCIceServer[], iceTransportPolicy: string}} options.ice from the login
   *   reply
   * @param {(msg: object) => void} options.send sends a signaling message
   * @param {import('../view/ui.js').Log} options.log
   * @param {(pc: RTCPeerConnection) => Promise<void>} [options.beforeAnswer] runs between
   *   applying a remote offer and creating the answer (the relay sets its send tracks there)
   * @param {(sdp: string) => Promise<string>} [options.shapeAnswer] the answer's SDP as it is
   *   to be applied and sent (the relay renumbers the vehicle's codec for its forward)
   */
  constructor({ remote, polite, mayOffer, ice, send, log, beforeAnswer, shapeAnswer }) {
    super();
    this.remote = remote;
    this.polite = polite;
    this.mayOffer = mayOffer;
    this.send = send;
    this.log = log;
    this.beforeAnswer = beforeAnswer;
    this.shapeAnswer = shapeAnswer;
    this.pc = new RTCPeerConnection({
      iceServers: ice.iceServers,
      iceTransportPolicy: ice.iceTransportPolicy,
    });
    this.pc.addEventListener('icecandidate', ({ candidate }) => {
      // The end-of-candidates null is not needed by the other side and not worth a message.
      if (candidate) this.#signal({ type: 'candidate', to: remote, candidate: candidate.toJSON() });
    });
    this.pc.addEventListener('negotiationneeded', () => this.#offer());
    this.pc.addEventListener('track', (event) =>
      this.dispatchEvent(new CustomEvent('track', { detail: event })),
    );
    this.pc.addEventListener('datachannel', ({ channel }) =>
      this.dispatchEvent(new CustomEvent('datachannel', { detail: channel })),
    );
    this.pc.addEventListener('connectionstatechange', () => {
      this.log.info(`connection with ${remote}: ${this.pc.connectionState}`);
      this.dispatchEvent(new CustomEvent('state', { detail: this.pc.connectionState }));
    });
  }

  get closed() {
    return this.pc.connectionState === 'closed' || this.pc.signalingState === 'closed';
  }

  /** Apply an `offer`, `answer` or `candidate` message from the remote peer (may reject). */
  async handle(msg) {
    if (msg.type === 'offer' || msg.type === 'answer') {
      const sdp = typeof msg.sdp === 'string' ? msg.sdp : msg.sdp?.sdp;
      await this.#description({ type: msg.type, sdp });
    } else if (msg.type === 'candidate') {
      await this.#candidate(msg.candidate);
    }
  }

  close() {
    this.pc.close();
    this.dispatchEvent(new CustomEvent('state', { detail: 'closed' }));
  }

  async #offer() {
    if (!this.mayOffer) {
      this.log.warn(`renegotiation with ${this.remote} needed, but this side never offers`);
      return;
    }
    try {
      this.#makingOffer = true;
      await this.pc.setLocalDescription();
      this.#signal({ type: 'offer', to: this.remote, sdp: this.pc.localDescription.sdp });
    } catch (err) {
      this.log.error(`could not make an offer to ${this.remote}: ${err.message}`);
    } finally {
      this.#makingOffer = false;
    }
  }

  async #description(description) {
    const pc = this.pc;
    const readyForOffer =
      !this.#makingOffer && (pc.signalingState === 'stable' || this.#settingRemoteAnswer);
    const offerCollision = description.type === 'offer' && !readyForOffer;
    this.#ignoreOffer = !this.polite && offerCollision;
    if (this.#ignoreOffer) {
      this.log.warn(`ignored a colliding offer from ${this.remote}`);
      return;
    }
    this.#settingRemoteAnswer = description.type === 'answer';
    try {
      await pc.setRemoteDescription(description);
    } finally {
      this.#settingRemoteAnswer = false;
    }
    if (description.type === 'offer') {
      if (this.beforeAnswer) await this.beforeAnswer(pc);
      if (this.shapeAnswer) {
        const answer = await pc.createAnswer();
        await pc.setLocalDescription({ type: 'answer', sdp: await this.shapeAnswer(answer.sdp) });
      } else await pc.setLocalDescription();
      this.#signal({ type: 'answer', to: this.remote, sdp: pc.localDescription.sdp });
    }
  }

  async #candidate(candidate) {
    if (!candidate) return;
    try {
      await this.pc.addIceCandidate(candidate);
    } catch (err) {
      // Candidates of an offer we ignored are expected to fail; anything else is news.
      if (!this.#ignoreOffer) throw err;
    }
  }

  #signal(msg) {
    try {
      this.send(msg);
    } catch (err) {
      this.log.warn(`could not send ${msg.type} to ${this.remote}: ${err.message}`);
    }
  }
}

/** A malformed or unexpected data-channel message; the reason is sent back to the sender. */
export class BadMessage extends Error {}

/** Send one JSON message if the channel is open; returns whether it was sent. */
export function sendJson(channel, msg) {
  if (channel === null || channel === undefined || channel.readyState !== 'open') return false;
  channel.send(JSON.stringify(msg));
  return true;
}

/**
 * Dispatch a data channel's JSON messages through `handlers` (one per `type`), each message
 * first validated against `schema`: what this side accepts on this channel, generated from
 * app/protocol/channels.py (`SCHEMAS[label][role]` of config.js). Malformed JSON, a type the
 * schema does not accept, a field that breaks it or a handler's BadMessage is logged and
 * answered with `{"type":"error","reason","ref"}` naming the field, never thrown; an `error`
 * from the other side is logged. The handlers must cover exactly the schema's types (but
 * `error`), or this throws at once: a page and the protocol that drifted apart are a bug.
 */
export function serveChannel(channel, handlers, log, schema) {
  const accepted = acceptedTypes(schema);
  const handled = [...Object.keys(handlers), 'error'];
  const missing = accepted.filter((type) => !handled.includes(type));
  const extra = handled.filter((type) => !accepted.includes(type));
  if (missing.length || extra.length) {
    throw new Error(
      `${channel.label}: handlers do not match the protocol ` +
        `(missing ${missing}; not in it ${extra})`,
    );
  }
  const refuse = (reason, ref) => {
    log.warn(`${channel.label}: ${reason}`);
    sendJson(channel, { type: 'error', reason, ref });
  };
  channel.addEventListener('message', (event) => {
    let msg;
    try {
      msg = JSON.parse(event.data);
    } catch {
      refuse(`malformed JSON: ${String(event.data).slice(0, 60)}`, null);
      return;
    }
    if (
      msg === null ||
      typeof msg !== 'object' ||
      Array.isArray(msg) ||
      typeof msg.type !== 'string'
    ) {
      refuse('expected a JSON object with a string field "type"', null);
      return;
    }
    if (!accepted.includes(msg.type)) {
      refuse(`unknown message type "${msg.type}" on channel "${channel.label}"`, msg.type);
      return;
    }
    const problems = validate(schema, msg);
    if (problems.length) {
      refuse(`bad ${msg.type}: ${describeProblems(problems)}`, msg.type);
      return;
    }
    if (msg.type === 'error') {
      const about = msg.ref ? ` (about ${msg.ref})` : '';
      log.error(`${channel.label}: the other side says: ${msg.reason}${about}`);
      return;
    }
    try {
      handlers[msg.type](msg);
    } catch (err) {
      if (!(err instanceof BadMessage)) throw err;
      refuse(err.message, msg.type);
    }
  });
}

/**
 * The offering side's connection to the room's relay (vehicle and client pages): follows the
 * roster, so whichever joins first, a relay that arrives, leaves or is reloaded gets a fresh
 * connection. `setup(peer)` adds the tracks and data channels before the first offer.
 * Events: `peer` (detail: the new Peer), `lost` (detail: reason, the old connection is gone).
 */
export class RelayLink extends EventTarget {
  #syncing = false;
  #again = false;

  constructor(room, { log, setup }) {
    super();
    this.room = room;
    this.log = log;
    this.setup = setup;
    this.peer = null;
    room.addEventListener('roster', () => this.sync());
    room.addEventListener('peerleft', (event) => {
      if (this.peer !== null && event.detail === this.peer.remote)
        this.#drop(`relay ${event.detail} left`);
    });
    room.addEventListener('signal', (event) => this.#onSignal(event.detail));
  }

  /** Bring the connection in line with the roster (idempotent; safe to call at any time). */
  sync() {
    if (this.#syncing) {
      this.#again = true;
      return;
    }
    this.#syncing = true;
    try {
      do {
        this.#again = false;
        this.#syncOnce();
      } while (this.#again);
    } finally {
      this.#syncing = false;
    }
  }

  #syncOnce() {
    const relay = this.room.relay;
    const current = this.peer;
    if (current !== null && relay !== undefined && current.remote === relay.name && !current.closed)
      return;
    if (current !== null)
      this.#drop(relay === undefined ? 'no relay in the room' : 'relay changed');
    if (relay === undefined) return;
    this.log.info(`connecting to relay ${relay.name}`);
    const peer = new Peer({
      remote: relay.name,
      polite: false,
      mayOffer: true,
      ice: this.room.ice,
      send: (msg) => this.room.send(msg),
      log: this.log,
    });
    peer.addEventListener('state', (event) => {
      if (event.detail === 'failed' && this.peer === peer) {
        this.#drop(`connection to ${peer.remote} failed`);
        this.sync();
      }
    });
    this.peer = peer;
    this.dispatchEvent(new CustomEvent('peer', { detail: peer }));
    this.setup(peer);
  }

  #drop(reason) {
    const peer = this.peer;
    if (peer === null) return;
    this.peer = null;
    peer.close();
    this.log.info(`connection to ${peer.remote} closed: ${reason}`);
    this.dispatchEvent(new CustomEvent('lost', { detail: reason }));
  }

  #onSignal(msg) {
    if (!['offer', 'answer', 'candidate'].includes(msg.type)) return;
    if (this.peer === null || msg.from !== this.peer.remote) {
      this.log.warn(
        `ignored ${msg.type} from ${msg.from}: not the relay this page is connected to`,
      );
      return;
    }
    this.peer
      .handle(msg)
      .catch((err) => this.log.error(`negotiation with ${msg.from} failed: ${err.message}`));
  }
}

/**
 * Ask a video receiver to show each frame as soon as it is decoded: the smallest jitter buffer
 * (jitterBufferTarget, standard) and no playout delay (playoutDelayHint, Chromium's older name,
 * which also selects its low-latency renderer). A robot acts on the freshest frame, so a little
 * smoothness is traded for latency.
 */
export function preferLowLatency(receiver) {
  receiver.jitterBufferTarget = 0;
  if ('playoutDelayHint' in receiver) receiver.playoutDelayHint = 0;
}
