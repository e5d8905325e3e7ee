"""Type aliases shared across viewdb (the ground floor: imports nothing of viewdb)."""

from __future__ import annotations

__all__ = ["Intrinsics"]

#: Pinhole camera intrinsics ``(fx, fy, cx, cy)`` in pixels (OpenCV convention, no distortion).
Intrinsics = tuple[float, float, float, float]
