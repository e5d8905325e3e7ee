"""Writing a run's outputs: results JSON and CSVs, the figures, markdown tables.

Files (in ``out``): ``results.json`` (everything below), ``accuracy.csv`` (CMC per
protocol and configuration), ``timing.csv`` (per protocol, skimming, plan, client gap, k),
``index.md`` (index sizes and build times), ``report.md`` (all tables and the findings the
paper states, checked), ``cmc.png``, ``time_vs_gap.png``, ``time_split.png``.
"""

from __future__ import annotations

import csv
import json
import os
from collections import defaultdict
from pathlib import Path
from typing import Any

from .config import CONFIGURATIONS, BenchConfig
from .log import ResultLog
from .metrics import cmc, rank_of, timing_summary
from .plots import plot_cmc, plot_time_split, plot_time_vs_gap
from .tasks import plan_tasks

__all__ = ["summarise", "write_report"]


def summarise(config: BenchConfig, records: list[dict[str, Any]]) -> dict[str, Any]:
    """Accuracy (CMC of S1–S6 per protocol), timing rows and the paper's claims checked."""
    by_key = {r["key"]: r for r in records}
    accuracy: dict[str, dict[str, Any]] = {}
    for protocol in config.protocols:
        rows: dict[str, Any] = {}
        for c in CONFIGURATIONS:
            gap = None if c.plan == "server" else float(config.client_gap)
            recs = [r for r in records if r["protocol"] == protocol and r["skim"] == c.skim
                    and r["plan"] == c.plan and r["client_gap"] == gap and r["k"] == config.k]
            if not recs:
                continue
            rows[c.label] = {
                **timing_summary(recs),
                "description": c.description, "plan": c.plan, "skim": c.skim,
                "client_gap": gap, "k": config.k, "n": len(recs),
                "errors": sum(r["error"] is not None for r in recs),
                "cmc": cmc((rank_of(r["truth"], r["results"]) for r in recs), config.k),
            }
        if rows:
            accuracy[protocol] = rows
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = defaultdict(list)
    for r in records:
        if r["protocol"] in config.timing_protocols:
            groups[r["protocol"], r["skim"], r["plan"], r["client_gap"], r["k"]].append(r)
    timing = [
        {"protocol": p, "skim": s, "plan": plan, "client_gap": g, "k": k, **timing_summary(recs)}
        for (p, s, plan, g, k), recs in sorted(
            groups.items(), key=lambda x: (x[0][0], not x[0][1], x[0][2], x[0][3] or 0, x[0][4]))
    ]
    return {"accuracy": accuracy, "timing": timing, "findings": _findings(config, by_key, timing)}


def _same(by_key: dict[str, dict[str, Any]], a: str, b: str, what: str) -> float | None:
    """Share of queries where configurations ``a`` and ``b`` (keys without the query
    number, as ``protocol/{}/...``) agree on ``what`` (``rank`` or ``results``)."""
    pairs = []
    for key, ra in by_key.items():
        parts = key.split("/")
        if "/".join(parts[:1] + ["{}"] + parts[2:]) != a:
            continue
        rb = by_key.get(b.replace("{}", parts[1]))
        if rb is not None:
            pairs.append((ra, rb))
    if not pairs:
        return None
    if what == "rank":
        same = [rank_of(x["truth"], x["results"]) == rank_of(y["truth"], y["results"]) for x, y in pairs]
    else:
        same = [x["results"] == y["results"] for x, y in pairs]
    return sum(same) / len(same)


