"""`adversary train-selector`: fit the ASM on training scenes with one of two objectives.

CRASH trains selection and generation jointly through L = L_adv + L_reg, weighted by p. The
traffic model is frozen; the selector sees its context latents Z (after message passing).

`--objective labels` (default) makes the coupling explicit and affordable on a CPU: for every
training scene and every candidate c we run a short generation (`label_iterations` of the full
attack objective, p = one-hot(c), against the logged ego) and keep its final loss L_c and whether
it collided. The selector then minimises the expected generation loss under its own distribution,

    L_sel = sum_c p_c * (L_c - mean_c L_c) / (std_c L_c + 1e-6),

so p moves towards the agents whose attack the generator can complete most cheaply.

`--objective unrolled` puts p into the generation loss itself: `unroll_steps` gradient steps on
the latents from the posterior mean are unrolled differentiably and the selector minimises the
loss after them, back-propagated through the unroll (adversary/crash/unrolled.py). Each scene's
loss is divided by its own (detached) magnitude, so that every scene's relative improvement
counts alike, as the standardised labels make them count. Only the held-out scenes are labelled
(for the same validation measure).

Files in RUN: run.json (the settings; `--resume` continues only with the same ones), labels.jsonl
(one line per labelled scene, rewritten atomically as each is computed; `--resume` keeps them;
every scene with `labels`, the held-out ones with `unrolled`), unrolled_selector_mam.pt /
unrolled_selector_no_mam.pt (`unrolled` only: weights, optimizer and log, committed atomically
after every epoch, `riskmap.infra.training_run`; `--resume` continues from the last one),
selector_mam / selector_no_mam
(safetensors + sidecar naming the objective), summary.json. Labelling draws nothing from torch's
generator, and the unrolled selectors are initialised and shuffled from generators seeded per
selector and epoch, so a resumed run trains the same selectors as an uninterrupted one.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from adversary.crash.batch import collate
from adversary.crash.config import TrainSelectorConfig
from adversary.crash.features import SceneTensors
from adversary.crash.generate import GenerationConfig, attack_loss, generate, logged_ego_future
from adversary.crash.selection import SelectionModule, candidates, distance_weights
from adversary.crash.train_traffic import load_traffic_model, load_windows, scene_collides
from adversary.crash.unrolled import unrolled_loss
from riskmap.infra.atomic import atomic_write, write_json
from riskmap.infra.checkpoint import load_weights, read_sidecar, save_checkpoint
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import check_same_settings, lock_out_dir
from riskmap.infra.training_run import TrainingRun, refuse_unless_resume_run

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
    refuse_unless_resume_run(out, resume, "a run", markers=(None,))
    torch.manual_seed(config.seed)
    # The traffic model and the data are read (and bad ones refused) before --out exists.
    model, features, traffic_meta = load_traffic_model(traffic_checkpoint)
    for param in model.parameters():
        param.requires_grad_(False)
    train_items, _ = load_windows(data, features, 0.0, config.windows_per_episode)
    settings = {"config": asdict(config), "traffic_model": str(traffic_checkpoint)}
    if resume:
        check_same_settings(out, SETTINGS_FILE, settings, differs="other train-selector settings")
    lock_out_dir(out)   # one writer per run directory (creates it)
    write_json(out / SETTINGS_FILE, {**settings, **provenance()})
    rng = np.random.default_rng(config.seed)
    items = [train_items[i] for i in sorted(rng.permutation(len(train_items))[: config.max_scenes])]
    run = _Run(model, traffic_meta["model"]["hidden"], str(traffic_checkpoint), config, out, progress)
    train_on = _train_unrolled_pair if config.objective == "unrolled" else _train_label_pair
    summary, val = train_on(run, items, resume, rng)
    summary["val_baselines"] = _baseline_picks(model, val, rng)
    write_json(out / "summary.json", summary)
    return summary


def _train_label_pair(run: _Run, items: list[SceneTensors], resume: bool, rng: np.random.Generator
                      ) -> tuple[dict, list]:
    """`--objective labels`: label every scene, fit both selectors; (summary, held-out (item, label))."""
    labels = _label_all(run, items, resume)
    kept = [(it, lab) for it, lab in zip(items, labels) if lab is not None]
    train, val = _split(kept, run.config.val_fraction)
    summary = _summary(run, len(kept), len(train), len(val))
    z_train = contexts(run.model, [it for it, _ in train])
    for mam in (True, False):
        selector, total = _train_on_labels(run, z_train, [lab for _, lab in train], mam, rng)
        summary[_name(mam)] = _commit(run, selector, mam, val, {})
        summary[_name(mam)]["final_train_loss"] = total
    return summary, val


def _train_unrolled_pair(run: _Run, items: list[SceneTensors], resume: bool, rng: np.random.Generator
                         ) -> tuple[dict, list]:
    """`--objective unrolled`: label the held-out scenes only, train both selectors through the
    unroll; (summary, held-out (item, label))."""
    config = run.config
    train, held_out = _split([it for it in items if _has_candidates(it)], config.val_fraction)
    val = [(it, lab) for it, lab in zip(held_out, _label_all(run, held_out, resume)) if lab is not None]
    summary = _summary(run, len(val), len(train), len(val))
    for mam in (True, False):
        selector, log = _train_unrolled(run, train, mam, resume)
        summary[_name(mam)] = _commit(run, selector, mam, val, {"unroll_steps": config.unroll_steps,
                                                                "unroll_lr": config.unroll_lr,
                                                                "last_epoch": log[-1] if log else None})
        summary[_name(mam)]["final_train_loss"] = log[-1]["loss"] if log else None
    return summary, val


SETTINGS_FILE = "run.json"
BATCH_SCENES = 16
UNROLL_BATCH_SCENES = 32     # one unroll of 32 scenes costs about 1.4 of 16 (the decoder is step-serial)


@dataclass(frozen=True)
class _Run:
    """What every stage of one train-selector run needs."""
    model: object
    hidden: int
    traffic_model: str
    config: TrainSelectorConfig
    out: Path
    progress: bool


def _name(mam: bool) -> str:
    return "selector_mam" if mam else "selector_no_mam"


def _summary(run: _Run, labelled: int, train: int, val: int) -> dict:
    return {"config": asdict(run.config), "traffic_model": run.traffic_model, "objective": run.config.objective,
            "labelled_scenes": labelled, "train_scenes": train, "val_scenes": val}


def _split(kept: list, val_fraction: float) -> tuple[list, list]:
    """(train, held-out): the last share of the scenes (by order, i.e. by episode) is held out."""
    cut = round(len(kept) * (1.0 - val_fraction))
    return kept[:cut], kept[cut:]


def _has_candidates(item: SceneTensors) -> bool:
    """Whether a scene has a non-ego agent (the scenes `label_scene` labels)."""
    return bool(candidates(collate([item]), mam=False).any())


def _label_all(run: _Run, items: list[SceneTensors], resume: bool) -> list[dict | None]:
    """`label_scene` of every item, kept in RUN/labels.jsonl scene by scene (resumable)."""
    labels_path = run.out / "labels.jsonl"
    labels: list[dict | None] = []
    if resume and labels_path.exists():
        labels = [json.loads(line) for line in labels_path.read_text().splitlines() if line.strip()]
    started = time.perf_counter()
    for i in range(len(labels), len(items)):
        labels.append(label_scene(run.model, items[i], run.config.label_iterations))
        # Rewritten whole, atomically: a kill leaves the lines of finished scenes, never half a line.
        atomic_write(labels_path, lambda f: f.write("".join(json.dumps(lab) + "\n" for lab in labels).encode()))
        if run.progress and i % 10 == 0:
            print(f"labelled {i + 1}/{len(items)} scenes ({time.perf_counter() - started:.0f} s)", flush=True)
    return labels


def _train_on_labels(run: _Run, z_train: list[torch.Tensor], labels: list[dict], mam: bool,
                     rng: np.random.Generator) -> tuple[SelectionModule, float]:
    """The selector fit to the standardised label losses (module docstring); its last epoch's loss."""
    selector = SelectionModule(run.hidden)
    optimiser = torch.optim.Adam(selector.parameters(), lr=run.config.lr)
    targets = [_targets(lab, z.shape[0], mam) for z, lab in zip(z_train, labels)]
    total = 0.0
    for _ in range(run.config.epochs):
        order = rng.permutation(len(labels))
        total = 0.0
        for start in range(0, len(order), BATCH_SCENES):
            loss = sum(_selector_loss(selector, z_train[i], *targets[i]) for i in order[start:start + BATCH_SCENES]
                       if targets[i][0].any())
            if not torch.is_tensor(loss):
                continue
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item()
    return selector, total


