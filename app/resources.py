"""Where the package's files live: static assets, templates, the operations spec.

Plain paths with no imports of our own, so any layer may use them.
"""

from __future__ import annotations

from pathlib import Path

APP_DIR = Path(__file__).resolve().parent
STATIC_DIR = APP_DIR / "static"
TEMPLATES_DIR = APP_DIR / "templates"
OPERATION_MODULES_DIR = STATIC_DIR / "js" / "worker" / "operations"
OPERATIONS_SPEC = APP_DIR / "vision" / "operations.json"
# Face photos (with their licence) for the synthetic video and the simulated arena.
FACES_DIR = APP_DIR / "assets"
