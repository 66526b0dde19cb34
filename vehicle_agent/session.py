"""The vehicle's signaling session: logged in, a relay found, a link to it kept alive.

One :class:`SignalingSession` runs until cancelled. It logs in as a vehicle, waits for a relay in
the room, offers to it and keeps that link alive: when the relay leaves, the link fails or the
signaling server goes away, it tells the agent (``on_link_lost``: the robot stops) and
reconnects with backoff, without restarting. With a token it renews its session when the server
says (``renew``), before the token expires, and uses the fresh token from then on: for a later
login, and wherever its listeners (:attr:`SignalingSession.token_renewed`) prove it. Everything
that happens is dispatched from one queue, one handler per event kind.

What the relay says on the data channels is the agent's (``on_message``); this module only
moves it (:mod:`vehicle_agent.agent`).
"""

from __future__ import annotations

import asyncio
import logging
import ssl
import time
from collections.abc import Awaitable, Callable
from typing import Any

from aiortc import MediaStreamTrack, RTCIceServer
from pydantic import ValidationError

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.errors import describe
from app.protocol.signaling import Renew, Renewed
from app.supervise import Backoff
from vehicle_agent.events import EventLog
from vehicle_agent.peer import RelayLink
from vehicle_agent.signaling import SignalingClient, SignalingError

log = logging.getLogger(__name__)

# The relay must answer and ICE must connect within this long, or the session offers again.
CONNECT_TIMEOUT_S = 10.0

# Acts on one data-channel message from the relay (its text, the relay's name); the error
# reply to send back, if any.
MessageHandler = Callable[[str | bytes, str], channels.Error | None]


