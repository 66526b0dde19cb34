"""A plain ``pip install .`` is the server: serving must not need what the extras bring."""

from __future__ import annotations

import subprocess
import sys

# What the agent, tools, bench, fleet and dev extras install; none of it may load to serve pages.
EXTRAS_ONLY = ("aiortc", "av", "roslibpy", "playwright", "matplotlib", "cv2", "redis")

PROBE = """
import sys
from fastapi.testclient import TestClient
from app.server.app import create_app
from app.server.config import Settings
app = create_app(Settings(environment="development"))
with TestClient(app, base_url="http://127.0.0.1") as client:
    for path in ("/healthz", "/client?room=r", "/operations.json",
                 "/cascades/haarcascade_frontalface_default.xml", "/fleet", "/fleet/rooms"):
        assert client.get(path).status_code == 200, path
print(" ".join(sorted({name.split(".")[0] for name in sys.modules})))
"""


def test_serving_loads_no_extra() -> None:
    done = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr
    loaded = set(done.stdout.split())
    assert "app" in loaded and "fastapi" in loaded
    assert not loaded & set(EXTRAS_ONLY), sorted(loaded & set(EXTRAS_ONLY))