def _state_path(run: _Run, mam: bool) -> Path:
    return run.out / f"unrolled_{_name(mam)}.pt"


def _train_unrolled(run: _Run, train: list[SceneTensors], mam: bool, resume: bool
                    ) -> tuple[SelectionModule, list[dict]]:
    """The selector trained through the unrolled generation loss, one atomic commit per epoch
    (no random state: every epoch's order comes from its own generator; no best: the last epoch's
    selector is the one committed)."""
    config = run.config
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed * 2 + int(not mam))
        selector = SelectionModule(run.hidden)
    optimizer = torch.optim.Adam(selector.parameters(), lr=config.lr)
    training = TrainingRun(run.out, resume, state=_state_path(run, mam).name, random_state=False)
    training.resume_from(selector, optimizer)
    started = time.perf_counter()
    for epoch in range(training.first_epoch, config.epochs):
        order = np.random.default_rng([config.seed, int(mam), epoch]).permutation(len(train))
        losses = [_unrolled_step(run, selector, optimizer, [train[i] for i in order[s:s + UNROLL_BATCH_SCENES]],
                                 mam) for s in range(0, len(order), UNROLL_BATCH_SCENES)]
        done = [v for v in losses if v is not None]
        training.commit(selector, optimizer, {"epoch": epoch, "loss": float(np.mean(done)) if done else None,
                                              "skipped_batches": len(losses) - len(done)})
        if run.progress and (epoch % 5 == 0 or epoch == config.epochs - 1):
            print(f"{_name(mam)} epoch {epoch + 1}/{config.epochs}: unrolled loss {training.log[-1]['loss']} "
                  f"({time.perf_counter() - started:.0f} s)", flush=True)
    return selector, training.log