def _findings(config: BenchConfig, by_key: dict[str, dict[str, Any]],
              timing: list[dict[str, Any]]) -> dict[str, Any]:
    k, g = config.k, f"{config.client_gap:g}"
    out: dict[str, Any] = {}
    for protocol in config.protocols:
        def key(skim: bool, plan: str, gap: str | None = g, protocol: str = protocol) -> str:
            return (f"{protocol}/{{}}/{'skim' if skim else 'noskim'}/{plan}/"
                    f"{'-' if plan == 'server' else gap}/{k}")

        out[protocol] = {
            "S1_S4_same_rank": _same(by_key, key(True, "server"), key(False, "server"), "rank"),
            "S2_S5_same_rank": _same(by_key, key(True, "cs1"), key(False, "cs1"), "rank"),
            "S2_equals_S1_results": _same(by_key, key(True, "cs1"), key(True, "server"), "results"),
            "S5_equals_S4_results": _same(by_key, key(False, "cs1"), key(False, "server"), "results"),
            "S3_equals_S1_results": _same(by_key, key(True, "cs2"), key(True, "server"), "results"),
            "S6_equals_S4_results": _same(by_key, key(False, "cs2"), key(False, "server"), "results"),
        }
    best: dict[str, Any] = {}
    for row in timing:
        if row["plan"] == "server":
            continue
        name = f"{row['protocol']}/{'skim' if row['skim'] else 'noskim'}/{row['plan']}/k{row['k']}"
        if name not in best or row["total_median_ms"] < best[name][1]:
            best[name] = (row["client_gap"], row["total_median_ms"])
    out["fastest_client_gap"] = {n: gap for n, (gap, _) in sorted(best.items())}
    return out


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.1f} %"


def _ms(x: float) -> str:
    return f"{x:.2f}" if x == x else "–"


def _bytes(n: int | float | None) -> str:
    if n is None:
        return "–"
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.2f} {unit}"
    return f"{int(n)} B"


def index_table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| file | kind | skimming | grid gap | objects | views (rows) | of grid | R-tree entries "
        "| R-tree bytes | file bytes | build wall s | Σ per-object s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        grid = f"{r['views'] / r['views_grid']:.1%}" if r.get("views_grid") else "–"
        build = "–" if r["build_seconds"] is None else f"{r['build_seconds']:.1f}" + (
            f" (jobs {r['jobs']})" if r.get("jobs") else "")
        lines.append(
            f"| {r['file']} | {r['kind']} | {'yes' if r['skim'] else 'no'} | {r['gap']:g}° "
            f"| {r['objects']} | {r['views']:,} | {grid} | {r['rtree_entries']:,} "
            f"| {_bytes(r['rtree_bytes'])} | {_bytes(r['file_bytes'])} | {build} "
            f"| {'–' if r['object_seconds'] is None else format(r['object_seconds'], '.1f')} |"
        )
    return "\n".join(lines) + "\n"


def _accuracy_table(config: BenchConfig, rows: dict[str, Any]) -> str:
    head = "| config | description | n | " + " | ".join(f"rank {i}" for i in range(1, config.k + 1))
    lines = [head + " | errors | client ms | server ms | total ms (medians) |",
             "|---" * (config.k + 7) + "|"]
    for label, r in rows.items():
        rates = " | ".join(f"{100 * x:.1f} %" for x in r["cmc"])
        lines.append(f"| {label} | {r['description']} | {r['n']} | {rates} | {r['errors']} "
                     f"| {_ms(r['client_median_ms'])} | {_ms(r['server_median_ms'])} "
                     f"| {_ms(r['total_median_ms'])} |")
    return "\n".join(lines) + "\n"


def _timing_table(timing: list[dict[str, Any]], k: int) -> str:
    lines = ["| protocol | skimming | plan | client gap | k | n | client ms | server ms | total ms "
             "| total ms (mean) | sent | received |", "|---" * 12 + "|"]
    for r in timing:
        if r["k"] != k and r["plan"] != "server":
            continue
        lines.append(
            f"| {r['protocol']} | {'yes' if r['skim'] else 'no'} | {r['plan']} "
            f"| {'–' if r['client_gap'] is None else format(r['client_gap'], 'g') + '°'} | {r['k']} "
            f"| {int(r['n'])} | {_ms(r['client_median_ms'])} | {_ms(r['server_median_ms'])} "
            f"| {_ms(r['total_median_ms'])} | {_ms(r['total_mean_ms'])} "
            f"| {_bytes(r['bytes_sent_mean'])} | {_bytes(r['bytes_received_mean'])} |"
        )
    return "\n".join(lines) + "\n"


