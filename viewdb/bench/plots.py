"""The figures of a benchmark run (matplotlib, the ``bench`` extra): Fig. 6 (CMC of S1–S6)
and Fig. 7 (total time against the client grid gap for k = 1..5, CS1 and CS2)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import ViewDBError

__all__ = ["plot_cmc", "plot_time_split", "plot_time_vs_gap"]

_COLOURS = {"server": "tab:blue", "cs1": "tab:orange", "cs2": "tab:green"}
_MARKERS = {"server": "o", "cs1": "s", "cs2": "^"}
_SHIFT = {"server": -0.05, "cs1": 0.0, "cs2": 0.05}


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError as exc:
        raise ViewDBError("plots need matplotlib: pip install 'viewdb[bench]'") from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_cmc(accuracy: dict[str, dict[str, Any]], path: Path, max_rank: int) -> None:
    """``accuracy[protocol][label]`` has ``plan``, ``skim``, ``cmc``, ``n``."""
    plt = _pyplot()
    protocols = list(accuracy)
    fig, axes = plt.subplots(1, len(protocols), figsize=(5.2 * len(protocols), 4.2), squeeze=False)
    ranks = list(range(1, max_rank + 1))
    for ax, protocol in zip(axes[0], protocols, strict=True):
        low = 1.0
        for label, row in accuracy[protocol].items():
            # equal curves would hide each other: plans are shifted apart slightly in x,
            # skimmed drawn thick and faint, unskimmed thin and dashed on top
            shift = _SHIFT[row["plan"]]
            ax.plot([r + shift for r in ranks], row["cmc"], marker=_MARKERS[row["plan"]],
                    color=_COLOURS[row["plan"]], linestyle="-" if row["skim"] else "--",
                    linewidth=3.5 if row["skim"] else 1.2, alpha=0.45 if row["skim"] else 1.0,
                    markersize=7 if row["skim"] else 4,
                    label=f"{label} {row['plan']}{'' if row['skim'] else ' no skim'}")
            low = min(low, min(row["cmc"]))
        ax.set_title(f"CMC, {protocol} queries (n = {next(iter(accuracy[protocol].values()))['n']}; "
                     "plans shifted apart in x)", fontsize=10)
        ax.set_xlabel("rank")
        ax.set_ylabel("identification rate")
        ax.set_xticks(ranks)
        ax.set_ylim(max(0.0, low - 0.05), 1.005)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_time_vs_gap(timing: list[dict[str, Any]], path: Path, protocol: str) -> None:
    """Median total (client + server) ms against the client gap, a line per k; panels
    CS1 / CS2 × skimmed / full grid; the server alone as a dotted line per k."""
    plt = _pyplot()
    rows = [r for r in timing if r["protocol"] == protocol]
    ks = sorted({r["k"] for r in rows})
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.5), sharex=True)
    cmap = plt.get_cmap("viridis")
    for i, skim in enumerate((True, False)):
        for j, plan in enumerate(("cs1", "cs2")):
            ax = axes[i][j]
            for n, k in enumerate(ks):
                colour = cmap(n / max(1, len(ks) - 1) * 0.9)
                line = sorted((r["client_gap"], r["total_median_ms"]) for r in rows
                              if r["plan"] == plan and r["skim"] == skim and r["k"] == k)
                if line:
                    ax.plot([g for g, _ in line], [t for _, t in line], marker="o",
                            color=colour, label=f"k = {k}")
                server = [r["total_median_ms"] for r in rows
                          if r["plan"] == "server" and r["skim"] == skim and r["k"] == k]
                if server:
                    ax.axhline(server[0], color=colour, linestyle=":", linewidth=1)
            ax.set_title(f"{plan.upper()}, {'with' if skim else 'without'} skimming "
                         "(dotted: server alone)", fontsize=10)
            ax.set_xlabel("client grid gap (degrees)")
            ax.set_ylabel("total time, median (ms)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_time_split(timing: list[dict[str, Any]], path: Path, protocol: str, k: int) -> None:
    """Client and server halves (median ms, stacked) per configuration and client gap at k."""
    plt = _pyplot()
    rows = sorted((r for r in timing if r["protocol"] == protocol and r["k"] == k),
                  key=lambda r: (not r["skim"], r["plan"], r["client_gap"] or 0))
    labels = [f"{r['plan']}{'' if r['client_gap'] is None else ' ' + format(r['client_gap'], 'g')}"
              f"{'' if r['skim'] else '*'}" for r in rows]
    client = [r["client_median_ms"] for r in rows]
    server = [r["server_median_ms"] for r in rows]
    fig, ax = plt.subplots(figsize=(max(6, 0.55 * len(rows)), 4))
    xs = range(len(rows))
    ax.bar(xs, client, color="tab:orange", label="client")
    ax.bar(xs, server, bottom=client, color="tab:blue", label="server")
    ax.set_xticks(list(xs), labels, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("median ms")
    ax.set_title(f"client and server time at k = {k} ({protocol} queries; * = without skimming)")
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
