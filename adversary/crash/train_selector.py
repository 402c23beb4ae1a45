"""`adversary train-selector`: fit the ASM with the task-coupled loss on training scenes.

CRASH trains selection and generation jointly through L = L_adv + L_reg, weighted by p. We make
the coupling explicit and affordable on a CPU: for every training scene and every candidate c we
run a short generation (`label_iterations` of the full attack objective, p = one-hot(c), against
the logged ego) and keep its final loss L_c and whether it collided. The selector then minimises
the expected generation loss under its own distribution,

    L_sel = sum_c p_c * (L_c - mean_c L_c) / (std_c L_c + 1e-6),

so p moves towards the agents whose attack the generator can complete most cheaply. The traffic
model is frozen; the selector sees its context latents Z (after message passing).

Files in RUN: labels.jsonl (one line per scene, written atomically as each is computed; `--resume`
keeps them), selector_mam / selector_no_mam (safetensors + sidecar), summary.json. Labelling draws
nothing from torch's generator, so the selectors start from the same draws whether the labels were
made now or by a killed run (a resumed run trains the same selectors).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from adversary.crash.batch import collate
from adversary.crash.config import TrainSelectorConfig
from adversary.crash.features import SceneTensors
from adversary.crash.generate import GenerationConfig, attack_loss, generate, logged_ego_future
from adversary.crash.selection import SelectionModule, candidates, distance_weights
from adversary.crash.train_traffic import load_traffic_model, load_windows, scene_collides
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.checkpoint import load_weights, read_sidecar, save_checkpoint
from riskmap.infra.rundir import lock_out_dir, refuse_unless_resume

CHECKPOINT_KIND = "crash_selector"


def adversary_collides(traj: np.ndarray, sizes: np.ndarray, row: int) -> bool:
    """Whether the boxes of the ego (row 0) and `row` overlap at some step; traj [N, F, 4]."""
    pair = traj[[0, row]]
    return scene_collides(pair, sizes[[0, row]], np.ones(pair.shape[:2], bool))


def label_scene(model, item: SceneTensors, iterations: int) -> dict | None:
    """Final generation loss and collision of a short attack by every non-ego agent."""
    batch = collate([item])
    rows = np.flatnonzero(candidates(batch, mam=False)[0].numpy())
    if len(rows) == 0:
        return None
    reps = batch.repeat(len(rows))
    p = torch.zeros(len(rows), batch.past.shape[1])
    p[torch.arange(len(rows)), torch.from_numpy(rows)] = 1.0
    ego = logged_ego_future(reps)
    config = GenerationConfig(iterations=iterations, stop_on_collision=False)
    gen = generate(model, reps, p, ego, config)
    with torch.no_grad():
        enc = model.encode(reps)
        z_init, _ = model.posterior_of(reps, enc)
        loss, traj, _ = attack_loss(model, reps, enc, gen.z, z_init, p, gen.adversary, ego, config)
    n = item.num_agents
    collided = [adversary_collides(traj[i, :n].numpy(), item.sizes, int(r)) for i, r in enumerate(rows)]
    moving = candidates(batch, mam=True)[0].numpy()
    return {"rows": rows.tolist(), "loss": loss.tolist(), "collided": collided,
            "moving": [bool(moving[r]) for r in rows], "seconds": gen.seconds}


@torch.no_grad()
def contexts(model, items: list[SceneTensors]) -> list[torch.Tensor]:
    return [model.encode(collate([it])).context[0] for it in items]


def _selector_loss(selector, z: torch.Tensor, mask: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    p = selector(z[None], mask[None])[0]
    return (p * target).sum()


def _targets(label: dict, n: int, mam: bool) -> tuple[torch.Tensor, torch.Tensor]:
    mask = torch.zeros(n, dtype=torch.bool)
    loss = torch.zeros(n)
    rows = [r for r, m in zip(label["rows"], label["moving"]) if m or not mam]
    values = np.array([v for v, m in zip(label["loss"], label["moving"]) if m or not mam])
    if len(rows):
        mask[rows] = True
        loss[rows] = torch.tensor((values - values.mean()) / (values.std() + 1e-6), dtype=torch.float32)
    return mask, loss


def evaluate_selection(p_rows: list[int], labels: list[dict]) -> dict:
    """Share of scenes whose chosen row's short attack collided, and how often it is the best."""
    hits = best = 0
    for row, label in zip(p_rows, labels):
        idx = label["rows"].index(row) if row in label["rows"] else None
        if idx is None:
            continue
        hits += label["collided"][idx]
        best += int(np.argmin(label["loss"]) == idx)
    return {"scenes": len(labels), "collided": hits / max(len(labels), 1),
            "picks_lowest_loss": best / max(len(labels), 1)}


