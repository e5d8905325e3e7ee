"""Synthetic photos of a rendered object: the object scaled, placed and composited with
anti-aliased edges over a background of a chosen kind, with sensor noise (the tests of
segmentation and ``benchmarks/segmentation.py``)."""

from __future__ import annotations

import cv2
import numpy as np

#: The backgrounds the tests assert on; "clutter_strong" is only measured (benchmarks).
BACKGROUNDS = ("plain_light", "plain_dark", "gradient", "clutter")
ALL_BACKGROUNDS = (*BACKGROUNDS, "clutter_strong")


def background(kind: str, shape: tuple[int, int], rng: np.random.Generator,
               object_colours: np.ndarray) -> np.ndarray:
    """A float RGB background of ``kind`` (see :data:`ALL_BACKGROUNDS`)."""
    h, w = shape
    if kind in ("plain_light", "plain_dark"):
        # as a photographer would: of a few light (or dark, saturated) colours, the one
        # that contrasts best with the object (largest 5th percentile of RGB distance)
        if kind == "plain_light":
            options = rng.uniform(195, 250, (4, 3))
        else:
            options = np.array([[25, 35, 90], [20, 70, 40], [70, 25, 80], [75, 45, 20]], float)
            options = options + rng.uniform(-10, 10, 3)
        some = object_colours[:: max(1, len(object_colours) // 500)]
        score = [np.quantile(np.linalg.norm(some - o, axis=1), 0.05) for o in options]
        return np.zeros((h, w, 3)) + options[int(np.argmax(score))]
    if kind == "gradient":  # linear, any direction, between two random light colours
        a, b = rng.uniform(170, 250, 3), rng.uniform(120, 200, 3)
        angle = rng.uniform(0, 2 * np.pi)
        yy, xx = np.mgrid[0:h, 0:w]
        t = np.cos(angle) * xx / w + np.sin(angle) * yy / h
        t = (t - t.min()) / (t.max() - t.min())
        return a + (b - a) * t[:, :, None]
    if kind in ("clutter", "clutter_strong"):  # soft blobs near the base colour + texture
        contrast, texture = (12, 6) if kind == "clutter" else (25, 8)
        base = rng.uniform(170, 235, 3)
        bg = np.zeros((h, w, 3)) + base
        for _ in range(int(rng.integers(6, 14))):
            centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            axes = (int(rng.integers(8, w // 4)), int(rng.integers(8, h // 4)))
            colour = tuple(float(v) for v in np.clip(base + rng.uniform(-contrast, contrast, 3), 0, 255))
            cv2.ellipse(bg, centre, axes, float(rng.uniform(0, 180)), 0, 360, colour, -1)
        bg = cv2.GaussianBlur(bg, (0, 0), 2.0)
        return bg + cv2.GaussianBlur(rng.normal(0, texture, (h, w, 3)), (0, 0), 1.5)
    raise ValueError(f"unknown background {kind!r}")


def make_scene(color: np.ndarray, mask: np.ndarray, kind: str, rng: np.random.Generator,
               shape: tuple[int, int] = (240, 320)) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic photo of a render: ``(uint8 RGB image, true silhouette)``.

    The object (``color`` is black off ``mask``, i.e. premultiplied) is scaled so its
    longer side is 35-75 % of the shorter image side, placed at a random position at
    least 6 % from the edges, composited with anti-aliased edges (the true silhouette is
    coverage > 1/2) over ``background(kind)``, and sensor noise (sigma 2) is added.
    """
    h, w = shape
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    obj = color[r0:r1, c0:c1].astype(np.float64)
    cover = mask[r0:r1, c0:c1].astype(np.float64)
    scale = rng.uniform(0.35, 0.75) * min(h, w) / max(r1 - r0, c1 - c0)
    size = (max(1, round((c1 - c0) * scale)), max(1, round((r1 - r0) * scale)))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    obj, cover = cv2.resize(obj, size, interpolation=interp), cv2.resize(cover, size, interpolation=interp)
    margin = round(0.06 * min(h, w))
    y = int(rng.integers(margin, max(margin + 1, h - margin - size[1])))
    x = int(rng.integers(margin, max(margin + 1, w - margin - size[0])))
    alpha = np.zeros((h, w))
    alpha[y : y + size[1], x : x + size[0]] = cover
    premultiplied = np.zeros((h, w, 3))
    premultiplied[y : y + size[1], x : x + size[0]] = obj
    out = premultiplied + (1 - alpha[:, :, None]) * background(kind, shape, rng, color[mask].astype(float))
    out += rng.normal(0, 2.0, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8), alpha > 0.5
