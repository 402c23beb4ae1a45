"""AP, AUC and F1 of a guard checkpoint per split, scenario family and source (natural, scripted
aggressive, CRASH, search), with the windows labelled for the checkpoint's horizon.

    python experiments/guard_family_ap.py --checkpoint checkpoints/guard_tgat --data data/guard/all \
        --splits val,seen,unseen --out experiments/results/guard/warns/family_ap.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from riskmap.guard.dataset import labels_for, load_job
from riskmap.guard.metrics import binary_metrics
from riskmap.guard.predictor import AccidentPredictor
from riskmap.guard.train import predict
from riskmap.infra.atomic import write_json


def group_of(job_name: str) -> tuple[str, str]:
    """(family, source) of a job file name (`riskmap.guard.dataset.Job.name`, `adversary guard-data`'s)."""
    parts = job_name.split("_")
    if parts[1] == "adv":
        return parts[2], "crash"
    if parts[1] == "search":
        return "highway", "search"
    return parts[1].split("-")[0], {"agg": "aggressive", "nat": "natural"}[parts[-1]]


def main() -> None:
    import torch

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", default="checkpoints/guard_tgat")
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--splits", default="val,seen,unseen")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    predictor = AccidentPredictor.load(args.checkpoint)
    horizon = predictor.model.config.horizon_s
    rows = []
    for split in args.splits.split(","):
        groups: dict = {}
        for path in sorted((args.data / "jobs").glob(f"{split}_*.npz")):
            groups.setdefault(group_of(path.stem), []).append(load_job(path))
        for (family, source), jobs in sorted(groups.items()):
            tensors = tuple(torch.from_numpy(np.concatenate([j[k] for j in jobs]))
                            for k in ("node_u", "node_i", "edge", "mask"))
            probs, _ = predict(predictor.model, (tensors[0].float(), tensors[1].float(), tensors[2].float(),
                                                 tensors[3].bool()))
            labels = labels_for(np.concatenate([j["ttc_s"] for j in jobs]), horizon)
            m = binary_metrics(labels, probs, predictor.alert_threshold)
            rows.append({"split": split, "family": family, "source": source, "episodes": len(jobs), **m})
            ap = "–" if m["ap"] is None else f"{m['ap']:.3f}"
            auc = "–" if m["auc"] is None else f"{m['auc']:.3f}"
            print(f"| {split} | {family} | {source} | {len(jobs)} | {m['n']} ({m['positives']}) | {ap} | {auc} | "
                  f"{m['f1']:.3f} |")
    if args.out:
        write_json(args.out, {"checkpoint": args.checkpoint, "horizon_s": horizon,
                              "alert_threshold": predictor.alert_threshold, "rows": rows})


if __name__ == "__main__":
    main()
