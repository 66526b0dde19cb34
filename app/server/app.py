"""The FastAPI application factory."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from app.resources import STATIC_DIR
from app.server.config import Settings
from app.server.fleet.page import router as fleet_router
from app.server.headers import SecurityHeaders
from app.server.hosts import HostGuard, allowed_hosts
from app.server.metrics import ServerMetrics
from app.server.origins import OriginGuard
from app.server.pages import router as pages_router
from app.server.rosbridge import Simulator, robot_state
from app.server.rosbridge import router as rosbridge_router
from app.server.signaling import Switchboard
from app.server.signaling import router as signaling_router
from app.server.vision import router as vision_router
from app.vision.spec import load_spec

if TYPE_CHECKING:
    from app.server.fleet.bus import FleetHub


def fleet_hub(settings: Settings) -> FleetHub:
    """The fleet hub for ``settings.redis_url``; imported only then (it needs the fleet extra)."""
    try:
        from app.server.fleet.bus import FleetHub
    except ModuleNotFoundError as exc:
        raise RuntimeError(
            f"AUTOPILOT_REDIS_URL is set but {exc.name} is missing: "
            "pip install 'webrtc-autopilot[fleet]'"
        ) from exc
    return FleetHub.from_settings(settings)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app: signaling at /ws, role pages, the simulated robot and /rosbridge.

    Its metrics are on ``app.state.metrics`` (:class:`ServerMetrics`); ``autopilot serve
    --metrics-port`` serves their registry.
    """
    settings = settings or Settings()
    metrics = ServerMetrics()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        app.state.simulator.start()
        if fleet is not None:
            await fleet.start()
        sampler = asyncio.create_task(
            metrics.run(app.state.signaling.hub, app.state.simulator), name="metrics-sampler"
        )
        expiry = asyncio.create_task(app.state.signaling.expire_sessions(), name="signaling-expiry")
        try:
            yield
        finally:
            for task in (sampler, expiry):
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            if fleet is not None:
                await fleet.stop()
            await app.state.simulator.stop()

    docs = settings.docs_enabled
    app = FastAPI(
        title="webrtc-autopilot",
        lifespan=lifespan,
        docs_url="/docs" if docs else None,
        redoc_url="/redoc" if docs else None,
        openapi_url="/openapi.json" if docs else None,
    )
    app.state.settings = settings
    app.state.metrics = metrics
    # The middleware added last runs first: the security headers go on every HTTP response,
    # the host and origin guards' refusals included; a foreign host or origin reaches no route.
    app.add_middleware(
        OriginGuard, allowed=settings.allowed_origins, on_refused=lambda: metrics.refused("origin")
    )
    if settings.secret is None:  # with one, a rebinding page has no token: any name is fine
        app.add_middleware(
            HostGuard,
            allowed=allowed_hosts(settings.host, settings.allowed_hosts),
            on_refused=lambda: metrics.refused("origin"),
        )
    app.add_middleware(SecurityHeaders)
    # Validated here so that a bad operations spec stops the server before it serves anything.
    app.state.operations = load_spec(settings.operations_spec)
    app.include_router(vision_router)
    # With Redis, this instance is one of a fleet (app/server/fleet/bus.py); else one process.
    fleet = fleet_hub(settings) if settings.redis_url else None
    app.state.signaling = Switchboard.from_settings(settings, fleet)
    if fleet is not None:
        fleet.deliver = app.state.signaling.dispatch
    app.state.signaling.hub.metrics = metrics
    app.state.signaling.outboxes.refused = metrics.refused
    app.include_router(signaling_router)
    app.include_router(pages_router)
    app.include_router(fleet_router)
    app.state.simulator = Simulator.from_settings(settings)
    app.state.simulator.outboxes.refused = metrics.refused
    app.include_router(rosbridge_router)
    # The robot's state for the client's map, where its simulation says.
    app.add_api_route(app.state.simulator.simulation.state_path, robot_state, methods=["GET"])

    @app.get("/healthz")
    async def healthz() -> dict[str, str]:
        return {"status": "ok"}

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app
