// The relay's pass-through forward, the page's side (its worker: worker/forward-worker.js): the
// vehicle's encoded frames go to the clients as they came, with no decode and encode for them
// (the relay still decodes the vehicle's video for its analysis). It needs Chromium's encoded
// transforms on both sides: RTCRtpScriptTransform on the vehicle's receiver, whose transformer
// can ask the vehicle for a key frame, and createEncodedStreams on each client's sender, whose
// streams take frames read elsewhere (a script transform's take only its own). Where either is
// missing, `VideoForward.supported` is false and the relay encodes the video for each client
// (net/relay-links.js). A client needs a key frame to start: one is asked for when it connects,
// and whenever its browser asks the relay for one (its PLI and FIR counts, polled).
import { alignAnswer, videoCodecs } from '../core/payload-types.js';

// How often each passing client's sender is asked whether its client lost the picture.
const KEY_FRAME_POLL_MS = 500;

/**
 * Events: `mode` (detail: {name, passing}): whether client `name` now gets the vehicle's frames
 * as they are (false: they do not decode there, and the relay must encode for it).
 */
export class VideoForward extends EventTarget {
  #clients = new Map(); // name -> {sender, passing, keyFrameRequests}

  /** Whether this browser can pass encoded frames from a receiver to other senders. */
  static get supported() {
    return (
      typeof RTCRtpScriptTransform === 'function' &&
      typeof RTCRtpSender.prototype.createEncodedStreams === 'function'
    );
  }

  constructor({ log }) {
    super();
    this.log = log;
    this.worker = new Worker(new URL('../worker/forward-worker.js', import.meta.url), {
      type: 'module',
    });
    this.worker.addEventListener('message', ({ data }) => this.#onMode(data));
    this.worker.addEventListener('error', (event) =>
      log.error(`the video forward's worker failed: ${event.message}`),
    );
    // This browser's own numbering of its codecs, which its clients' offers use too.
    this.ownCodecs = ownCodecs();
    setInterval(() => this.#watchKeyFrameRequests(), KEY_FRAME_POLL_MS);
  }

  /** The relay's answer to the vehicle, renumbered to send its codec as clients receive it. */
  async answerVehicle(sdp) {
    const aligned = alignAnswer(sdp, await this.ownCodecs);
    this.worker.postMessage({ type: 'vehicleCodecs', codecs: videoCodecs(aligned) });
    return aligned;
  }

  /** The vehicle's video receiver: its frames pass through the worker from now on. */
  receiveVehicle(receiver) {
    receiver.transform = new RTCRtpScriptTransform(this.worker, {});
  }

  /**
   * Forward to client `name` on `sender` (before it has a track: the streams must be made
   * first), which receives the codecs of its `offer` (SDP).
   */
  addClient(name, sender, offer) {
    const { readable, writable } = sender.createEncodedStreams();
    const codecs = videoCodecs(offer);
    this.worker.postMessage({ type: 'addSink', name, readable, writable, codecs }, [
      readable,
      writable,
    ]);
    this.#clients.set(name, { sender, passing: null, keyFrameRequests: 0 });
  }

  removeClient(name) {
    if (!this.#clients.delete(name)) return;
    this.worker.postMessage({ type: 'removeSink', name });
  }

  /** Ask the vehicle for a key frame (a client connected and has no picture yet). */
  requestKeyFrame() {
    this.worker.postMessage({ type: 'keyFrame' });
  }

  #onMode({ name, passing }) {
    const client = this.#clients.get(name);
    if (client === undefined) return;
    client.passing = passing;
    if (passing) this.requestKeyFrame();
    this.dispatchEvent(new CustomEvent('mode', { detail: { name, passing } }));
  }

  /** A passing client whose browser asked the relay for a key frame: ask the vehicle. */
  async #watchKeyFrameRequests() {
    for (const client of this.#clients.values()) {
      if (!client.passing) continue;
      let requests = 0;
      try {
        (await client.sender.getStats()).forEach((stats) => {
          if (stats.type === 'outbound-rtp')
            requests += (stats.pliCount ?? 0) + (stats.firCount ?? 0);
        });
      } catch {
        continue; // its connection closed meanwhile
      }
      if (requests > client.keyFrameRequests) this.requestKeyFrame();
      client.keyFrameRequests = requests;
    }
  }
}

/** The video codecs of an offer this browser makes, with its own payload types. */
async function ownCodecs() {
  const pc = new RTCPeerConnection();
  try {
    pc.addTransceiver('video', { direction: 'recvonly' });
    return videoCodecs((await pc.createOffer()).sdp);
  } finally {
    pc.close();
  }
}
