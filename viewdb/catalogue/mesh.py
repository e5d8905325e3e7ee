"""Loading and normalising meshes: the only module that reads mesh files.

OBJ, PLY, STL, OFF and GLB/glTF are read through trimesh. A file becomes a
:class:`NormalisedMesh`: a ``trimesh.Scene`` whose node transforms are baked into its
geometry (textures and vertex colours kept for the shaded render), moved so the bounding
box centre is at the origin and scaled so the farthest vertex is at distance 1. The
original centre and scale are kept, so a pose can be reported in the mesh's own units.

trimesh catches ``BaseException`` in places (a texture image that fails to load, for one:
"failed to load image", and the mesh goes on untextured), which would swallow a Ctrl-C
and let an ingest run on. So Ctrl-C is held while trimesh reads, normalises or writes a
mesh and raised as soon as it is done (:mod:`viewdb.interrupts`).

A mesh over the face cap is refused before it is read whole: its declared triangle count
comes from its header, or from its lines streamed in constant memory
(:func:`declared_faces`); the count of the loaded mesh is checked again after.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import IO, TYPE_CHECKING
from urllib.parse import unquote

import numpy as np
from numpy.typing import NDArray

from ..config import DEFAULT_MAX_FACES, integer
from ..errors import MeshError
from ..interrupts import interrupts_held
from ..lazy import lazy_module
from ..paths import not_regular, open_regular

__all__ = [
    "DEFAULT_MAX_FACES", "MESH_SUFFIXES", "LoadOptions", "NormalisedMesh", "declared_faces", "load_mesh",
    "mesh_from_glb", "missing_textures", "referenced_files",
]

#: File endings ingest accepts (case-insensitive).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")

#: A mesh whose total area is below this (in squared normalised units) has "no area".
MIN_AREA = 1e-10

logging.getLogger("trimesh").setLevel(logging.ERROR)

if TYPE_CHECKING:
    import trimesh
else:
    #: Imported when a mesh is first loaded or built (:mod:`viewdb.lazy`).
    trimesh = lazy_module("trimesh")


@dataclass(frozen=True, eq=False)
class NormalisedMesh:
    """A mesh in model space (centre at origin, radius 1), with its original placement.

    ``original = centre + scale · normalised`` maps model space back to the file's units.
    """

    name: str
    scene: trimesh.Scene
    centre: NDArray[np.float64] = field(repr=False)
    scale: float
    source: str = ""
    content_hash: str = ""

    @cached_property
    def geometry(self) -> trimesh.Trimesh:
        """All triangles as one mesh (no textures): for geometry, not for shading."""
        return _concatenate(self.scene)

    @property
    def n_faces(self) -> int:
        return int(len(self.geometry.faces))

    @property
    def n_vertices(self) -> int:
        return int(len(self.geometry.vertices))

    def to_glb(self) -> bytes:
        """The normalised scene as binary glTF (textures and vertex colours included)."""
        with interrupts_held():  # see the module doc
            data = self.scene.export(file_type="glb")
        return bytes(data)


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file's bytes (the content hash that makes re-ingest a no-op)."""
    h = hashlib.sha256()
    with open_regular(path) as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass(frozen=True)
class LoadOptions:
    """What an ingest accepts."""

    #: Most triangles a mesh may have (``None``: no cap).
    max_faces: int | None = DEFAULT_MAX_FACES
    #: Ingest a mesh whose texture files are missing untextured, instead of refusing it.
    allow_missing_textures: bool = False

    def __post_init__(self) -> None:
        if self.max_faces is not None:
            integer(self.max_faces, "max_faces", 1)


