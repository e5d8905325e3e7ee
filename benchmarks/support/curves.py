"""Synthetic distance curves shared by the bound kernels' benchmark and tests."""

from __future__ import annotations

import numpy as np


def smooth_curve(rng: np.random.Generator, n: int) -> np.ndarray:
    """A real-looking centroid distance curve: 1 + a few low sinusoids, mean 1, with
    float32's precision (as stored), as float64."""
    t = np.arange(n) / n
    x = np.ones(n)
    for _ in range(rng.integers(1, 5)):
        f = rng.integers(1, 7)
        x += rng.uniform(0.02, 0.25) * np.cos(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    x = np.maximum(x, 0.05)
    x /= x.mean()
    return x.astype(np.float32).astype(np.float64)