class SignalingSession:
    """The vehicle's login to ``server`` as ``name`` in ``room``, and its link to the relay.

    ``track()`` gives the video for each new link; ``on_message`` acts on the relay's
    data-channel messages; ``on_new_link`` and ``on_link_lost`` are called when a link is
    offered and when the commands' link is gone (or the session stops).
    """

    def __init__(
        self,
        server: str,
        name: str,
        room: str,
        *,
        track: Callable[[], MediaStreamTrack],
        on_message: MessageHandler,
        on_new_link: Callable[[], None],
        on_link_lost: Callable[[], None],
        events: EventLog,
        token: str | None = None,
        tls: ssl.SSLContext | None = None,
        ice_servers: list[RTCIceServer] | None = None,
    ) -> None:
        self.server, self.name, self.room = server, name, room
        self._track = track
        self._on_message = on_message
        self._on_new_link = on_new_link
        self._on_link_lost = on_link_lost
        self.events = events
        self.tls = tls
        self.ice_servers = list(ice_servers or [])
        # The session's token as last renewed (the next login uses it), and the renewal's timer.
        self.token = token
        self._renewal: asyncio.TimerHandle | None = None
        # Who else proves the token (the robot's rosbridge connection, the ROS camera's): each
        # is given every fresh token.
        self.token_renewed: list[Callable[[str], None]] = []
        self.logged_in = asyncio.Event()
        self._client: SignalingClient | None = None
        self._relay: str | None = None
        self._link: RelayLink | None = None
        self._queue: asyncio.Queue[tuple[str, Any]] = asyncio.Queue()
        self._link_backoff = Backoff()
        self._retry: asyncio.TimerHandle | None = None
        self._handlers: dict[str, Callable[[Any], Awaitable[None]]] = {
            "login": self._ignore,
            "peers": self._on_peers,
            "answer": self._on_answer,
            "candidate": self._on_candidate,
            "leave": self._on_leave,
            "renewed": self._on_renewed,
            "error": self._on_server_error,
        }
        # What the session loop's queue carries (besides "closed", which ends the session).
        self._events: dict[str, Callable[[Any], Awaitable[None]]] = {
            "signal": self._on_signal,
            "link_down": self._on_link_event,
            "retry": self._on_retry,
            "renew": self._on_renew,
        }

    @property
    def link(self) -> RelayLink | None:
        """The current connection to the relay, if any."""
        return self._link

    async def run(self) -> None:
        """Run until cancelled; raises :class:`SignalingError` if the first login fails."""
        try:
            await self._signaling_loop()
        finally:
            await self._drop_link("agent stopping")

    # --- signaling -----------------------------------------------------------------------

    async def _signaling_loop(self) -> None:
        backoff = Backoff()
        first = True
        while True:
            client = SignalingClient(
                self.server, self.name, self.room, token=self.token, tls=self.tls
            )
            try:
                peers = await client.connect()
            except SignalingError as exc:
                # A wrong URL or a refused name at start-up is the operator's to fix; later
                # the server may just be restarting.
                if first:
                    raise
                delay = backoff.next()
                log.warning("%s; retrying in %.1f s", exc, delay)
                await asyncio.sleep(delay)
                continue
            first = False
            backoff.reset()
            log.info(
                "logged in to %s as vehicle %r in room %r", client.url, client.name, client.room
            )
            self._client = client
            self.logged_in.set()
            try:
                await self._session(client, peers)
            finally:
                self.logged_in.clear()
                self._client = None
                await self._drop_link("signaling connection lost")
                self._relay = None
                await client.close()
            delay = backoff.next()
            log.warning("signaling connection lost; reconnecting in %.1f s", delay)
            await asyncio.sleep(delay)

    async def _session(self, client: SignalingClient, peers: list[dict[str, Any]]) -> None:
        self._queue = asyncio.Queue()
        reader = asyncio.create_task(self._read(client), name="signaling-reader")
        self._renew_after(client.renew_in)
        try:
            await self._on_peers({"peers": peers})
            while True:
                kind, payload = await self._queue.get()
                if kind == "closed":
                    return
                await self._events[kind](payload)
        finally:
            reader.cancel()
            await asyncio.gather(reader, return_exceptions=True)
            if self._retry is not None:
                self._retry.cancel()
                self._retry = None
            if self._renewal is not None:
                self._renewal.cancel()
                self._renewal = None

    def _renew_after(self, seconds: float | None) -> None:
        """Ask for a fresh token in ``seconds`` (None: the server asks for no tokens)."""
        if seconds is None:
            return
        queue = self._queue
        loop = asyncio.get_running_loop()
        self._renewal = loop.call_later(seconds, queue.put_nowait, ("renew", None))

    async def _on_renew(self, payload: None) -> None:
        self._renewal = None
        if self._client is not None:
            await self._client.send(Renew(type="renew").model_dump(exclude_none=True))

    async def _on_renewed(self, message: dict[str, Any]) -> None:
        try:
            renewed = Renewed.model_validate(message)
        except ValidationError as exc:
            log.warning("malformed renewal from the server: %s", describe(exc))
            return
        self.token = renewed.token
        for listener in self.token_renewed:
            listener(renewed.token)
        log.debug("token renewed; next renewal in %.0f s", renewed.renewIn)
        self._renew_after(renewed.renewIn)

    async def _on_signal(self, message: dict[str, Any]) -> None:
        handler = self._handlers.get(message["type"])
        if handler is None:
            log.debug("ignoring signaling message %s", message["type"])
        else:
            await handler(message)

    async def _on_link_event(self, payload: tuple[RelayLink, str]) -> None:
        link, reason = payload
        await self._on_link_down(link, reason)

    async def _on_retry(self, payload: None) -> None:
        self._retry = None
        await self._ensure_link()

    async def _read(self, client: SignalingClient) -> None:
        async for message in client.messages():
            self._queue.put_nowait(("signal", message))
        self._queue.put_nowait(("closed", None))

    async def _ignore(self, message: dict[str, Any]) -> None:
        return None

    async def _on_peers(self, message: dict[str, Any]) -> None:
        relays = [p.get("name") for p in message.get("peers", []) if p.get("role") == "relay"]
        relay = relays[0] if relays and isinstance(relays[0], str) else None
        if relay == self._relay:
            return
        if self._relay is not None:
            log.info("relay %s left the room", self._relay)
            await self._drop_link("relay left")
        self._relay = relay
        self._link_backoff.reset()
        if relay is None:
            log.info("waiting for a relay in room %r", self.room)
        else:
            log.info("relay %s is in the room", relay)
            await self._ensure_link()

    async def _on_answer(self, message: dict[str, Any]) -> None:
        link = self._link
        if (
            link is None
            or message.get("from") != link.relay
            or not isinstance(message.get("sdp"), str)
        ):
            log.warning("ignoring an answer from %s", message.get("from"))
            return
        await link.on_answer(message["sdp"])

    async def _on_candidate(self, message: dict[str, Any]) -> None:
        link = self._link
        candidate = message.get("candidate")
        if link is None or message.get("from") != link.relay:
            log.debug("ignoring a candidate from %s", message.get("from"))
            return
        if candidate is not None and not isinstance(candidate, dict):
            log.warning("ignoring a malformed candidate from %s", message.get("from"))
            return
        await link.on_candidate(candidate)

    async def _on_leave(self, message: dict[str, Any]) -> None:
        if message.get("from") == self._relay:
            log.info("relay %s left", self._relay)
            await self._drop_link("relay left")
            self._relay = None

    async def _on_server_error(self, message: dict[str, Any]) -> None:
        log.warning("signaling server refused %s: %s", message.get("ref"), message.get("reason"))

    # --- the link to the relay -------------------------------------------------------------

    async def _ensure_link(self) -> None:
        if self._relay is None or self._link is not None or self._retry is not None:
            return
        client = self._client
        if client is None:
            return
        ice_servers = [
            RTCIceServer(urls=s.urls, username=s.username, credential=s.credential)
            for s in client.ice_servers
        ]
        link = RelayLink(
            self._relay,
            self._track(),
            client.send,
            self._on_channel_message,
            self._link_failed,
            ice_servers + self.ice_servers,
            client.ice_transport_policy,
        )
        link.on_up = self._on_link_up
        self._link = link
        self._on_new_link()
        self.events.emit(ev.LinkChanged(state="offer", relay=link.relay, t=time.monotonic()))
        await link.start()
        asyncio.get_running_loop().call_later(CONNECT_TIMEOUT_S, self._check_connected, link)

    def _on_link_up(self, link: RelayLink) -> None:
        candidates = link.local_candidate_types()
        log.info("link to %s up (local candidates: %s)", link.relay, ", ".join(candidates))
        self.events.emit(
            ev.LinkChanged(
                state="up",
                relay=link.relay,
                local_candidates=tuple(candidates),
                selected=link.selected_candidate_type(),
                t=time.monotonic(),
            )
        )

    def _check_connected(self, link: RelayLink) -> None:
        if link is self._link and not link.connected.is_set():
            self._link_failed(link, f"no connection within {CONNECT_TIMEOUT_S:g} s")

    def _link_failed(self, link: RelayLink, reason: str) -> None:
        self._queue.put_nowait(("link_down", (link, reason)))

    async def _on_link_down(self, link: RelayLink, reason: str) -> None:
        if link is not self._link:
            return  # an old link we already replaced
        await self._drop_link(reason)
        if self._relay is not None:
            delay = self._link_backoff.next()
            log.info("offering to %s again in %.1f s", self._relay, delay)
            self._retry = asyncio.get_running_loop().call_later(
                delay, self._queue.put_nowait, ("retry", None)
            )

    async def _drop_link(self, reason: str) -> None:
        link, self._link = self._link, None
        # Stop at once, autopilot or operator: the link that carried the commands is gone.
        self._on_link_lost()
        if link is None:
            return
        log.info("link to %s down: %s", link.relay, reason)
        self.events.emit(
            ev.LinkChanged(state="down", relay=link.relay, reason=reason, t=time.monotonic())
        )
        await link.close()

    def _on_channel_message(self, link: RelayLink, text: str | bytes) -> None:
        if link is not self._link:
            return
        if not link.connected.is_set():
            link.connected.set()
        reply = self._on_message(text, link.relay)
        if reply is not None:
            link.send(reply)
