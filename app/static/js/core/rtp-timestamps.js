// One RTP timeline for the clients across vehicles. The relay passes the vehicle's encoded
// frames on to each client's sender as they are (worker/forward-worker.js), timestamps
// included; a vehicle that comes back (a reload) starts a new stream at a random timestamp.
// Where that timestamp is behind the last one a client received, and the new stream's VP8
// picture ids are behind too, the client's receiver drops every frame of the new stream, key
// frames included: its video stays frozen. So each stream's timestamps are shifted to follow the
// last one forwarded. Tested in e2e/test_rtp_timestamps_js.py and, with a vehicle reloaded
// again and again, in e2e/test_join_order.py.

/** The step from the last frame of one stream to the first of the next: a frame at 30/s on the
 * 90 kHz video clock. */
const STREAM_STEP = 3000;

export class ContinuousTimestamps {
  #stream = null; // the stream whose frames come now (any value compared with ===)
  #shift = 0; // added to that stream's timestamps, modulo 2^32
  #last = null; // the last timestamp handed out

  /**
   * The timestamp to forward a frame of `stream` with: its own where it is the first stream,
   * shifted for a later stream so that its first frame comes STREAM_STEP after the last frame.
   * @param {unknown} stream
   * @param {number} rtpTimestamp the frame's own, 0 .. 2^32 - 1
   * @returns {number}
   */
  next(stream, rtpTimestamp) {
    if (stream !== this.#stream) {
      this.#stream = stream;
      this.#shift = this.#last === null ? 0 : (this.#last + STREAM_STEP - rtpTimestamp) >>> 0;
    }
    this.#last = (rtpTimestamp + this.#shift) >>> 0;
    return this.#last;
  }
}