def train_selector(traffic_checkpoint: Path, data: list[Path], out: Path,
                   config: TrainSelectorConfig = TrainSelectorConfig(), resume: bool = False,
                   progress: bool = True) -> dict:
    out = Path(out)
    refuse_unless_resume(out, "a run", None, resume)
    torch.manual_seed(config.seed)
    # The traffic model and the data are read (and bad ones refused) before --out exists.
    model, features, traffic_meta = load_traffic_model(traffic_checkpoint)
    for param in model.parameters():
        param.requires_grad_(False)
    train_items, _ = load_windows(data, features, 0.0, config.windows_per_episode)
    lock_out_dir(out)   # one writer per run directory (creates it)
    rng = np.random.default_rng(config.seed)
    items = [train_items[i] for i in sorted(rng.permutation(len(train_items))[: config.max_scenes])]
    labels_path = out / "labels.jsonl"
    labels: list[dict | None] = []
    if resume and labels_path.exists():
        labels = [json.loads(line) for line in labels_path.read_text().splitlines() if line.strip()]
    started = time.perf_counter()
    for i in range(len(labels), len(items)):
        labels.append(label_scene(model, items[i], config.label_iterations))
        # Rewritten whole, atomically: a kill leaves the lines of finished scenes, never half a line.
        atomic_write(labels_path, lambda f: f.write("".join(json.dumps(lab) + "\n" for lab in labels).encode()))
        if progress and i % 10 == 0:
            print(f"labelled {i + 1}/{len(items)} scenes ({time.perf_counter() - started:.0f} s)", flush=True)
    kept = [(it, lab) for it, lab in zip(items, labels) if lab is not None]
    cut = round(len(kept) * (1.0 - config.val_fraction))
    train, val = kept[:cut], kept[cut:]
    z_train = contexts(model, [it for it, _ in train])
    z_val = contexts(model, [it for it, _ in val])
    summary = {"config": asdict(config), "traffic_model": str(traffic_checkpoint),
               "labelled_scenes": len(kept), "train_scenes": len(train), "val_scenes": len(val)}
    for mam in (True, False):
        selector = SelectionModule(traffic_meta["model"]["hidden"])
        optimiser = torch.optim.Adam(selector.parameters(), lr=config.lr)
        targets = [_targets(lab, z.shape[0], mam) for z, (_, lab) in zip(z_train, train)]
        for epoch in range(config.epochs):
            order = rng.permutation(len(train))
            total = 0.0
            for start in range(0, len(order), 16):
                loss = sum(_selector_loss(selector, z_train[i], *targets[i]) for i in order[start:start + 16]
                           if targets[i][0].any())
                if not torch.is_tensor(loss):
                    continue
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
                total += loss.item()
        name = "selector_mam" if mam else "selector_no_mam"
        picks = []
        with torch.no_grad():
            for z, (it, lab) in zip(z_val, val):
                mask = _targets(lab, z.shape[0], mam)[0]
                picks.append(int(selector(z[None], mask[None])[0].argmax()) if mask.any() else -1)
        metrics = evaluate_selection(picks, [lab for _, lab in val])
        summary[name] = {"val": metrics, "final_train_loss": total}
        save_checkpoint(out / name, selector, {"mam": mam, "hidden": traffic_meta["model"]["hidden"],
                                               "traffic_model": str(traffic_checkpoint), "val": metrics},
                        kind=CHECKPOINT_KIND)
    summary["val_baselines"] = _baseline_picks(model, val, rng)
    write_json(out / "summary.json", summary)
    return summary


@torch.no_grad()
def _baseline_picks(model, val: list, rng: np.random.Generator) -> dict:
    """The same validation measure for distance-based, nearest, random and the oracle."""
    out = {}
    labels = [lab for _, lab in val]
    dist_rows, near_rows, rand_rows, best_rows = [], [], [], []
    for it, lab in val:
        batch = collate([it])
        enc = model.encode(batch)
        mu, _ = model.posterior_of(batch, enc)
        traj = model.decode(batch, enc, mu)
        mask = candidates(batch, mam=False)
        w = distance_weights(traj, logged_ego_future(batch), batch, mask)[0]
        dist_rows.append(int(w.argmax()) if w.sum() > 0 else -1)
        d = batch.past[0, :, -1, :2].norm(dim=-1).masked_fill(~mask[0], float("inf"))
        near_rows.append(int(d.argmin()))
        rand_rows.append(int(rng.choice(lab["rows"])))
        best_rows.append(lab["rows"][int(np.argmin(lab["loss"]))])
    for name, rows in (("distance", dist_rows), ("nearest", near_rows), ("random", rand_rows),
                       ("lowest_loss_oracle", best_rows)):
        out[name] = evaluate_selection(rows, labels)
    return out


def load_selector(path: Path) -> tuple[SelectionModule, dict]:
    data = read_sidecar(path, kind=CHECKPOINT_KIND)
    selector = load_weights(SelectionModule(data["hidden"]), path,
                            "train it again with `adversary train-selector`")
    return selector, data