def load_mesh(
    path: str | Path, name: str | None = None, content_hash: str | None = None,
    options: LoadOptions = LoadOptions(),  # noqa: B008 - frozen, shared on purpose
) -> NormalisedMesh:
    """Load a mesh file and normalise it.

    Parameters
    ----------
    path
        An OBJ, PLY, STL, OFF, GLB or glTF file.
    name
        Object name; defaults to the file's stem.
    content_hash
        The file's :func:`file_hash` if the caller already computed it.
    options
        The face cap and what to do about missing texture files.

    Raises
    ------
    MeshError
        The file is missing, not a supported mesh, holds no triangles or has no area,
        has more triangles than ``options.max_faces``, or names a texture file that does
        not exist (unless ``options.allow_missing_textures``).
    """
    path = Path(path)
    why = not_regular(path)
    if why is not None:
        raise MeshError("no such file" if why == "does not exist" else why, path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(
            f"unsupported file type {path.suffix or '(none)'!r}; "
            f"use one of {', '.join(MESH_SUFFIXES)}",
            path,
        )
    _check_references(path, options)
    if options.max_faces is not None:  # refused before the file is read whole
        declared = declared_faces(path)
        if declared is not None and declared > options.max_faces:
            raise MeshError(_over_cap(declared, options.max_faces), path)
    load = trimesh.load  # imports trimesh: a core install without it fails here, not below
    with interrupts_held():  # see the module doc
        try:
            loaded = load(str(path), process=False)
        except Exception as exc:  # trimesh raises many types for bad files
            raise MeshError(f"cannot be read as a mesh: {_short(exc)}", path) from exc
        if options.max_faces is not None:
            faces = _face_count(loaded)
            if faces > options.max_faces:
                raise MeshError(_over_cap(faces, options.max_faces), path)
        digest = content_hash or file_hash(path)
        return _normalise(loaded, name or path.stem, str(path), digest, path)


def _over_cap(faces: int, cap: int) -> str:
    return (f"has {faces:,} triangles, more than the cap of {cap:,}; decimate it first or raise "
            "the cap (`max_faces`)")


#: Bytes of a header read to find a mesh's declared face count (PLY, OFF; a GLB's JSON
#: chunk may be larger and is read whole, never its binary chunk).
_HEADER_BYTES = 1 << 16
_GLTF_TRIANGLES = 4


def declared_faces(path: str | Path) -> int | None:
    """The triangles a mesh file declares, found without loading it: from the header
    (PLY's ``element face``, OFF's counts, binary STL's count, a GLB or glTF's accessors)
    or by streaming its lines (OBJ's ``f`` lines, ASCII STL's facets), in constant memory.
    An OBJ's polygons count as the triangles they make, a PLY's or OFF's once each (so
    never more than the loaded mesh has). None when it cannot tell (the loader's own
    count then applies)."""
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        with open_regular(path, "rb") as f:
            if suffix == ".ply":
                return _ply_faces(f.read(_HEADER_BYTES))
            if suffix == ".off":
                return _off_faces(f.read(_HEADER_BYTES))
            if suffix == ".stl":
                return _stl_faces(f, path.stat().st_size)
            if suffix == ".obj":
                return _obj_faces(f)
            if suffix in (".glb", ".gltf"):
                return _gltf_faces(f, suffix == ".glb")
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        return None
    return None


def _ply_faces(head: bytes) -> int | None:
    if not head.startswith(b"ply") or b"end_header" not in head:
        return None
    for line in head.split(b"end_header")[0].splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == b"element" and parts[1] == b"face":
            return int(parts[2])
    return 0


def _off_faces(head: bytes) -> int | None:
    words: list[bytes] = []
    for line in head.splitlines():
        words += line.split(b"#")[0].split()
        if len(words) >= 4:
            break
    if not words or not words[0].endswith(b"OFF"):
        return None
    return int(words[2])


def _stl_faces(f: IO[bytes], size: int) -> int | None:
    head = f.read(84)
    if len(head) == 84 and 84 + 50 * int.from_bytes(head[80:84], "little") == size:
        return int.from_bytes(head[80:84], "little")  # binary: the count, checked by the size
    if not head.lstrip().lower().startswith(b"solid"):
        return None
    f.seek(0)
    return sum(line.lstrip().lower().startswith(b"facet") for line in f)  # ASCII: streamed


def _obj_faces(f: IO[bytes]) -> int:
    count = 0
    for line in f:  # streamed: one line in memory at a time
        if line.startswith(b"f ") or line.startswith(b"f\t"):
            count += max(len(line.split()) - 3, 0)
    return count


def _gltf_faces(f: IO[bytes], binary: bool) -> int | None:
    if binary:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
            return None
        doc = json.loads(f.read(int.from_bytes(head[12:16], "little")))
    else:
        doc = json.load(f)
    accessors = doc.get("accessors", [])
    count = 0
    for mesh in doc.get("meshes", []):
        for primitive in mesh.get("primitives", []):
            if primitive.get("mode", _GLTF_TRIANGLES) != _GLTF_TRIANGLES:
                continue
            at = primitive.get("indices", primitive.get("attributes", {}).get("POSITION"))
            if at is None:
                continue
            count += int(accessors[at]["count"]) // 3
    return count


def _face_count(loaded: object) -> int:
    if isinstance(loaded, trimesh.Scene):
        return sum(len(g.faces) for g in loaded.geometry.values() if isinstance(g, trimesh.Trimesh))
    return len(getattr(loaded, "faces", ()))


def referenced_files(path: str | Path) -> list[tuple[str, Path]]:
    """The files a mesh file names beside itself, as ``(name as written, path)``: an
    OBJ's material libraries and their ``map_*`` images, a glTF's external images and
    buffers (embedded ``data:`` ones and GLB files need nothing outside). A library that
    cannot be read names nothing more."""
    path = Path(path)
    folder = path.parent
    suffix = path.suffix.lower()
    out: list[tuple[str, Path]] = []
    try:
        if suffix == ".obj":
            with open_regular(path, "r", encoding="utf-8", errors="replace") as lines:
                libraries = [line.split(None, 1)[1].strip() for line in lines
                             if line.startswith("mtllib") and len(line.split(None, 1)) == 2]
            for library in libraries:
                mtl = folder / library
                out.append((library, mtl))
                if not_regular(mtl) is not None:
                    continue
                with open_regular(mtl, "r", encoding="utf-8", errors="replace") as lines:
                    for line in lines:
                        parts = line.strip().split()
                        if parts and parts[0].lower().startswith("map_") and len(parts) >= 2:
                            # options (-s 1 1 1 ...) come before the file
                            out.append((parts[-1], mtl.parent / parts[-1]))
        elif suffix == ".gltf":
            with open_regular(path, "r", encoding="utf-8") as f:
                doc = json.load(f)
            for key in ("images", "buffers"):
                for item in doc.get(key, []) if isinstance(doc, dict) else []:
                    uri = item.get("uri") if isinstance(item, dict) else None
                    if isinstance(uri, str) and not uri.startswith("data:"):
                        out.append((uri, folder / unquote(uri)))
    except (OSError, ValueError):
        return out  # an unreadable file is reported by the loader
    return out


def missing_textures(path: str | Path) -> list[str]:
    """Texture files (and material libraries, glTF buffers) a mesh file names that do not
    exist next to it (:func:`referenced_files`)."""
    return [name for name, ref in referenced_files(path) if not_regular(ref) == "does not exist"]


def _check_references(path: Path, options: LoadOptions) -> None:
    """Refuse a mesh naming a file that is there but not a regular file (a FIFO would
    block the loader for good), and unless allowed one naming a missing file."""
    missing = []
    for name, ref in referenced_files(path):
        why = not_regular(ref)
        if why == "does not exist":
            missing.append(name)
        elif why is not None:
            raise MeshError(f"names the file {name!r}, which {why}", path)
    if missing and not options.allow_missing_textures:
        raise MeshError(
            f"names texture file {missing[0]!r}, which does not exist"
            + (f" (and {len(missing) - 1} more)" if len(missing) > 1 else "")
            + "; restore it, or ingest untextured with `allow_missing_textures`=True",
            path,
        )


def mesh_from_glb(data: bytes, name: str) -> NormalisedMesh:
    """Rebuild an already normalised mesh from the GLB blob a database stores."""
    load = trimesh.load  # imports trimesh: a core install without it fails here, not below
    with interrupts_held():  # see the module doc
        try:
            loaded = load(io.BytesIO(data), file_type="glb", process=False)
        except Exception as exc:
            raise MeshError(f"stored mesh of object {name!r} cannot be decoded: {_short(exc)}") from exc
        scene = _as_scene(loaded, name)
    return NormalisedMesh(name=name, scene=scene, centre=np.zeros(3), scale=1.0)


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:200]


