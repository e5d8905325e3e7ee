"""How the DTW band and the gravity hint's roll tolerance trade rank against search time.

    python benchmarks/band_study.py DB [--seeds 1-6] [--photos 40] [--bands 6,5,4]
                                       [--roll-tolerances 15,10,8] [--roll-band 5]

Each photo of ``benchmarks/photo_accuracy.py`` (same seed, same photos) is queried without
pose once per setting, the settings in turn on the same photo so that load affects them
alike: first every ``--bands`` value with full in-plane invariance, then every
``--roll-tolerances`` value with the gravity hint ``roll=0`` (the photos are upright) at
band ``--roll-band``. Printed per setting: rank-1 and rank-5 of the right object, and the
median search time (the server stage) and whole query, with each setting's median search
time against the first setting of its group (the baseline of the same run).
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import dataclass, field

import viewdb
from viewdb.bench.photos import parse_seeds, seed_photos
from viewdb.config import RecognitionConfig
from viewdb.recognition.options import QueryOptions


@dataclass
class Tally:
    ranks: list[int] = field(default_factory=list)
    search_ms: list[float] = field(default_factory=list)
    total_ms: list[float] = field(default_factory=list)

    def line(self, label: str, baseline: float) -> str:
        n = len(self.ranks)
        search = statistics.median(self.search_ms)
        return (f"{label:<22} rank-1 {sum(r == 1 for r in self.ranks) / n:6.1%}  rank-5 "
                f"{sum(r <= 5 for r in self.ranks) / n:6.1%}  search {search:6.0f} ms "
                f"({search / baseline:.2f}x)  whole {statistics.median(self.total_ms):6.0f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--bands", default="6,5,4")
    parser.add_argument("--roll-tolerances", default="15,10,8")
    parser.add_argument("--roll-band", type=int, default=5)
    args = parser.parse_args()
    settings = [(f"band {b}", QueryOptions(pose=False, band=int(b))) for b in args.bands.split(",") if b]
    settings += [(f"roll 0 ±{t}°, band {args.roll_band}",
                  QueryOptions(pose=False, roll=0.0, band=args.roll_band,
                               recognition=RecognitionConfig(roll_tolerance=float(t))))
                 for t in args.roll_tolerances.split(",") if t]
    tallies = {label: Tally() for label, _ in settings}
    with viewdb.open(args.db, read_only=True) as db:
        for seed in parse_seeds(args.seeds):
            photos = seed_photos(db, str(seed), args.photos)
            db.query(photos[0][1], pose=False)  # warm
            for spec, image in photos:
                for label, options in settings:
                    start = time.perf_counter()
                    result = db.query(image, options=options)
                    tally = tallies[label]
                    tally.total_ms.append((time.perf_counter() - start) * 1e3)
                    tally.search_ms.append(result.timing_ms.get("server", 0.0))
                    names = [m.object for m in result.results]
                    tally.ranks.append(names.index(spec.object) + 1 if spec.object in names else 99)
            print(f"after seed {seed}: {len(tallies[settings[0][0]].ranks)} photos", flush=True)
    groups = [[s for s in settings if s[1].roll is None], [s for s in settings if s[1].roll is not None]]
    for group in groups:
        if not group:
            continue
        baseline = statistics.median(tallies[group[0][0]].search_ms)
        for label, _ in group:
            print(tallies[label].line(label, baseline))


if __name__ == "__main__":
    main()
