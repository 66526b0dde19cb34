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

# The relay's worker loads one build for every operation the client may switch it to, so the SIMD
# build earns its place by a measured speed-up of some operation's work as the relay runs it and
# a slow-down of none (`autopilot bench --opencv-builds` decides by
# `app.tools.bench.opencv_builds.choose`): the DNN face runs several times faster on it, and the
# cascades no slower (docs/bench/opencv-builds.md).
RELAY_OPENCV_BUILD: Final[OpenCvBuild] = "simd"
