"""The OpenCV.js builds the relay's analyzer can load, and the one it loads unless told.

Two builds of the OpenCV that pyproject.toml pins: the official one from npm
(``app/static/opencv.js``, ``scripts/vendor``) and ours with WebAssembly SIMD
(``app/static/opencv-simd.js``, ``scripts/build-opencv-js``). A page's ``?opencv=`` names one for
that page (the bench and ``autopilot parity --opencv`` do); without it every page, the relay's and
the parity page's alike, loads :data:`RELAY_OPENCV_BUILD`, so that parity checks what the relay
runs.
"""

from __future__ import annotations

from typing import Final, Literal, get_args

OpenCvBuild = Literal["simd", "official"]
OPENCV_BUILDS: Final[tuple[OpenCvBuild, ...]] = get_args(OpenCvBuild)

# The SIMD build earns its place only by a measured speed-up of the cascade as the relay runs it
# (`autopilot bench --opencv-builds` decides by `app.tools.bench.opencv_builds.choose`); it gave
# none, so the relay loads the official build, which agrees with Python OpenCV without a patch
# of ours (docs/bench/opencv-builds.md).
RELAY_OPENCV_BUILD: Final[OpenCvBuild] = "official"