def _write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_report(
    config: BenchConfig, log: ResultLog, queries: dict[str, list[Any]],
    index_rows: list[dict[str, Any]], names: list[str],
) -> tuple[dict[str, Path], dict[str, Any]]:
    """Write every output file; returns ``name -> path`` and the results summary."""
    out = config.out
    wanted = {t for t in _wanted_keys(config)}
    records = [r for r in log if r["key"] in wanted]
    summary = summarise(config, records)
    summary.update(config=config.to_dict(), objects=len(names), object_names=names,
                   index=index_rows, queries={p: len(q) for p, q in queries.items()})
    files = {"results.json": out / "results.json", "accuracy.csv": out / "accuracy.csv",
             "timing.csv": out / "timing.csv", "index.md": out / "index.md",
             "report.md": out / "report.md"}
    _write(files["results.json"], json.dumps(summary, indent=2))
    with files["accuracy.csv"].open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["protocol", "config", "plan", "skim", "client_gap", "n", "errors"]
                   + [f"rank{i}" for i in range(1, config.k + 1)]
                   + ["client_median_ms", "server_median_ms", "total_median_ms"])
        for protocol, rows in summary["accuracy"].items():
            for label, r in rows.items():
                w.writerow([protocol, label, r["plan"], r["skim"], r["client_gap"], r["n"], r["errors"]]
                           + [round(x, 6) for x in r["cmc"]]
                           + [round(r[k], 4) for k in ("client_median_ms", "server_median_ms",
                                                       "total_median_ms")])
    fields = ["protocol", "skim", "plan", "client_gap", "k", "n", "client_median_ms",
              "server_median_ms", "total_median_ms", "client_mean_ms", "server_mean_ms",
              "total_mean_ms", "bytes_sent_mean", "bytes_received_mean"]
    with files["timing.csv"].open("w", newline="") as f:
        dw = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        dw.writeheader()
        dw.writerows(summary["timing"])
    _write(files["index.md"], index_table(index_rows))
    if summary["accuracy"]:
        files["cmc.png"] = out / "cmc.png"
        plot_cmc(summary["accuracy"], files["cmc.png"], config.k)
    for protocol in config.timing_protocols:
        if any(r["protocol"] == protocol for r in summary["timing"]):
            suffix = "" if protocol == "grid" else f"_{protocol}"
            files[f"time_vs_gap{suffix}.png"] = out / f"time_vs_gap{suffix}.png"
            plot_time_vs_gap(summary["timing"], files[f"time_vs_gap{suffix}.png"], protocol)
            files[f"time_split{suffix}.png"] = out / f"time_split{suffix}.png"
            plot_time_split(summary["timing"], files[f"time_split{suffix}.png"], protocol, config.k)
    _write(files["report.md"], _markdown(config, summary, index_rows, names))
    return files, summary


def _wanted_keys(config: BenchConfig) -> list[str]:
    return [t.key for t in plan_tasks(config)]


def _markdown(config: BenchConfig, summary: dict[str, Any], rows: list[dict[str, Any]],
              names: list[str]) -> str:
    parts = [
        "# viewdb bench\n",
        f"{len(names)} objects from `{config.models}` ({', '.join(names)}); server grid "
        f"{config.gap:g}°, images {config.image_size} px; {config.queries} queries per protocol, "
        f"seed {config.seed}; accuracy client grid {config.client_gap:g}°, k = {config.k}.\n",
        "## Index sizes and build times\n", index_table(rows),
    ]
    for protocol, acc in summary["accuracy"].items():
        parts += [f"\n## Accuracy, {protocol} queries (CMC)\n", _accuracy_table(config, acc)]
        f = summary["findings"].get(protocol, {})
        parts.append(
            f"\nSkimming keeps the rank of the right object: S1 = S4 on {_pct(f.get('S1_S4_same_rank'))}, "
            f"S2 = S5 on {_pct(f.get('S2_S5_same_rank'))} of queries. CS1 returns the server's "
            f"answer: S2 = S1 on {_pct(f.get('S2_equals_S1_results'))}, S5 = S4 on "
            f"{_pct(f.get('S5_equals_S4_results'))}. CS2 returns it on "
            f"{_pct(f.get('S3_equals_S1_results'))} (S3) and {_pct(f.get('S6_equals_S4_results'))} (S6).\n"
        )
    if summary["timing"]:
        parts += [f"\n## Time (medians per query; CS1/CS2 at k = {config.k}, server alone at every k)\n",
                  _timing_table(summary["timing"], config.k)]
        fastest = summary["findings"].get("fastest_client_gap", {})
        if fastest:
            parts.append("\nFastest client gap: " + "; ".join(
                f"{n} {g:g}°" for n, g in fastest.items()) + ".\n")
    return "\n".join(parts)
