"""Training throughput of the space-time planner by raster size (`riskmap train --raster-px`).

One epoch of the same windows at each size, the sizes interleaved in one process and repeated
(`--repeats`), after one untimed epoch per size that fills the sample cache (each size has its
own raster cache; the per-step maps are shared). Reports the median training windows per second
(the pass over the training windows alone, as `bench_train.py`) and each size's ratio to the
first. Half of every epoch's windows are drawn afresh (the perturbed-ego augmentation), so the
sample building stays in the measurement, as in a real run.

    .venv/bin/python experiments/bench_raster_size.py --data data/highway [--sizes 200,100] \
        [--max-windows 192] [--repeats 3] [--init-checkpoint checkpoints/riskmap_highway] \
        [--out experiments/results/spacetime/bench_raster_size.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
from dataclasses import replace
from pathlib import Path

import torch
from bench_train import _busy_cpu_s, _own_cpu_s

from riskmap.training.config import TrainConfig
from riskmap.training.train import train


def one_epoch(config: TrainConfig, out: Path) -> dict:
    records: list[dict] = []
    busy, own = _busy_cpu_s(), _own_cpu_s()
    train(replace(config, out=str(out)), progress=False,
          on_epoch=lambda epoch, record: records.append(record))
    return records[0] | {"others_cpu_s": (_busy_cpu_s() - busy) - (_own_cpu_s() - own)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--sizes", default="200,100", help="raster pixels a side, comma-separated")
    parser.add_argument("--max-windows", type=int, default=192)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--init-checkpoint", default=None)
    parser.add_argument("--out", type=Path)
    cli = parser.parse_args()
    sizes = [int(v) for v in cli.sizes.split(",")]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        base = TrainConfig(data=cli.data, out="", epochs=1, max_windows=cli.max_windows,
                           device="cpu", planner="spacetime", cache=str(tmp / "cache"),
                           init_checkpoint=cli.init_checkpoint, seed=0)
        runs: dict[int, list[dict]] = {px: [] for px in sizes}
        for px in sizes:                                    # fill each size's cache, untimed
            one_epoch(replace(base, raster_px=px), tmp / f"warm{px}")
        for repeat in range(cli.repeats):
            for px in sizes:
                runs[px].append(one_epoch(replace(base, raster_px=px), tmp / f"r{repeat}_{px}"))
    rows = []
    for px in sizes:
        train_s = statistics.median(r["train_s"] for r in runs[px])
        rows.append({"raster_px": px, "train_windows": runs[px][0]["train_windows"],
                     "windows_per_s": round(runs[px][0]["train_windows"] / train_s, 2),
                     "median_train_s": round(train_s, 2),
                     "median_data_wait_s": round(statistics.median(r["data_s"] for r in runs[px]), 2),
                     "others_cpu_s": [round(r["others_cpu_s"], 1) for r in runs[px]]})
    first = rows[0]["windows_per_s"]
    print(f"{'raster px':>9} {'windows/s':>10} {'train s':>8} {'waiting for data s':>19} {'ratio':>6}")
    for row in rows:
        row["ratio_to_first"] = round(row["windows_per_s"] / first, 2)
        print(f"{row['raster_px']:9d} {row['windows_per_s']:10.2f} {row['median_train_s']:8.2f} "
              f"{row['median_data_wait_s']:19.2f} {row['ratio_to_first']:6.2f}")
    if cli.out:
        cli.out.parent.mkdir(parents=True, exist_ok=True)
        cli.out.write_text(json.dumps({
            "rows": rows, "repeats": cli.repeats, "data": cli.data, "threads": torch.get_num_threads(),
            "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
            "torch": torch.__version__}, indent=2) + "\n")


if __name__ == "__main__":
    main()
