// The relay's peer connections, one per remote peer of its room: it answers the offers of the
// vehicle and of the clients, takes in the vehicle's video and forwards it to every client, and
// opens the vehicle's and the clients' data channels to the page. One vehicle is served at a
// time (core/relay-seats.js): another vehicle's offer is ignored while the seat is taken, and a
// peer's departure clears only what that peer held. The video goes to a client as the vehicle
// encoded it where the browser allows it and the client decodes the vehicle's codec
// (net/video-forward.js, 'pass-through'); otherwise the relay encodes the decoded video again
// for that client, at a smaller size ('re-encode').
import { CHANNELS, PROTOCOL, SCHEMAS } from '../config.js';
import { Seat } from '../core/relay-seats.js';
import { LinkMeter } from './link-health.js';
import { Peer, preferLowLatency, sendJson, serveChannel } from './peer.js';
import { VideoForward } from './video-forward.js';

/**
 * Events (CustomEvent detail):
 *   `vehicletrack`  the served vehicle's video track, or null when it left
 *   `vehicle`       the served vehicle's name once its autopilot channel is open, null when closed
 *   `control`       a client's name, when its control channel opened
 *   `controlclosed` a client's name, when the control channel of its connection closed (the
 *                   link dropped with the connection still there)
 *   `left`          {name, role}: a peer's connection is gone
 *   `changed`       the connections or their channels changed (for the page's peer list)
 */
export class RelayLinks extends EventTarget {
  #peers = new Map(); // remote name -> {peer, role, channel, stateChannel, meter, forward}
  #signalQueues = new Map(); // remote name -> promise of its last signaling message handled
  #seat = new Seat('the relay');

  /**
   * @param {object} options
   * @param {import('./room.js').RoomSession} options.room the relay's room (roster, ICE, send)
   * @param {import('../view/ui.js').Log} options.log
   * @param {(name: string) => object} options.controlHandlers a client's control-channel
   *   handlers, by message type (serveChannel)
   * @param {{pose: (msg: object) => void, frameTimes: (msg: object) => void}}
   *   options.vehicleHandlers the served vehicle's messages, validated: its pose, the capture
   *   times of its frames
   */
  constructor({ room, log, controlHandlers, vehicleHandlers }) {
    super();
    this.room = room;
    this.log = log;
    this.controlHandlers = controlHandlers;
    this.vehicleHandlers = vehicleHandlers;
    this.vehicleTrack = null; // the served vehicle's video track
    this.vehicle = null; // the served vehicle's name while its autopilot channel is open
    // The pass-through forward, or null where this browser cannot pass encoded frames on.
    this.forward = VideoForward.supported ? new VideoForward({ log }) : null;
    this.forward?.addEventListener('mode', ({ detail: { name, passing } }) =>
      this.#onForwardMode(name, passing),
    );
    if (this.forward === null) {
      log.info("this browser has no encoded transforms: the relay encodes each client's video");
    }
  }

  /** How each client gets the video: {name: 'pass-through' | 're-encode'}. */
  get forwards() {
    return Object.fromEntries(
      this.#clientEntries().map((entry) => [entry.peer.remote, entry.forward]),
    );
  }

  /** The names of the clients connected. */
  get clients() {
    return this.#clientEntries().map((entry) => entry.peer.remote);
  }

