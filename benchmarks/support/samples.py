"""The bundled sample models (``sample_models/``) by name or all of them."""

from __future__ import annotations

from pathlib import Path

SAMPLES = Path(__file__).resolve().parents[2] / "sample_models"
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def sample(stem: str) -> Path:
    """The sample model file called ``stem`` (any supported format)."""
    for p in sorted(SAMPLES.iterdir()):
        if p.stem == stem and p.suffix.lower() in MESH_SUFFIXES:
            return p
    raise FileNotFoundError(f"no sample model {stem!r} in {SAMPLES}")


def sample_files() -> list[Path]:
    """Every sample model file, sorted by path."""
    return sorted(p for p in SAMPLES.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