def _unrolled_step(run: _Run, selector: SelectionModule, optimiser, items: list[SceneTensors],
                   mam: bool) -> float | None:
    """One Adam step on a batch of scenes; the batch's mean generation loss after the unroll (None:
    nothing to learn, or a non-finite loss, which is skipped)."""
    batch = collate(items)
    has = candidates(batch, mam).any(-1)
    if not has.any():
        return None
    loss, _ = unrolled_loss(run.model, batch, selector, mam, run.config.unroll_steps, run.config.unroll_lr)
    relative = (loss / loss.detach().abs().clamp(min=1.0))[has].mean()
    if not torch.isfinite(relative):
        return None
    optimiser.zero_grad()
    relative.backward()
    optimiser.step()
    return loss.detach()[has].mean().item()


def _commit(run: _Run, selector: SelectionModule, mam: bool, val: list, extra: dict) -> dict:
    """Validate the selector on the held-out labels and write RUN/selector_(no_)mam."""
    picks = []
    with torch.no_grad():
        for it, lab in val:
            z = contexts(run.model, [it])[0]
            mask = _targets(lab, z.shape[0], mam)[0]
            picks.append(int(selector(z[None], mask[None])[0].argmax()) if mask.any() else -1)
    metrics = evaluate_selection(picks, [lab for _, lab in val])
    unrolled = _val_unrolled_loss(run, selector, [it for it, _ in val], mam)
    save_checkpoint(run.out / _name(mam), selector,
                    {"mam": mam, "hidden": run.hidden, "traffic_model": run.traffic_model, "val": metrics,
                     "objective": run.config.objective, **extra},
                    kind=CHECKPOINT_KIND)
    return {"val": metrics, "val_unrolled_loss": unrolled}


def _val_unrolled_loss(run: _Run, selector: SelectionModule, items: list[SceneTensors], mam: bool) -> float | None:
    """Mean generation loss after the unroll over the held-out scenes with candidates (both
    objectives report it: what the unrolled objective minimises)."""
    values = []
    for start in range(0, len(items), BATCH_SCENES):
        batch = collate(items[start:start + BATCH_SCENES])
        has = candidates(batch, mam).any(-1)
        if has.any():
            loss, _ = unrolled_loss(run.model, batch, selector, mam, run.config.unroll_steps, run.config.unroll_lr)
            values += loss.detach()[has].tolist()
    return float(np.mean(values)) if values else None


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
