"""What a benchmark run measures: the paper's configurations and the run's settings.

Table 1 of Tak & Hwang (section IV.A) crosses three platforms with camera view skimming
on or off; :data:`CONFIGURATIONS` is that table. :class:`BenchConfig` holds everything a
run depends on, validated before any file is touched.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..config import BuildConfig, IndexConfig, RenderConfig
from ..errors import ViewDBError

__all__ = ["CONFIGURATIONS", "PROTOCOLS", "BenchConfig", "Configuration", "MissConfig", "TwinConfig"]

#: Query protocols: ``grid`` is the paper's (a view at a random grid pose of a random
#: object, rendered from its mesh); ``photo`` an off-grid perspective render with random
#: lighting, a plain background colour, noise and JPEG compression, queried as an image.
PROTOCOLS = ("grid", "photo")


@dataclass(frozen=True)
class Configuration:
    """One row of the paper's Table 1."""

    label: str
    plan: str
    skim: bool

    @property
    def description(self) -> str:
        platform = {"server": "Server alone", "cs1": "CS1", "cs2": "CS2"}[self.plan]
        return f"{platform} {'with' if self.skim else 'without'} camera view skimming"


#: S1–S6 (Table 1).
CONFIGURATIONS = (
    Configuration("S1", "server", True),
    Configuration("S2", "cs1", True),
    Configuration("S3", "cs2", True),
    Configuration("S4", "server", False),
    Configuration("S5", "cs1", False),
    Configuration("S6", "cs2", False),
)


@dataclass(frozen=True)
class BenchConfig:
    """A benchmark run (defaults: the paper's setting, section IV)."""

    #: Folder of mesh files (every supported file in it is a model).
    models: Path
    #: Folder for the results (JSON, CSV, PNG, markdown) and the per-query log.
    out: Path
    #: Queries per protocol.
    queries: int = 100
    seed: int = 0
    #: Client grid gaps of the time experiment (Fig. 7), multiples of ``gap``.
    gaps: tuple[float, ...] = (20.0, 30.0, 40.0, 50.0)
    #: Largest k (CMC ranks 1..k; the time experiment runs k = 1..k).
    k: int = 5
    #: Worker processes for ingest.
    jobs: int = 1
    #: Use only this many models (evenly spaced over the sorted file names); None: all.
    subset: int | None = None
    #: Where the databases are built and kept (default ``out/cache``).
    cache: Path | None = None
    #: Server grid gap.
    gap: float = 10.0
    #: Client grid gap of the accuracy experiment (Fig. 6: 30°).
    client_gap: float = 30.0
    image_size: int = 256
    protocols: tuple[str, ...] = PROTOCOLS
    #: Sakoe–Chiba band of the DTW (samples).
    band: int = 6
    #: In-plane turns tried per photo query (the query engine's default).
    rotations: int = 8
    #: Timing experiment on these protocols (Fig. 7 uses the paper's).
    timing_protocols: tuple[str, ...] = field(default=("grid",))

    def __post_init__(self) -> None:
        def bad(message: str) -> ViewDBError:
            return ViewDBError(message)

        if self.queries < 1:
            raise bad(f"`queries` must be at least 1, got {self.queries}")
        if not 1 <= self.k <= 100:
            raise bad(f"`k` must be in [1, 100], got {self.k}")
        if self.jobs < 1:
            raise bad(f"`jobs` must be at least 1, got {self.jobs}")
        if self.subset is not None and self.subset < 1:
            raise bad(f"`subset` must be at least 1, got {self.subset}")
        if not self.gaps:
            raise bad("`gaps` needs at least one client gap")
        for p in self.protocols + self.timing_protocols:
            if p not in PROTOCOLS:
                raise bad(f"protocol must be one of {', '.join(PROTOCOLS)}, got {p!r}")
        if not self.protocols:
            raise bad("at least one protocol is needed")
        try:
            for g in self.client_gaps:
                self.build_config(g)
        except ValueError as exc:
            raise bad(f"{exc}") from exc

    @property
    def client_gaps(self) -> tuple[float, ...]:
        """Every client gap a client file is needed for, ascending."""
        return tuple(sorted({float(g) for g in self.gaps} | {float(self.client_gap)}))

    @property
    def cache_dir(self) -> Path:
        return self.cache if self.cache is not None else self.out / "cache"

    def build_config(self, client_gap: float | None = None) -> BuildConfig:
        """The databases' build configuration (client gap: the full db's own sparse tier)."""
        return BuildConfig(
            gap=float(self.gap), render=RenderConfig(image_size=self.image_size),
            index=IndexConfig(client_gap=None if client_gap is None else float(client_gap)),
        ).resolved()

    def fingerprint(self, models: list[str]) -> dict[str, Any]:
        """What the per-query results depend on: a results log written under another
        fingerprint must not be continued."""
        return {
            "models": hashlib.sha256("\n".join(models).encode()).hexdigest()[:16],
            "n_models": len(models), "queries": self.queries, "seed": self.seed,
            "gap": float(self.gap), "image_size": self.image_size, "band": self.band,
            "rotations": self.rotations,
        }

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["models"], out["out"] = str(self.models), str(self.out)
        out["cache"] = str(self.cache_dir)
        return json.loads(json.dumps(out))


@dataclass(frozen=True)
class TwinConfig:
    """The twin test (:mod:`viewdb.bench.twins`): when two meshes are near-identical."""

    #: Random surface points per mesh (dense: they stand for the surface), and how many of
    #: them are measured from.
    samples: int = 20000
    probes: int = 2000
    #: Twins have a twin distance (symmetric chamfer, in RMS radii) at most this.
    threshold: float = 0.03
    #: Best axis alignments refined by ICP, and ICP's most iterations.
    icp_starts: int = 4
    icp_iterations: int = 30
    #: Seed of the surface sampling.
    seed: int = 0

    def __post_init__(self) -> None:
        if not 10 <= self.probes <= self.samples or self.threshold < 0:
            raise ValueError("need 10 <= probes <= samples and threshold >= 0")
        if self.icp_starts < 1 or self.icp_iterations < 0:
            raise ValueError("need icp_starts >= 1 and icp_iterations >= 0")


@dataclass(frozen=True)
class MissConfig:
    """How a recognition miss is classified (:mod:`viewdb.bench.misses`)."""

    #: A miss whose automatic mask has an IoU below this with the true silhouette is a
    #: segmentation miss.
    min_iou: float = 0.9
    #: The search's shortlist: a miss whose object is not among the search's best this many
    #: (by outline alone, before the colour and shape re-rankings) is a recall miss.
    shortlist: int = 10
    twins: TwinConfig = field(default_factory=TwinConfig)

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_iou <= 1.0 or not 1 <= self.shortlist <= 100:
            raise ValueError("need 0 <= min_iou <= 1 and 1 <= shortlist <= 100")
