"""`riskmap guard train`: fit the TGAT accident predictor, early-stopped on validation AP.

BCE with logits, Adam (4e-4), batch 8. After every epoch the whole validation, seen-test and
unseen-test splits are scored in one pass each (metrics over the whole split, not averaged per
batch). Run directory: state.pt (everything --resume needs, written whole after every epoch: the
epoch's one commit point), then from it history.json and, when the epoch is the best so far,
best.safetensors + best.json (a resumed run writes them again from its state: the kill may have
come between them); at the end curves.png and result.json.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch import nn

from rasterize.errors import InputError
from riskmap.guard.config import GuardTrainConfig
from riskmap.guard.dataset import load_split
from riskmap.guard.metrics import binary_metrics
from riskmap.guard.tgat import TGAT
from riskmap.infra.atomic import write_json
from riskmap.infra.checkpoint import load_state, save_checkpoint, save_state
from riskmap.infra.rundir import lock_out_dir, refuse_unless_resume

CHECKPOINT_KIND = "guard_tgat"
ALERT_THRESHOLD = 0.6     # the online threshold of the paper; metrics are also given at 0.5


def _tensors(split: dict) -> tuple[torch.Tensor, ...]:
    return (torch.from_numpy(split["node_u"]).float(), torch.from_numpy(split["node_i"]).float(),
            torch.from_numpy(split["edge"]).float(), torch.from_numpy(split["mask"]).bool(),
            torch.from_numpy(split["label"].astype(np.float32)))


@torch.no_grad()
def predict(model: nn.Module, tensors: tuple[torch.Tensor, ...], chunk: int = 4096) -> np.ndarray:
    """Accident probabilities [W] of every window, in eval mode."""
    model.eval()
    probs = [torch.sigmoid(model(*(t[s:s + chunk] for t in tensors[:4])))
             for s in range(0, len(tensors[0]), chunk)]
    return torch.cat(probs).numpy().astype(np.float64)


def evaluate(model: nn.Module, tensors: tuple[torch.Tensor, ...]) -> dict:
    probs = predict(model, tensors)
    labels = tensors[4].numpy().astype(int)
    return {**binary_metrics(labels, probs, 0.5),
            "at_alert_threshold": binary_metrics(labels, probs, ALERT_THRESHOLD)}


def train(data: Path, out: Path, config: GuardTrainConfig = GuardTrainConfig(), resume: bool = False,
          progress: bool = True) -> dict:
    out = Path(out)
    state_path = out / "state.pt"
    refuse_unless_resume(out, "a guard training run", "state.pt", resume)
    torch.manual_seed(config.seed)
    # The data is read (and bad data refused) before --out exists.
    splits = {name: _tensors(load_split(data, name)) for name in ("train", "val", "seen", "unseen")}
    lock_out_dir(out)   # one writer per run directory (creates it)
    model = TGAT(config.model)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.lr)
    loss_fn = nn.BCEWithLogitsLoss()
    history, best, epoch0 = [], {"val_ap": -1.0, "epoch": None}, 0

    def publish(epoch: int, history: list[dict], best: dict) -> None:
        """The files derived from the state committed after `epoch`."""
        if best["epoch"] == epoch:
            save_checkpoint(out / "best.safetensors", model, {
                "kind": CHECKPOINT_KIND, "model": config.model.to_dict(), "train": asdict(config),
                "alert_threshold": ALERT_THRESHOLD, "data": str(data), "epoch": epoch,
                "metrics": {k: history[-1][k] for k in ("val", "seen", "unseen")}})
        write_json(out / "history.json", history)

    if resume and state_path.exists():
        state = load_state(state_path)
        # More epochs (or patience) may be asked for on resume; everything else must match.
        if state["config"] | {"epochs": config.epochs, "patience": config.patience} != asdict(config):
            raise InputError(f"--out {out} was trained with other settings; choose another --out")
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        torch.set_rng_state(state["rng"])
        history, best, epoch0 = state["history"], state["best"], state["epoch"] + 1
        publish(state["epoch"], history, best)
    n_train = len(splits["train"][0])
    for epoch in range(epoch0, config.epochs):
        if epoch - (best["epoch"] if best["epoch"] is not None else -1) > config.patience:
            break
        model.train()
        order = torch.randperm(n_train)
        losses = []
        for start in range(0, n_train, config.batch_size):
            idx = order[start:start + config.batch_size]
            batch = [t[idx] for t in splits["train"]]
            loss = loss_fn(model(*batch[:4]), batch[4])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            losses.append(float(loss.detach()))
        row = {"epoch": epoch, "train_loss": float(np.mean(losses))}
        row.update({name: evaluate(model, splits[name]) for name in ("val", "seen", "unseen")})
        history.append(row)
        if row["val"]["ap"] > best["val_ap"]:
            best = {"val_ap": row["val"]["ap"], "epoch": epoch}
        save_state(state_path, {"config": asdict(config), "model": model.state_dict(),
                                "optimiser": optimiser.state_dict(), "rng": torch.get_rng_state(),
                                "history": history, "best": best, "epoch": epoch})
        publish(epoch, history, best)
        if progress:
            print(f"epoch {epoch}: loss {row['train_loss']:.4f} val AP {row['val']['ap']:.3f} "
                  f"seen AP {row['seen']['ap']:.3f} unseen AP {row['unseen']['ap']:.3f}", flush=True)
    from riskmap.guard.figures import save_training_curves

    save_training_curves(history, out / "curves.png")
    sidecar = json.loads((out / "best.json").read_text())
    result = {"best_epoch": best["epoch"], "test": {"seen": sidecar["metrics"]["seen"],
                                                    "unseen": sidecar["metrics"]["unseen"]},
              "val": sidecar["metrics"]["val"],
              "sizes": {name: {"n": len(t[4]), "positives": int(t[4].sum())} for name, t in splits.items()}}
    write_json(out / "result.json", result)
    return result
