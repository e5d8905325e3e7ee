"""Where pyrender and OpenGL are loaded: the one place that picks the GL platform.

pyrender picks its platform from ``PYOPENGL_PLATFORM`` at import time. viewdb sets it to
``egl`` (headless; Mesa's software EGL works without a GPU) unless the user already chose
one (e.g. ``osmesa``).

Single sampling. pyrender renders into a 4× multisampled framebuffer and resolves depth by
taking one sample, which sits off the pixel centre (a quarter pixel or so on Mesa). viewdb
needs depth and silhouette sampled exactly at pixel centres — the mirror pairing relies on
a sampling grid symmetric about the image's vertical axis, and lifting keypoints to 3-D on
the depth being where the pixel is — so it makes pyrender allocate single-sampled buffers
(:func:`_single_sampled`). It also renders about twice as fast in software.

No face culling. A silhouette is every triangle's projection, whatever its winding: open
shells (a car body with no floor) and meshes with flipped triangles must not lose faces
seen from behind. pyrender honours ``SKIP_CULL_FACES`` when it binds a material but
always culls back faces in its depth-only pass, which viewdb uses for fast silhouettes;
:func:`_no_face_culling` makes it never enable culling.

Importing this module does not import OpenGL; call
:func:`pyrender_module` when rendering is actually needed, so the rest of viewdb (queries
on a shipped client db) works on machines with no GL at all.
"""

from __future__ import annotations

import os
from types import ModuleType

from ..errors import RenderError

__all__ = ["pyrender_module"]

_PYRENDER: ModuleType | None = None


def pyrender_module() -> ModuleType:
    """Import pyrender with a headless platform, or raise :class:`RenderError` saying why."""
    global _PYRENDER
    if _PYRENDER is None:
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        try:
            import pyrender
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.split(".")[0] in ("pyrender", "OpenGL", "trimesh"):
                raise  # not installed (the ingest extra): lazy.missing_extra names it
            raise RenderError(f"cannot load pyrender: {exc}") from exc
        except Exception as exc:  # OpenGL platform errors, missing libEGL
            platform = os.environ.get("PYOPENGL_PLATFORM")
            raise RenderError(
                f"cannot load pyrender with PYOPENGL_PLATFORM={platform}: {exc}; "
                "install libegl1 and libgl1-mesa-dri (see install.sh)"
            ) from exc
        _single_sampled(pyrender)
        _no_face_culling(pyrender)
        _PYRENDER = pyrender
    return _PYRENDER


def _single_sampled(pyrender: ModuleType) -> None:
    """Make pyrender's main framebuffer single-sampled (see the module docstring)."""
    renderer_module = pyrender.renderer
    if getattr(renderer_module, "_viewdb_single_sampled", False):
        return
    storage = renderer_module.glRenderbufferStorage

    def storage_multisample(target: int, _samples: int, fmt: int, width: int, height: int) -> None:
        storage(target, fmt, width, height)

    renderer_module.glRenderbufferStorageMultisample = storage_multisample
    renderer_module._viewdb_single_sampled = True


def _no_face_culling(pyrender: ModuleType) -> None:
    """Make pyrender's renderer ignore requests to enable back-face culling."""
    renderer_module = pyrender.renderer
    if getattr(renderer_module, "_viewdb_no_culling", False):
        return
    enable = renderer_module.glEnable
    cull_face = renderer_module.GL_CULL_FACE

    def gl_enable(capability: int) -> None:
        if capability != cull_face:
            enable(capability)

    renderer_module.glEnable = gl_enable
    renderer_module._viewdb_no_culling = True
