"""The DeepRacer console's reward graph, drawn from ``RUN/metrics.csv``."""

from __future__ import annotations

import csv
from pathlib import Path


def _column(rows: list[dict[str, str]], key: str) -> tuple[list[int], list[float]]:
    xs, ys = [], []
    for row in rows:
        if row.get(key) not in (None, ""):
            xs.append(int(row["iteration"]))
            ys.append(float(row[key]))
    return xs, ys


def reward_graph(metrics_csv: str | Path, out_png: str | Path) -> Path:
    """Average reward and % completion (training, evaluation) per iteration; best lap."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with Path(metrics_csv).open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=(3, 1))
    xs, ys = _column(rows, "mean_reward")
    top.plot(xs, ys, color="tab:green", label="average reward (training)")
    top.set_ylabel("reward per episode")
    right = top.twinx()
    xs, ys = _column(rows, "mean_progress")
    right.plot(xs, ys, color="tab:blue", label="average % completion (training)")
    xs, ys = _column(rows, "eval_progress")
    right.plot(xs, ys, "o-", color="tab:red", label="average % completion (evaluation)")
    right.set_ylabel("% track completion")
    right.set_ylim(0, 105)
    handles = top.get_legend_handles_labels()[0] + right.get_legend_handles_labels()[0]
    top.legend(handles=handles, loc="upper left", fontsize="small")
    xs, ys = _column(rows, "eval_best_lap")
    bottom.plot(xs, ys, "s-", color="tab:purple")
    bottom.set_ylabel("best eval lap (s)")
    bottom.set_xlabel("iteration")
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=80)
    plt.close(fig)
    return out