def _as_scene(loaded: object, where: str | Path) -> trimesh.Scene:
    if isinstance(loaded, trimesh.Scene):
        return loaded
    if isinstance(loaded, trimesh.Trimesh):
        return trimesh.Scene(loaded)
    raise MeshError(f"holds no triangle mesh (got {type(loaded).__name__})", where)


def _baked_meshes(scene: trimesh.Scene) -> list[trimesh.Trimesh]:
    """Each triangle geometry of the scene with its node transform applied (visuals kept)."""
    meshes = []
    for node in scene.graph.nodes_geometry:
        transform, geometry_name = scene.graph[node]
        geometry = scene.geometry.get(geometry_name)
        if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
            continue
        baked = geometry.copy()
        _keep_texture_images(geometry, baked)
        baked.apply_transform(transform)
        meshes.append(baked)
    return meshes


def _keep_texture_images(original: trimesh.Trimesh, copy: trimesh.Trimesh) -> None:
    """Share the original PIL texture images with the copy.

    ``Trimesh.copy`` copies images and loses their ``format``, and the GLB exporter keeps
    JPEG textures as JPEG only when ``format == "JPEG"``: without this a stored mesh grows
    several-fold (JPEG re-encoded as PNG).
    """
    src = getattr(original.visual, "material", None)
    dst = getattr(copy.visual, "material", None)
    if src is None or dst is None:
        return
    for attr in ("image", "baseColorTexture", "emissiveTexture", "normalTexture",
                 "occlusionTexture", "metallicRoughnessTexture"):
        image = getattr(src, attr, None)
        if image is not None and hasattr(image, "format") and hasattr(dst, attr):
            try:
                setattr(dst, attr, image)
            except Exception:  # noqa: S112 - read-only property on some material types
                continue


