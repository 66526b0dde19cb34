"""The vehicle's RTCPeerConnection to the room's relay (aiortc).

The vehicle is always the offerer (docs/architecture.md, "Signaling protocol"): it adds its
video track, opens the reliable ``autopilot`` and the lossy ``autopilot-state`` data channels
(``app.protocol.channels``) and sends an offer; the relay answers and trickles its candidates.
aiortc gathers its own candidates before the offer goes out, so they ride inside the SDP. A link
is used once: when it fails or the relay goes away the agent closes it and makes a new one.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from typing import Any

from aiortc import (
    MediaStreamTrack,
    RTCConfiguration,
    RTCDataChannel,
    RTCIceServer,
    RTCIceTransportPolicy,
    RTCPeerConnection,
    RTCSessionDescription,
)
from aiortc.sdp import candidate_from_sdp

from app.protocol.channels import (
    AUTOPILOT_CHANNEL,
    AUTOPILOT_STATE_CHANNEL,
    STATE_CHANNEL_MAX_RETRANSMITS,
    STATE_CHANNEL_ORDERED,
    ChannelMessage,
    dump,
)
from app.protocol.signaling import IceTransportPolicy

log = logging.getLogger(__name__)

SendSignal = Callable[[dict[str, Any]], Awaitable[None]]


class RelayLink:
    """One peer connection from the vehicle to the relay named ``relay``.

    ``on_message(link, text)`` gets each data-channel message (either channel);
    ``on_down(link, reason)`` is called once when the connection fails, closes or the reliable
    channel closes. ``ice_transport_policy="relay"`` keeps to relayed candidates (TURN).
    """

    def __init__(
        self,
        relay: str,
        track: MediaStreamTrack,
        send_signal: SendSignal,
        on_message: Callable[[RelayLink, str], None],
        on_down: Callable[[RelayLink, str], None],
        ice_servers: list[RTCIceServer] | None = None,
        ice_transport_policy: IceTransportPolicy = "all",
    ) -> None:
        self.relay = relay
        self._send_signal = send_signal
        self._on_message = on_message
        self._on_down = on_down
        self._down = False
        self._pending_candidates: list[dict[str, Any] | None] = []
        # An explicit empty list: aiortc's default is a public STUN server, and nothing here
        # may talk to the outside world unless the operator configured it.
        self.pc = RTCPeerConnection(
            RTCConfiguration(
                iceServers=list(ice_servers or []),
                iceTransportPolicy=RTCIceTransportPolicy(ice_transport_policy),
            )
        )
        self.pc.addTrack(track)
        self.channel = self.pc.createDataChannel(AUTOPILOT_CHANNEL)
        self.state_channel = self.pc.createDataChannel(
            AUTOPILOT_STATE_CHANNEL,
            ordered=STATE_CHANNEL_ORDERED,
            maxRetransmits=STATE_CHANNEL_MAX_RETRANSMITS,
        )
        self.connected = asyncio.Event()
        # Called once when the reliable channel opens (the agent records the link as up).
        self.on_up: Callable[[RelayLink], None] | None = None

        # Both channels carry the relay's JSON messages; which one a message came by is no matter.
        for channel in (self.channel, self.state_channel):
            channel.on("message", self._receive)

        @self.channel.on("open")
        def _open() -> None:
            log.info("data channel %r to %s open", AUTOPILOT_CHANNEL, relay)
            self.connected.set()
            if self.on_up is not None:
                self.on_up(self)

        @self.channel.on("close")
        def _channel_closed() -> None:
            self._fail("data channel closed")

        @self.pc.on("connectionstatechange")
        def _state() -> None:
            state = self.pc.connectionState
            log.info("peer connection to %s: %s", relay, state)
            if state in ("failed", "closed"):
                self._fail(f"peer connection {state}")

    async def start(self) -> None:
        """Create the offer (candidates included) and send it to the relay."""
        offer = await self.pc.createOffer()
        await self.pc.setLocalDescription(offer)
        local = self.pc.localDescription
        await self._send_signal({"type": "offer", "to": self.relay, "sdp": local.sdp})
        log.info("offer sent to %s", self.relay)

    async def on_answer(self, sdp: str) -> None:
        """Apply the relay's answer, then the candidates that arrived before it."""
        if self.pc.signalingState != "have-local-offer":
            log.warning(
                "ignoring an answer from %s in state %s", self.relay, self.pc.signalingState
            )
            return
        await self.pc.setRemoteDescription(RTCSessionDescription(sdp=sdp, type="answer"))
        pending, self._pending_candidates = self._pending_candidates, []
        for candidate in pending:
            await self.on_candidate(candidate)

    async def on_candidate(self, init: dict[str, Any] | None) -> None:
        """Add one trickled candidate (RTCIceCandidateInit); None or "" ends the candidates."""
        if self.pc.remoteDescription is None:
            self._pending_candidates.append(init)
            return
        text = (init or {}).get("candidate") or ""
        if not text:
            await self.pc.addIceCandidate(None)
            return
        try:
            candidate = candidate_from_sdp(text.removeprefix("candidate:"))
        except (ValueError, IndexError) as exc:
            log.warning("ignoring an unreadable candidate from %s: %s (%s)", self.relay, text, exc)
            return
        candidate.sdpMid = init.get("sdpMid") if init else None
        candidate.sdpMLineIndex = init.get("sdpMLineIndex") if init else None
        if candidate.sdpMid is None and candidate.sdpMLineIndex is None:
            candidate.sdpMLineIndex = 0
        await self.pc.addIceCandidate(candidate)

    def local_candidate_types(self) -> list[str]:
        """Types of the candidates this side gathered (``relay`` only under the relay policy)."""
        ice = self.pc.sctp.transport.transport if self.pc.sctp is not None else None
        if ice is None:
            return []
        return sorted({c.type for c in ice.iceGatherer.getLocalCandidates()})

    def selected_candidate_type(self) -> str | None:
        """Type of this side's candidate in the nominated pair (host/srflx/relay), or None.

        aiortc exposes no selected pair, so this reads aioice's nominated pair (a private
        attribute): None when it is not there, never a guess.
        """
        ice = self.pc.sctp.transport.transport if self.pc.sctp is not None else None
        connection = getattr(ice, "_connection", None)
        pair = getattr(connection, "_nominated", {}).get(1)
        local = getattr(pair, "local_candidate", None)
        kind = getattr(local, "type", None)
        return kind if isinstance(kind, str) else None

    def send(self, message: ChannelMessage) -> bool:
        """Send a JSON message on the reliable channel; False when it is not open."""
        return _send(self.channel, message)

    def send_state(self, message: ChannelMessage) -> bool:
        """Send a JSON message on the lossy state channel; False when it is not open."""
        return _send(self.state_channel, message)

    def _receive(self, message: str | bytes) -> None:
        if isinstance(message, bytes):
            message = message.decode("utf-8", errors="replace")
        self._on_message(self, message)

    def _fail(self, reason: str) -> None:
        if not self._down:
            self._down = True
            self._on_down(self, reason)

    async def close(self) -> None:
        """Close the connection; ``on_down`` is not called for a close we asked for."""
        self._down = True
        # aiortc's close() swallows a cancellation that lands inside it; shielded, the caller
        # still sees its own cancellation while the close completes in the background.
        await asyncio.shield(self.pc.close())


def _send(channel: RTCDataChannel, message: ChannelMessage) -> bool:
    if channel.readyState != "open":
        return False
    # A model holds finite numbers only, so its JSON never carries NaN (browsers refuse it).
    channel.send(dump(message))
    return True
