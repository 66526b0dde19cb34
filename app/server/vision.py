"""HTTP routes of the vision side: the spec, the cascade files and the parity harness page."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse
from fastapi.templating import Jinja2Templates

from app.resources import TEMPLATES_DIR
from app.vision.spec import CASCADE_DIR, Spec

router = APIRouter()
_templates = Jinja2Templates(directory=TEMPLATES_DIR)


def _spec(request: Request) -> Spec:
    spec: Spec = request.app.state.operations
    return spec


@router.get("/operations.json")
async def operations_json(request: Request) -> JSONResponse:
    """The validated spec with every default filled in and every profile merged."""
    return JSONResponse(_spec(request).for_browser())


@router.get("/cascades/{name}")
async def cascade(name: str, request: Request) -> FileResponse:
    """A cascade XML from the pinned OpenCV wheel; only files the spec names."""
    if name not in _spec(request).cascade_files():
        raise HTTPException(status_code=404, detail=f"no operation uses cascade {name!r}")
    return FileResponse(CASCADE_DIR / name, media_type="application/xml")


@router.get("/parity", response_class=HTMLResponse)
async def parity_page(request: Request) -> HTMLResponse:
    """Harness page for ``autopilot parity``: the relay's analyzer, driven from Python."""
    return _templates.TemplateResponse(request, "parity.html", {})