def _concatenate(scene: trimesh.Scene) -> trimesh.Trimesh:
    meshes = _baked_meshes(scene)
    vertices, faces, offset = [], [], 0
    for m in meshes:
        vertices.append(np.asarray(m.vertices, dtype=np.float64))
        faces.append(np.asarray(m.faces, dtype=np.int64) + offset)
        offset += len(m.vertices)
    if not meshes:
        return trimesh.Trimesh()
    return trimesh.Trimesh(np.vstack(vertices), np.vstack(faces), process=False)


def _normalise(
    loaded: object, name: str, source: str, content_hash: str, where: str | Path
) -> NormalisedMesh:
    scene = _as_scene(loaded, where)
    meshes = _baked_meshes(scene)
    if not meshes:
        raise MeshError("holds no triangles", where)
    vertices = np.vstack([np.asarray(m.vertices, dtype=np.float64) for m in meshes])
    if not np.all(np.isfinite(vertices)):
        raise MeshError("has non-finite vertex coordinates", where)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo + hi) / 2.0
    scale = float(np.linalg.norm(vertices - centre, axis=1).max())
    if not scale > 0:
        raise MeshError("has no extent (all vertices coincide)", where)
    transform = np.diag([1.0 / scale] * 3 + [1.0])
    transform[:3, 3] = -centre / scale
    out = trimesh.Scene()
    area = 0.0
    for i, mesh in enumerate(meshes):
        mesh.apply_transform(transform)
        area += float(mesh.area)
        out.add_geometry(mesh, geom_name=f"part_{i:03d}")
    if not area > MIN_AREA:
        raise MeshError("has no surface area (degenerate triangles only)", where)
    return NormalisedMesh(
        name=name, scene=out, centre=centre, scale=scale, source=source, content_hash=content_hash
    )
