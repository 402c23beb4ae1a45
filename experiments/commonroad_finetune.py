"""The shipped highway planner on recorded human driving, before and after fine-tuning on it.

Data: windows cut from CommonRoad recordings (`riskmap collect --from-commonroad`), one shard per
recorded demonstrator. Held out by vehicle, k-fold: demonstrators are dealt round-robin (in
dataset order) into `folds` folds; for each fold a copy of the checkpoint is fine-tuned on the
windows of the other folds' vehicles (MaxEnt IRL step of `riskmap.planner.irl`, the loss and
augmentation `riskmap train` uses) and evaluated on the fold's own vehicles. Every window is thus
scored once by a model that never trained on its demonstrator (the other vehicles of the same
recording may appear around it in the raster: held out by vehicle, not by scene).

Metrics (experiments/eval_plans.window_errors), averaged over `plan_seeds` sampler seeds:
ADE / FDE of the 12 plan waypoints against the recorded human's 6 s future, and the goal error
(plan end to the centre of the goal cell the planner was given).

    .venv/bin/python -m riskmap collect --from-commonroad tests/fixtures/commonroad --out data/commonroad
    .venv/bin/python experiments/commonroad_finetune.py --data data/commonroad
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader, Subset

from rasterize.frames import ego_from_world, ego_pose
from riskmap.data.dataset import DemoDataset, PerturbedEgo
from riskmap.evaluation.open_loop import window_errors
from riskmap.infra.atomic import write_json
from riskmap.infra.checkpoint import save_checkpoint
from riskmap.planner.baselines import ConstantVelocityPlanner
from riskmap.planner.irl import IRLConfig, irl_step
from riskmap.planner.model import load_model
from riskmap.planner.riskmap_planner import RiskMapPlanner


@dataclass(frozen=True)
class FineTuneArgs:
    data: str                                     # dataset from `riskmap collect --from-commonroad`
    checkpoint: str = "checkpoints/riskmap_highway"
    out: str = "experiments/results/commonroad"   # result JSON and markdown table
    runs: str = "runs/commonroad_finetune"        # fine-tuned checkpoints, one per fold (--resume)
    folds: int = 4
    epochs: int = 15
    lr: float = 5e-4                              # as the shipped run
    batch_size: int = 4
    grad_clip: float = 10.0
    augment_probability: float = 0.5             # ego-pose perturbation, as `riskmap train`
    plan_seeds: int = 3
    seed: int = 0


def _vehicle_folds(dataset: DemoDataset, folds: int) -> list[list[int]]:
    episodes = sorted({dataset.episode_of(i) for i in range(len(dataset))})
    if len(episodes) < folds:
        raise SystemExit(f"{len(episodes)} demonstrators cannot make {folds} folds; lower --folds")
    return [episodes[k::folds] for k in range(folds)]


def _errors(checkpoint: Path, dataset: DemoDataset, indices: list[int], side: dict, seeds: int
            ) -> dict[str, np.ndarray]:
    """Per-window errors averaged over sampler seeds: {metric: [len(indices)]}."""
    runs = []
    for seed in range(seeds):
        planner = RiskMapPlanner.load(checkpoint, seed=seed)
        runs.append(window_errors(planner, dataset, indices, side["maps"]["sigma_x"],
                                  side["maps"]["sigma_y"]))
    keys = ("ade_m", "fde_m", "goal_error_m", "plan_end_m", "demo_end_m")
    return {k: np.mean([r[k] for r in runs], axis=0) for k in keys}


def _constant_velocity_errors(dataset: DemoDataset) -> dict[str, np.ndarray]:
    """ADE / FDE of the `cv` baseline (current speed and heading for 6 s) on every window."""
    planner = ConstantVelocityPlanner()
    ade, fde = [], []
    for i in range(len(dataset)):
        scene = dataset.scene(i)
        demo = ego_from_world(scene.ego_future_xy(), *ego_pose(scene))
        err = np.linalg.norm(planner.plan(scene).waypoints - demo, axis=1)
        ade.append(err.mean())
        fde.append(err[-1])
    return {"ade_m": np.array(ade), "fde_m": np.array(fde)}


def fine_tune(args: FineTuneArgs, dataset: DemoDataset, train_idx: list[int], out: Path) -> Path:
    """Fine-tune the checkpoint on `train_idx`; writes `out`.safetensors/.json, returns `out`."""
    if out.with_suffix(".json").exists():
        return out                                # finished earlier: resume
    torch.manual_seed(args.seed)
    model, side = load_model(Path(args.checkpoint))
    model.train()
    irl = IRLConfig(**side["irl"])
    augmented = PerturbedEgo(dataset, args.seed, args.augment_probability)
    optimizer = torch.optim.Adam(model.parameters(), lr=args.lr)
    log = []
    for epoch in range(args.epochs):
        augmented.set_epoch(epoch)
        order = torch.randperm(len(train_idx), generator=torch.Generator().manual_seed(
            args.seed * 100003 + epoch))
        losses = []
        for batch in DataLoader(Subset(augmented, [train_idx[i] for i in order]),
                                batch_size=args.batch_size):
            step = irl_step(model(batch["raster"], batch["motion"]), batch, irl)
            optimizer.zero_grad()
            step.loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), args.grad_clip)
            optimizer.step()
            losses.append(step.loss.item())
        log.append(float(np.mean(losses)))
        print(f"  epoch {epoch + 1}/{args.epochs}: loss {log[-1]:.4f}", flush=True)
    model.eval()
    sidecar = {k: v for k, v in side.items() if k not in ("kind", "git_commit", "package_version")}
    sidecar["fine_tune"] = {**asdict(args), "train_windows": len(train_idx), "loss_per_epoch": log}
    save_checkpoint(out, model, sidecar)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for name, default in asdict(FineTuneArgs(data="")).items():
        kind = type(default) if default != "" else str
        parser.add_argument(f"--{name.replace('_', '-')}", type=kind, default=default,
                            required=name == "data")
    args = FineTuneArgs(**vars(parser.parse_args()))
    torch.set_num_threads(1)
    _, side = load_model(Path(args.checkpoint))
    maps = side["maps"]
    planner = RiskMapPlanner.load(args.checkpoint)
    dataset = DemoDataset(args.data, planner.grid.rows, raster=planner.raster, sigma_x=maps["sigma_x"],
                          sigma_y=maps["sigma_y"], goal_variance=maps["goal_variance"],
                          goal=maps["goal"])
    folds = _vehicle_folds(dataset, args.folds)
    all_idx = list(range(len(dataset)))
    print(f"{len(dataset)} windows, {sum(map(len, folds))} demonstrators, {args.folds} folds")
    before = _errors(Path(args.checkpoint), dataset, all_idx, side, args.plan_seeds)
    after = {k: np.zeros(len(dataset)) for k in before}
    after_train = {k: [] for k in before}
    fold_info = []
    for k, held in enumerate(folds):
        test_idx = [i for i in all_idx if dataset.episode_of(i) in held]
        train_idx = [i for i in all_idx if dataset.episode_of(i) not in held]
        print(f"fold {k}: train {len(train_idx)} windows, test {len(test_idx)} windows")
        ckpt = fine_tune(args, dataset, train_idx, Path(args.runs) / f"fold_{k}")
        errs = _errors(ckpt, dataset, test_idx, side, args.plan_seeds)
        for key, values in errs.items():
            after[key][test_idx] = values
        fit = _errors(ckpt, dataset, train_idx, side, args.plan_seeds)
        for key, values in fit.items():
            after_train[key].extend(values)
        fold_info.append({"fold": k, "held_out_episodes": held, "train_windows": len(train_idx),
                          "test_windows": len(test_idx)})

    def summary(errs):
        return {k: {"mean": float(np.mean(v)), "median": float(np.median(v))} for k, v in errs.items()}

    vehicles = []
    for ep in sorted({dataset.episode_of(i) for i in all_idx}):
        idx = [i for i in all_idx if dataset.episode_of(i) == ep]
        vehicles.append({"episode": ep, "windows": len(idx),
                         **{f"before_{k}": float(np.mean(before[k][idx])) for k in before},
                         **{f"after_{k}": float(np.mean(after[k][idx])) for k in after}})
    cv = _constant_velocity_errors(dataset)
    result = {"args": asdict(args), "windows": len(dataset), "demonstrators": len(vehicles),
              "constant_velocity": summary(cv), "before": summary(before), "after_held_out": summary(after),
              "after_on_training_windows": summary(after_train), "folds": fold_info,
              "per_vehicle": vehicles}
    out = Path(args.out)
    write_json(out / "finetune.json", result)
    rows = [("shipped highway planner", summary(before)), ("fine-tuned, held-out vehicles",
                                                         summary(after)),
            ("fine-tuned, its own training vehicles", summary(after_train))]
    table = ["| model | ADE (m) | FDE (m) | plan end to goal (m) | plan length (m) |",
             "|---|---|---|---|---|"]
    table += [f"| {name} | {s['ade_m']['mean']:.2f} | {s['fde_m']['mean']:.2f} | "
              f"{s['goal_error_m']['mean']:.2f} | {s['plan_end_m']['mean']:.1f} |" for name, s in rows]
    table.append(f"| constant velocity (reference) | {np.mean(cv['ade_m']):.2f} | "
                 f"{np.mean(cv['fde_m']):.2f} | – | – |")
    table.append(f"| (recorded human's 6 s displacement) | | | | {np.mean(before['demo_end_m']):.1f} |")
    (out / "finetune.md").write_text("\n".join(table) + "\n")
    print("\n".join(table))


if __name__ == "__main__":
    main()
