"""The FastAPI application factory."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from app import operations
from app.config import PACKAGE_DIR, Settings
from app.pages import router as pages_router
from app.server.fleet.bus import FleetHub
from app.server.fleet.page import router as fleet_router
from app.signaling.routes import Switchboard
from app.signaling.routes import router as signaling_router
from app.turtlesim.routes import Simulator
from app.turtlesim.routes import router as turtlesim_router


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the app: signaling at /ws, role pages, turtle simulator and /rosbridge."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        app.state.simulator.start()
        if fleet is not None:
            await fleet.start()
        try:
            yield
        finally:
            if fleet is not None:
                await fleet.stop()
            await app.state.simulator.stop()

    app = FastAPI(title="webrtc-autopilot", lifespan=lifespan)
    app.state.settings = settings
    # Validated here so that a bad operations spec stops the server before it serves anything.
    app.state.operations = operations.load_spec(settings.operations_spec)
    app.include_router(operations.router)
    # With Redis, this instance is one of a fleet (app/server/fleet/bus.py); else one process.
    fleet = FleetHub.from_settings(settings) if settings.redis_url else None
    if fleet is None:
        app.state.signaling = Switchboard.from_settings(settings)
    else:
        app.state.signaling = Switchboard(fleet)
        fleet.deliver = app.state.signaling.dispatch
    app.state.fleet_hub = fleet
    app.include_router(signaling_router)
    app.include_router(pages_router)
    app.include_router(fleet_router)
    app.state.simulator = Simulator(settings.sim_tick_s, settings.max_message_bytes)
    app.state.turtlesim = app.state.simulator.sim
    app.include_router(turtlesim_router)

    @app.get("/healthz")
    async def healthz() -> dict[str, str]:
        return {"status": "ok"}

    app.mount("/static", StaticFiles(directory=PACKAGE_DIR / "static"), name="static")
    return app
