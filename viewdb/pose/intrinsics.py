"""Camera intrinsics from text or a file: ``fx,fy,cx,cy``, or a JSON / YAML file.

Accepted (pixels, OpenCV convention: pixel centres on integers, no distortion):

* the text ``"fx,fy,cx,cy"`` (four numbers);
* a JSON or YAML file (``.json``, ``.yaml``, ``.yml``) holding either the keys ``fx``,
  ``fy``, ``cx``, ``cy``; or a 3×3 camera matrix (nested, or 9 numbers row by row) under
  ``K``, ``camera_matrix`` or ``intrinsics`` (an OpenCV-style ``{"data": [...]}`` mapping
  is read too); or the bare matrix / four numbers at the top level.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..config import LIMITS, finite
from ..errors import QueryError
from ..paths import not_regular, open_regular
from ..typed import Intrinsics

__all__ = ["Intrinsics", "check_intrinsics", "parse_intrinsics"]

#: Keys a camera matrix may be stored under.
MATRIX_KEYS = ("K", "k", "camera_matrix", "cameraMatrix", "intrinsics", "intrinsic_matrix")


def parse_intrinsics(value: str | os.PathLike[str] | Any) -> Intrinsics:
    """``(fx, fy, cx, cy)`` from ``"fx,fy,cx,cy"``, a JSON/YAML file path, a 3×3 matrix or
    four numbers.

    Raises
    ------
    QueryError
        Unreadable file, unknown layout, or values that are not a camera (``fx, fy > 0``,
        finite ``cx, cy``, a matrix whose last row is ``0 0 1`` and with no skew); the
        message names the file.
    """
    if isinstance(value, os.PathLike) or (isinstance(value, str) and not _looks_numeric(value)):
        return _from_file(Path(value))
    if isinstance(value, str):
        parts = [p.strip() for p in value.split(",")]
        try:
            numbers = [float(p) for p in parts]
        except ValueError:
            numbers = []
        if len(numbers) != 4:
            raise QueryError(f"intrinsics {value!r}: expected fx,fy,cx,cy (four numbers) or a "
                             "JSON/YAML file")
        return check_intrinsics(numbers, None)
    if isinstance(value, (list, tuple, np.ndarray)):
        try:
            value = np.asarray(value, dtype=np.float64).ravel().tolist()
        except (TypeError, ValueError) as exc:
            raise QueryError(f"intrinsics must be numbers, got {value!r}") from exc
    return _from_data(value, None)


def _looks_numeric(text: str) -> bool:
    return all(c in "0123456789.,+-eE \t" for c in text) and "," in text


#: An intrinsics file is a few numbers; a larger file is not one.
MAX_FILE_BYTES = 1 << 20


def _from_file(path: Path) -> Intrinsics:
    why = not_regular(path)
    if why is not None:
        raise QueryError("intrinsics file not found" if why == "does not exist" else why, path)
    try:
        with open_regular(path) as f:
            raw = f.read(MAX_FILE_BYTES + 1)
        if len(raw) > MAX_FILE_BYTES:
            raise QueryError(f"is over {MAX_FILE_BYTES:,} bytes: not an intrinsics file", path)
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise QueryError(f"cannot read the intrinsics file: {exc}", path) from exc
    if path.suffix.lower() in (".yaml", ".yml"):
        import yaml

        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise QueryError(f"not valid YAML: {' '.join(str(exc).split())[:160]}", path) from exc
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise QueryError(f"not valid JSON: {exc}", path) from exc
    return _from_data(data, path)


def _from_data(data: Any, path: Path | None) -> Intrinsics:
    if isinstance(data, dict):
        if all(key in data for key in ("fx", "fy", "cx", "cy")):
            return check_intrinsics([data["fx"], data["fy"], data["cx"], data["cy"]], path)
        for key in MATRIX_KEYS:
            if key in data:
                return _from_data(data[key], path)
        if "data" in data:  # OpenCV FileStorage style {rows: 3, cols: 3, data: [...]}
            return _from_data(data["data"], path)
        raise QueryError("no intrinsics found: expected keys fx, fy, cx, cy or a 3x3 matrix under "
                         f"one of {', '.join(MATRIX_KEYS)}", path)
    if isinstance(data, (list, tuple)):
        flat = _flatten(data)
        if flat is None:
            raise QueryError("intrinsics must be numbers", path)
        if len(flat) == 4:
            return check_intrinsics(flat, path)
        if len(flat) == 9:
            if any(abs(float(a) - b) > 1e-9 for a, b in zip(flat[6:], (0.0, 0.0, 1.0), strict=True)):
                raise QueryError(f"camera matrix's last row must be 0 0 1, got {flat[6:]}", path)
            if abs(float(flat[1])) > 1e-9 or abs(float(flat[3])) > 1e-9:
                raise QueryError("camera matrix with skew or shear is not supported "
                                 f"(K[0][1] = {flat[1]}, K[1][0] = {flat[3]})", path)
            return check_intrinsics([flat[0], flat[4], flat[2], flat[5]], path)
        raise QueryError(f"expected a 3x3 camera matrix or four numbers, got {len(flat)} numbers", path)
    raise QueryError(f"no intrinsics found in a {type(data).__name__}", path)


def _flatten(data: Any) -> list[Any] | None:
    out: list[Any] = []
    for item in data:
        if isinstance(item, (list, tuple)):
            inner = _flatten(item)
            if inner is None:
                return None
            out.extend(inner)
        elif isinstance(item, (int, float)) and not isinstance(item, bool):
            out.append(item)
        else:
            return None
    return out


def check_intrinsics(values: Any, path: Path | None = None) -> Intrinsics:
    """``(fx, fy, cx, cy)`` from four numbers, refused unless they are a camera within
    :data:`~viewdb.config.LIMITS` (focal lengths in ``[min_focal, max_focal]`` pixels, the
    principal point within ``max_principal`` pixels of the origin); the one check of every
    way intrinsics come in (text, file, array, HTTP)."""
    if not isinstance(values, list | tuple | np.ndarray) or len(values) != 4:
        raise QueryError(f"intrinsics must be four numbers fx, fy, cx, cy, got {values!r}"[:200], path)
    try:
        fx, fy = (finite(v, name, LIMITS.min_focal, LIMITS.max_focal)
                  for v, name in zip(values[:2], ("fx", "fy"), strict=True))
        cx, cy = (finite(v, name, -LIMITS.max_principal, LIMITS.max_principal)
                  for v, name in zip(values[2:], ("cx", "cy"), strict=True))
    except ValueError as exc:
        raise QueryError(f"intrinsics {exc} (pixels)", path) from exc
    return fx, fy, cx, cy
