"""The TGAT training curves (the paper's Fig. 5): AP, AUC, accuracy and F1 per epoch."""

from __future__ import annotations

import io
from pathlib import Path

from riskmap.infra.atomic import atomic_write

METRICS = ("ap", "auc", "accuracy", "f1")


def save_training_curves(history: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [row["epoch"] for row in history]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, split in zip(axes[:2], ("seen", "unseen")):
        for metric in METRICS:
            ax.plot(epochs, [row[split][metric] for row in history], marker=".", label=metric.upper()
                    if metric in ("ap", "auc") else metric.capitalize())
        ax.set_title(f"{split} test split (n = {history[0][split]['n']}, "
                     f"{history[0][split]['positives']} positive)")
        ax.set_xlabel("epoch")
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
    axes[2].plot(epochs, [row["train_loss"] for row in history], label="train loss (BCE + time to contact)")
    axes[2].plot(epochs, [row["val"]["ap"] for row in history], label="val AP (early stopping)")
    axes[2].set_xlabel("epoch")
    axes[2].set_title("training")
    axes[2].grid(alpha=0.3)
    axes[2].legend()
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    plt.close(fig)
    atomic_write(path, lambda f: f.write(buffer.getvalue()))
