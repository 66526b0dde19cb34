"""core/payload-types.js, in a real page: the video codecs of an SDP, the relay's answer to the
vehicle renumbered to this browser's own numbering, and whether a client decodes what passes
through. The answer is the relay's (Chromium's) answer to the Python agent's (aiortc's) offer,
which numbers VP8 97 where Chromium's own offers number it 96."""

from __future__ import annotations

from typing import Any

import pytest
from playwright.sync_api import Browser

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

H264 = "level-asymmetry-allowed=1;packetization-mode=1;profile-level-id=42001f"
ANSWER = "\r\n".join(
    [
        "v=0",
        "o=- 4 2 IN IP4 127.0.0.1",
        "s=-",
        "t=0 0",
        "a=group:BUNDLE 0 1",
        "m=video 9 UDP/TLS/RTP/SAVPF 97 98 99 100 96",
        "c=IN IP4 0.0.0.0",
        "a=mid:0",
        "a=recvonly",
        "a=rtpmap:97 VP8/90000",
        "a=rtcp-fb:97 nack pli",
        "a=rtpmap:98 rtx/90000",
        "a=fmtp:98 apt=97",
        "a=rtpmap:99 H264/90000",
        f"a=fmtp:99 {H264}",
        "a=rtpmap:100 rtx/90000",
        "a=fmtp:100 apt=99",
        "a=rtpmap:96 red/90000",
        "a=fmtp:96 99/99",
        "m=application 9 UDP/DTLS/SCTP webrtc-datachannel",
        "a=mid:1",
        "a=sctp-port:5000",
        "",
    ]
)

# The answer's codecs, Chromium's own, the answer aligned to them, and the checks, in the page.
CHECKS = """(answer) => {
  const { videoCodecs, alignAnswer, passesThrough } = window['payload-types'];
  const pc = new RTCPeerConnection();
  pc.addTransceiver('video', { direction: 'recvonly' });
  return pc.createOffer().then(({ sdp }) => {
    pc.close();
    const own = videoCodecs(sdp);
    const aligned = alignAnswer(answer, own);
    const ownVp8 = own.find((codec) => codec.mimeType === 'video/VP8').pt;
    return {
      codecs: videoCodecs(answer),
      ownVp8,
      aligned,
      alignedCodecs: videoCodecs(aligned),
      // Each vehicle frame carries its payload type; the client receives Chromium's numbers.
      passesAligned: passesThrough(ownVp8, videoCodecs(aligned), own),
      passesUnaligned: passesThrough(97, videoCodecs(answer), own),
      passesUnknown: passesThrough(111, videoCodecs(aligned), own),
      // Aligned back to the answer's own numbers: the exchange undone, nothing else touched.
      alignedBack: alignAnswer(aligned, videoCodecs(answer)),
      unchanged: alignAnswer(answer, []),
    };
  });
}"""


def test_the_answer_is_renumbered_to_the_browser_s_own_and_then_passes_through(
    server: RunningServer, browser: Browser
) -> None:
    with module_page(server, browser, "core/payload-types") as page:
        found: dict[str, Any] = page.evaluate(CHECKS, ANSWER)
    codecs = found["codecs"]
    # In the m-line's order, the application section left out, parameters read.
    assert [(c["pt"], c["mimeType"]) for c in codecs] == [
        (97, "video/VP8"),
        (98, "video/rtx"),
        (99, "video/H264"),
        (100, "video/rtx"),
        (96, "video/red"),
    ]
    assert codecs[1]["fmtp"] == "apt=97" and codecs[2]["fmtp"] == H264

    vp8 = found["ownVp8"]
    aligned = {c["mimeType"] + c["fmtp"]: c["pt"] for c in found["alignedCodecs"]}
    # VP8, the codec the vehicle sends (its first), now has Chromium's number, and its
    # retransmissions point at it; whatever held that number before took VP8's old one.
    assert aligned["video/VP8"] == vp8
    assert found["alignedCodecs"][0]["pt"] == vp8
    assert aligned[f"video/rtxapt={vp8}"] == 98
    if vp8 == 96:
        # The redundancy codec that held 96 moved to 97, its list kept pointing at H264.
        assert aligned["video/red99/99"] == 97
        assert "a=rtcp-fb:96 nack pli" in found["aligned"]
    # Nothing outside the video section changes.
    assert found["aligned"].split("m=application")[1] == ANSWER.split("m=application")[1]

    assert found["passesAligned"] is True
    assert found["passesUnaligned"] is (vp8 == 97)
    assert found["passesUnknown"] is False
    assert found["alignedBack"] == ANSWER
    assert found["unchanged"] == ANSWER
