// RTP payload types of the video in an SDP, for the relay's pass-through forward
// (net/video-forward.js): the relay sends a client the vehicle's encoded frames as they came,
// each with the payload type the vehicle gave it, so the client must receive that codec at that
// number. The vehicle's numbers are the relay's answer's (an answer lists what its author
// receives, and the vehicle sends with them: aiortc and libwebrtc both take the answer's
// numbers); a client's are its offer's. Chromium numbers its codecs the same way in every offer,
// so the relay answers the vehicle with the numbers its own offers give the vehicle's codec
// (`alignAnswer`), and a Chromium client then receives it at the same number. Pure: text in,
// text out.

// Not codecs a frame is encoded with: retransmissions, redundancy and error correction.
const CARRIERS = new Set(['rtx', 'red', 'ulpfec', 'flexfec-03']);

/**
 * The video codecs of the first video section of `sdp`, in the section's order:
 * [{pt, mimeType: 'video/VP8', clockRate, fmtp: normalised parameters or ''}].
 */
export function videoCodecs(sdp) {
  const section = videoSection(sdp.split(/\r?\n/));
  if (section === null) return [];
  const [mLine, ...attributes] = section.lines;
  const order = mLine.split(' ').slice(3).map(Number);
  const codecs = new Map(
    order.map((pt) => [pt, { pt, mimeType: null, clockRate: null, fmtp: '' }]),
  );
  for (const line of attributes) {
    let match = /^a=rtpmap:(\d+) ([^/]+)\/(\d+)/.exec(line);
    if (match && codecs.has(Number(match[1]))) {
      Object.assign(codecs.get(Number(match[1])), {
        mimeType: `video/${match[2]}`,
        clockRate: Number(match[3]),
      });
    }
    match = /^a=fmtp:(\d+) (.*)$/.exec(line);
    if (match && codecs.has(Number(match[1])))
      codecs.get(Number(match[1])).fmtp = normaliseFmtp(match[2]);
  }
  return [...codecs.values()].filter((codec) => codec.mimeType !== null);
}

/** Whether two codecs (of `videoCodecs`) are the same encoding: name, clock rate, parameters. */
function sameCodec(a, b) {
  return (
    a.mimeType.toLowerCase() === b.mimeType.toLowerCase() &&
    a.clockRate === b.clockRate &&
    a.fmtp === b.fmtp
  );
}

/** The codec a sender of this SDP's video encodes with: its first one that is not a carrier. */
function sentCodec(codecs) {
  return codecs.find((codec) => !CARRIERS.has(codec.mimeType.slice(6).toLowerCase())) ?? null;
}

/**
 * `answer` with the payload type of the codec the vehicle will send (its first) exchanged with
 * the one `local` (this browser's own numbering, from an offer of its own) gives that codec, so
 * that a client of the same browser receives it at the same number; unchanged when `local` has
 * no such codec or the numbers already agree.
 */
export function alignAnswer(answer, local) {
  const sent = sentCodec(videoCodecs(answer));
  const wanted = sent && local.find((codec) => sameCodec(codec, sent));
  if (!wanted || wanted.pt === sent.pt) return answer;
  return swapPayloadTypes(answer, sent.pt, wanted.pt);
}

/**
 * Whether frames of payload type `pt`, encoded with the vehicle's codec of that number
 * (`vehicle`: the vehicle's codecs), decode at a client that receives `client`'s codecs.
 */
export function passesThrough(pt, vehicle, client) {
  const sent = vehicle.find((codec) => codec.pt === pt);
  const received = client.find((codec) => codec.pt === pt);
  return sent !== undefined && received !== undefined && sameCodec(sent, received);
}

/** `sdp` with payload types `a` and `b` exchanged everywhere in its first video section. */
function swapPayloadTypes(sdp, a, b) {
  const eol = sdp.includes('\r\n') ? '\r\n' : '\n';
  const lines = sdp.split(/\r?\n/);
  const section = videoSection(lines);
  if (section === null) return sdp;
  const swap = (n) => (Number(n) === a ? String(b) : Number(n) === b ? String(a) : n);
  for (let i = section.start; i < section.start + section.lines.length; i += 1) {
    const line = lines[i];
    if (line.startsWith('m=video ')) {
      const parts = line.split(' ');
      lines[i] = [...parts.slice(0, 3), ...parts.slice(3).map(swap)].join(' ');
      continue;
    }
    const match = /^a=(rtpmap|fmtp|rtcp-fb):(\d+)( .*)?$/.exec(line);
    if (match === null) continue;
    let rest = match[3] ?? '';
    // What refers to another payload type: rtx's `apt=` and a redundancy list `96/96`.
    if (match[1] === 'fmtp')
      rest = rest
        .replace(/apt=(\d+)/, (_, n) => `apt=${swap(n)}`)
        .replace(/^ (\d+(?:\/\d+)+)$/, (_, list) => ` ${list.split('/').map(swap).join('/')}`);
    lines[i] = `a=${match[1]}:${swap(match[2])}${rest}`;
  }
  return lines.join(eol);
}

function videoSection(lines) {
  const start = lines.findIndex((line) => line.startsWith('m=video '));
  if (start < 0) return null;
  let end = lines.findIndex((line, i) => i > start && line.startsWith('m='));
  if (end < 0) end = lines.length;
  return { start, lines: lines.slice(start, end) };
}

function normaliseFmtp(params) {
  return params
    .split(';')
    .map((param) => param.trim())
    .filter(Boolean)
    .sort()
    .join(';');
}