  /** One line per connection, for a person to read. */
  describe() {
    return [...this.#peers.entries()].map(([name, entry]) => {
      const open = entry.channel ? ', channel open' : '';
      return `${entry.role} ${name} (${entry.peer.pc.connectionState}${open})`;
    });
  }

  /** An offer or a candidate from `msg.from`, handled in the order that sender sent them. */
  signal(msg) {
    const run = async () => {
      if (msg.type === 'offer') await this.#onOffer(msg);
      else await this.#peers.get(msg.from)?.peer.handle(msg);
    };
    const previous = this.#signalQueues.get(msg.from) ?? Promise.resolve();
    const next = previous
      .then(run)
      .catch((err) => this.log.error(`negotiation with ${msg.from} failed: ${err.message}`));
    this.#signalQueues.set(msg.from, next);
  }

  /** `name` left the room: its connection goes, and what it held with it. */
  left(name) {
    this.close(name, 'left the room');
    this.#signalQueues.delete(name);
  }

  /** Close every connection (this relay leaves its room). */
  closeAll(reason) {
    for (const name of [...this.#peers.keys()]) this.close(name, reason);
  }

  /**
   * Close the connection with `name`. Only what it held goes with it: the vehicle seat and
   * video when it was the served vehicle.
   */
  close(name, reason) {
    const entry = this.#peers.get(name);
    if (entry === undefined) return;
    this.#peers.delete(name);
    entry.peer.close();
    if (entry.role === 'client') this.forward?.removeClient(name);
    this.log.info(`connection with ${name} closed: ${reason}`);
    if (entry.role === 'vehicle' && this.#seat.release(name)) {
      this.#setVehicle(null);
      this.#setVehicleTrack(null);
    }
    this.#emit('left', { name, role: entry.role });
    this.#emit('changed');
  }

  /**
   * Send `msg` to the served vehicle: on the lossy state channel when `lossy` and it is open
   * (latest wins), else on the reliable one. Returns whether it was sent.
   */
  sendToVehicle(msg, { lossy = false } = {}) {
    const vehicle = this.#vehicleEntry();
    return sendJson(lossy ? (vehicle?.stateChannel ?? vehicle?.channel) : vehicle?.channel, msg);
  }

  /** Send `msg` to client `name` if its control channel is open; returns whether it was sent. */
  sendTo(name, msg) {
    const entry = this.#peers.get(name);
    return entry?.role === 'client' && sendJson(entry.channel, msg);
  }

  /** Send `msg` to every client whose control channel is open. */
  broadcast(msg) {
    for (const client of this.#clientEntries()) sendJson(client.channel, msg);
  }

  /** The vehicle → relay link's figures (link health), or null without a vehicle. */
  async readVehicleLink() {
    const meter = this.#vehicleEntry()?.meter;
    return meter == null ? null : meter.read();
  }

  #vehicleEntry() {
    const holder = this.#seat.holder;
    return holder === null ? undefined : this.#peers.get(holder);
  }

  #clientEntries() {
    return [...this.#peers.values()].filter((entry) => entry.role === 'client');
  }

  async #onOffer(msg) {
    const role = this.room.roster.find((peer) => peer.name === msg.from)?.role;
    if (role !== 'vehicle' && role !== 'client') {
      this.log.warn(`ignored an offer from ${msg.from}: not a vehicle or client of this room`);
      return;
    }
    if (role === 'vehicle') {
      const refused = this.#seat.claim(msg.from);
      if (refused !== null) {
        this.log.warn(`ignored an offer from vehicle ${msg.from}: ${refused}`);
        return;
      }
    }
    let entry = this.#peers.get(msg.from);
    if (entry === undefined || entry.peer.closed) entry = this.#open(msg.from, role);
    try {
      await entry.peer.handle(msg);
    } catch (err) {
      // A peer that reloaded offers a new DTLS identity to our old connection: start afresh.
      this.log.warn(
        `offer from ${msg.from} does not fit the old connection (${err.message}); ` +
          'starting a new one',
      );
      this.close(msg.from, 'replaced');
      if (role === 'vehicle') this.#seat.claim(msg.from);
      entry = this.#open(msg.from, role);
      await entry.peer.handle(msg);
    }
  }

  #open(name, role) {
    const peer = new Peer({
      remote: name,
      polite: true,
      mayOffer: false,
      ice: this.room.ice,
      send: (msg) => this.room.send(msg),
      log: this.log,
      beforeAnswer: role === 'client' ? () => this.#sendVideoTo(entry) : undefined,
      // The vehicle sends its codec with the number the clients receive it at (pass-through).
      shapeAnswer:
        role === 'vehicle' && this.forward !== null
          ? (sdp) => this.forward.answerVehicle(sdp)
          : undefined,
    });
    // The vehicle's link is measured here, where its video is received (link health).
    const entry = {
      peer,
      role,
      channel: null,
      stateChannel: null,
      meter: role === 'vehicle' ? new LinkMeter(peer.pc) : null,
      // A client's video: 'pass-through' or 're-encode', once its sender is set up.
      forward: null,
    };
    peer.addEventListener('track', (event) => {
      const { track, receiver } = event.detail;
      if (role === 'vehicle' && track.kind === 'video' && this.#seat.holder === name) {
        // Goals are worth most when fresh: a decoded frame is shown (and analysed) at once.
        preferLowLatency(receiver);
        this.forward?.receiveVehicle(receiver);
        this.#setVehicleTrack(track);
      }
    });
    peer.addEventListener('datachannel', (event) => this.#onDataChannel(entry, event.detail));
    peer.addEventListener('state', (event) => {
      if (event.detail === 'failed' && this.#peers.get(name) === entry) {
        this.close(name, 'connection failed');
      }
      // A client that passes through starts with the vehicle's next key frame.
      if (event.detail === 'connected' && entry.forward === 'pass-through') {
        this.forward.requestKeyFrame();
      }
      this.#emit('changed');
    });
    this.#peers.set(name, entry);
    this.#emit('changed');
    return entry;
  }

  #setVehicleTrack(track) {
    this.vehicleTrack = track;
    if (track !== null) this.log.info('vehicle video arrived; forwarding it to the clients');
    for (const client of this.#clientEntries()) this.#resendVideoTo(client);
    this.#emit('vehicletrack', track);
  }

  #setVehicle(name) {
    if (this.vehicle === name) return;
    this.vehicle = name;
    this.#emit('vehicle', name);
  }

  /**
   * Send the vehicle's video (or nothing yet) on every video transceiver of a client's link:
   * passed through, or the decoded track encoded again (the sender's track).
   */
  async #sendVideoTo(entry) {
    const pc = entry.peer.pc;
    for (const transceiver of pc.getTransceivers()) {
      if (transceiver.stopped || transceiver.receiver.track.kind !== 'video') continue;
      // The client offers recvonly; answering sendonly lets the track change later with no
      // renegotiation, which this side could not start anyway.
      if (pc.signalingState === 'have-remote-offer') transceiver.direction = 'sendonly';
      if (entry.forward === null) {
        // Its encoded streams must exist before the sender ever has a track.
        if (this.forward !== null)
          this.forward.addClient(entry.peer.remote, transceiver.sender, pc.remoteDescription.sdp);
        entry.forward = this.forward !== null ? 'pass-through' : 're-encode';
      }
      if (entry.forward === 'pass-through') {
        await transceiver.sender.replaceTrack(null);
        continue;
      }
      // Chromium's default degradation (balanced) on purpose: see vehicle.js.
      await transceiver.sender.replaceTrack(this.vehicleTrack);
      await forwardSmaller(transceiver.sender);
    }
  }

  #resendVideoTo(entry) {
    this.#sendVideoTo(entry).catch((err) =>
      this.log.error(`could not forward the vehicle's video: ${err.message}`),
    );
  }

  /** The forward found the vehicle's frames do (or do not) decode at client `name`. */
  #onForwardMode(name, passing) {
    const entry = this.#peers.get(name);
    if (entry?.role !== 'client') return;
    const forward = passing ? 'pass-through' : 're-encode';
    if (entry.forward === forward) return;
    entry.forward = forward;
    this.log.info(
      passing
        ? `client ${name} gets the vehicle's video as the vehicle encoded it`
        : `client ${name} does not receive the vehicle's codec at its number: encoding for it`,
    );
    this.#resendVideoTo(entry);
  }

  #onDataChannel(entry, channel) {
    const name = entry.peer.remote;
    if (entry.role === 'vehicle' && channel.label === CHANNELS.autopilotState) {
      // Goals go out, pose and capture times come in here: unordered, never retransmitted.
      const schema = SCHEMAS[CHANNELS.autopilotState].relay;
      serveChannel(channel, this.vehicleHandlers, this.log, schema);
      channel.addEventListener('open', () => {
        entry.stateChannel = channel;
      });
      channel.addEventListener('close', () => {
        if (entry.stateChannel === channel) entry.stateChannel = null;
      });
      return;
    }
    if (entry.role === 'vehicle' && channel.label === CHANNELS.autopilot) {
      const schema = SCHEMAS.autopilot.relay;
      serveChannel(channel, { pose: this.vehicleHandlers.pose }, this.log, schema);
      channel.addEventListener('open', () => {
        entry.channel = channel;
        this.log.info(`autopilot channel to vehicle ${name} open`);
        this.#setVehicle(name);
        this.#emit('changed');
      });
    } else if (entry.role === 'client' && channel.label === CHANNELS.control) {
      serveChannel(channel, this.controlHandlers(name), this.log, SCHEMAS.control.relay);
      channel.addEventListener('open', () => {
        entry.channel = channel;
        this.log.info(`control channel to client ${name} open`);
        this.#emit('control', name);
        this.#emit('changed');
      });
    } else {
      this.log.warn(`${entry.role} ${name} opened an unexpected data channel "${channel.label}"`);
      return;
    }
    channel.addEventListener('close', () => {
      const current = entry.channel === channel;
      if (current) entry.channel = null;
      if (entry.role === 'vehicle' && this.vehicle === name) this.#setVehicle(null);
      // A connection closed here (close()) is no longer in #peers and said `left` already.
      if (entry.role === 'client' && current && this.#peers.get(name) === entry) {
        this.#emit('controlclosed', name);
      }
      this.#emit('changed');
    });
  }

  #emit(type, detail = null) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }
}

/**
 * Encode the forward to a client (where it is not passed through) at
 * PROTOCOL.clientForwardScaleDown of the vehicle's size per side: the encode is the relay's
 * largest cost after the cascade (docs/bench/relay-cost.md).
 */
async function forwardSmaller(sender) {
  const params = sender.getParameters();
  // Before the answer the sender may have no encoding yet; sendVideoOn runs again with the track.
  if (params.encodings.length === 0) return;
  const scale = PROTOCOL.clientForwardScaleDown;
  if (params.encodings.every((encoding) => encoding.scaleResolutionDownBy === scale)) return;
  for (const encoding of params.encodings) encoding.scaleResolutionDownBy = scale;
  await sender.setParameters(params);
}
