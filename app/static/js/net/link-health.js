// Link health (docs/architecture.md, "What happened, what is happening"): one link's received video
// from two getStats() reports a period apart — round trip, packet loss, frames per second,
// resolution and the selected candidate pair's type — and the warnings the client page shows. The
// thresholds come from app/protocol/link_health.py through the page's config (`PROTOCOL.health`).

const RELAYED_FIRST = ['relay', 'srflx', 'prflx', 'host'];

/** The inbound video, the selected candidate pair and its two candidates of one report. */
function pick(report) {
  const stats = [...report.values()];
  const video = stats.find((s) => s.type === 'inbound-rtp' && s.kind === 'video') ?? null;
  const transport = stats.find((s) => s.type === 'transport' && s.selectedCandidatePairId);
  const pair =
    (transport && report.get(transport.selectedCandidatePairId)) ??
    stats.find((s) => s.type === 'candidate-pair' && s.nominated && s.state === 'succeeded') ??
    null;
  const local = pair ? report.get(pair.localCandidateId) : undefined;
  const remote = pair ? report.get(pair.remoteCandidateId) : undefined;
  return { video, pair, types: [local?.candidateType, remote?.candidateType] };
}

/**
 * {rttMs, lossPct, fps, width, height, candidate} of the link whose receiver gave `report` now
 * and `previous` one period ago (null on the first reading: no rates yet). Loss counts the
 * packets lost among those due over the period; the candidate type is the pair's most relayed
 * end (a relay at either end makes it a relayed link).
 */
function linkFigures(previous, report) {
  const now = pick(report);
  const before = previous === null ? null : pick(previous);
  const video = now.video;
  const rtt = now.pair?.currentRoundTripTime;
  const figures = {
    rttMs: typeof rtt === 'number' ? rtt * 1000 : null,
    lossPct: null,
    fps: null,
    width: video?.frameWidth ?? null,
    height: video?.frameHeight ?? null,
    candidate: RELAYED_FIRST.find((type) => now.types.includes(type)) ?? null,
  };
  const old = before?.video;
  if (video && old && video.timestamp > old.timestamp) {
    const lost = Math.max(0, (video.packetsLost ?? 0) - (old.packetsLost ?? 0));
    const received = Math.max(0, (video.packetsReceived ?? 0) - (old.packetsReceived ?? 0));
    figures.lossPct = lost + received > 0 ? (100 * lost) / (lost + received) : 0;
    const frames = (video.framesDecoded ?? 0) - (old.framesDecoded ?? 0);
    figures.fps = Math.max(0, (frames * 1000) / (video.timestamp - old.timestamp));
  }
  return figures;
}

/** The warnings one link's figures call for (`limits`: {maxLossPct, maxRttMs}). */
export function warnings(name, figures, limits) {
  const found = [];
  if (figures === null) return found;
  if (figures.lossPct !== null && figures.lossPct > limits.maxLossPct) {
    found.push(
      `${name}: ${figures.lossPct.toFixed(1)} % packet loss (over ${limits.maxLossPct} %)`,
    );
  }
  if (figures.rttMs !== null && figures.rttMs > limits.maxRttMs) {
    found.push(`${name}: round trip ${Math.round(figures.rttMs)} ms (over ${limits.maxRttMs} ms)`);
  }
  return found;
}

/**
 * Reads one RTCPeerConnection's stats every call of `read()`, keeping the last report for the
 * rates; `figures` is the latest result (null before the first reading).
 */
export class LinkMeter {
  #previous = null;

  constructor(pc) {
    this.pc = pc;
    this.figures = null;
  }

  async read() {
    const report = await this.pc.getStats();
    this.figures = linkFigures(this.#previous, report);
    this.#previous = report;
    return this.figures;
  }
}
