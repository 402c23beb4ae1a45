"""`riskmap guard train`: fit the TGAT accident predictor, early-stopped on validation AP.

BCE with logits plus `ttc_weight` × smooth L1 of the time to contact on the positive windows,
Adam (4e-4), batch 8; labels for the model's horizon (`TGATConfig.horizon_s`). After every epoch
the whole validation, seen-test and unseen-test splits are scored in one pass each (metrics over
the whole split, not averaged per batch). The best epoch's alert threshold is chosen on the
validation decision frames for the target alert ratio (`riskmap.guard.threshold`; the paper's
0.6 when the data holds no frames) and written to the sidecar with the metrics at it. Run directory: state.pt (everything --resume needs, written whole after every epoch: the
epoch's one commit point, `riskmap.infra.training_run`), then from it history.json and, when the
epoch is the best so far, best.safetensors + best.json (a resumed run writes them again from its
state: the kill may have come between them); at the end curves.png and result.json.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch import nn

from riskmap.guard.config import GuardTrainConfig
from riskmap.guard.dataset import load_frames, load_split
from riskmap.guard.metrics import binary_metrics
from riskmap.guard.tgat import TGAT
from riskmap.guard.threshold import alert_ratio, frame_max_scores, threshold_for_ratio
from riskmap.infra.atomic import write_json
from riskmap.infra.training_run import TrainingRun, json_log

CHECKPOINT_KIND = "guard_tgat"
ALERT_THRESHOLD = 0.6     # the paper's online threshold: used when the data holds no decision frames


def _tensors(split: dict) -> tuple[torch.Tensor, ...]:
    """(node_u, node_i, edge, mask, label, ttc_s) of a split from `load_split`."""
    return (torch.from_numpy(split["node_u"]).float(), torch.from_numpy(split["node_i"]).float(),
            torch.from_numpy(split["edge"]).float(), torch.from_numpy(split["mask"]).bool(),
            torch.from_numpy(split["label"].astype(np.float32)), torch.from_numpy(split["ttc_s"]).float())


@torch.no_grad()
def predict(model: nn.Module, tensors: tuple[torch.Tensor, ...], chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """(accident probabilities [W], time to contact [W] s) of every window, in eval mode."""
    model.eval()
    outs = [model(*(t[s:s + chunk] for t in tensors[:4])) for s in range(0, len(tensors[0]), chunk)]
    probs = torch.cat([torch.sigmoid(logit) for logit, _ in outs]) if outs else torch.zeros(0)
    ttc = torch.cat([t for _, t in outs]) if outs else torch.zeros(0)
    return probs.numpy().astype(np.float64), ttc.numpy().astype(np.float64)


def evaluate(model: nn.Module, tensors: tuple[torch.Tensor, ...], threshold: float = ALERT_THRESHOLD) -> dict:
    """Metrics at 0.5 and at `threshold`, and the time-to-contact error on the positives."""
    probs, ttc = predict(model, tensors)
    labels = tensors[4].numpy().astype(int)
    positive = labels == 1
    error = np.abs(ttc[positive] - tensors[5].numpy()[positive])
    return {**binary_metrics(labels, probs, 0.5),
            "at_alert_threshold": binary_metrics(labels, probs, threshold),
            "ttc_mae_s": float(error.mean()) if len(error) else None}


def frame_scores(model: nn.Module, frames: dict) -> np.ndarray:
    """Highest score per decision frame [frames] (`load_frames`)."""
    tensors = (torch.from_numpy(frames["node_u"]).float(), torch.from_numpy(frames["node_i"]).float(),
               torch.from_numpy(frames["edge"]).float(), torch.from_numpy(frames["mask"]).bool())
    probs, _ = predict(model, tensors)
    return frame_max_scores(probs, frames["frame"], frames["frames"])


def choose_threshold(model: nn.Module, val_frames: dict | None, ratio: float) -> tuple[float, str, float | None]:
    """(alert threshold, where it came from, the validation alert ratio it gives)."""
    if val_frames is None:
        return ALERT_THRESHOLD, "fixed (no validation decision frames)", None
    scores = frame_scores(model, val_frames)
    threshold = threshold_for_ratio(scores, ratio)
    return threshold, f"validation frames, target alert ratio {ratio:g}", alert_ratio(scores, threshold)


def training_loss(model: nn.Module, batch: list[torch.Tensor], ttc_weight: float) -> torch.Tensor:
    logits, ttc = model(*batch[:4])
    loss = nn.functional.binary_cross_entropy_with_logits(logits, batch[4])
    positive = batch[4] > 0.5
    if ttc_weight > 0 and positive.any():
        loss = loss + ttc_weight * nn.functional.smooth_l1_loss(ttc[positive], batch[5][positive])
    return loss


def train(data: Path, out: Path, config: GuardTrainConfig = GuardTrainConfig(), resume: bool = False,
          progress: bool = True) -> dict:
    out = Path(out)
    # Best by validation AP; more epochs (or patience) may be asked for on resume, nothing else.
    run = TrainingRun(out, resume, metric=lambda row: row["val"]["ap"], higher=True,
                      settings=asdict(config), may_change=("epochs", "patience"),
                      fix="choose another --out").refuse("a guard training run")
    torch.manual_seed(config.seed)
    # The data is read (and bad data refused) before --out exists.
    horizon_s = config.model.horizon_s
    splits = {name: _tensors(load_split(data, name, horizon_s)) for name in ("train", "val", "seen", "unseen")}
    val_frames = load_frames(data, "val")
    run.lock()   # one writer per run directory (creates it)
    model = TGAT(config.model)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)

    def best_sidecar(epoch: int) -> dict:
        """The best checkpoint's sidecar (`epoch` the best so far): its alert threshold and the
        metrics at it."""
        threshold, source, ratio = choose_threshold(model, val_frames, config.alert_ratio)
        return {"kind": CHECKPOINT_KIND, "model": config.model.to_dict(), "train": asdict(config),
                "horizon_s": horizon_s, "alert_threshold": threshold, "alert_threshold_source": source,
                "validation_alert_ratio": ratio, "data": str(data), "epoch": epoch,
                "metrics": {k: evaluate(model, splits[k], threshold) for k in ("val", "seen", "unseen")}}

    run.resume_from(model, optimizer)
    run.publishes(log=json_log("history.json"), sidecar=best_sidecar, kind=CHECKPOINT_KIND)
    run.republish(model)     # the run may have been killed between the commit and its files
    n_train = len(splits["train"][0])
    for epoch in range(run.first_epoch, config.epochs):
        if epoch - (run.best_epoch if run.best_epoch is not None else -1) > config.patience:
            break
        model.train()
        order = torch.randperm(n_train)
        losses = []
        for start in range(0, n_train, config.batch_size):
            idx = order[start:start + config.batch_size]
            loss = training_loss(model, [t[idx] for t in splits["train"]], config.ttc_weight)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(float(loss.detach()))
        row = {"epoch": epoch, "train_loss": float(np.mean(losses))}
        row.update({name: evaluate(model, splits[name]) for name in ("val", "seen", "unseen")})
        run.commit(model, optimizer, row)
        if progress:
            print(f"epoch {epoch}: loss {row['train_loss']:.4f} val AP {row['val']['ap']:.3f} "
                  f"seen AP {row['seen']['ap']:.3f} unseen AP {row['unseen']['ap']:.3f}", flush=True)
    from riskmap.guard.figures import save_training_curves

    save_training_curves(run.log, out / "curves.png")
    sidecar = json.loads((out / "best.json").read_text())
    result = {"best_epoch": run.best_epoch, "test": {"seen": sidecar["metrics"]["seen"],
                                                    "unseen": sidecar["metrics"]["unseen"]},
              "val": sidecar["metrics"]["val"], "alert_threshold": sidecar["alert_threshold"],
              "alert_threshold_source": sidecar["alert_threshold_source"],
              "validation_alert_ratio": sidecar["validation_alert_ratio"], "horizon_s": horizon_s,
              "sizes": {name: {"n": len(t[4]), "positives": int(t[4].sum())} for name, t in splits.items()}}
    write_json(out / "result.json", result)
    return result
