"""Learning-curve figures (I/O layer: matplotlib, files)."""
from __future__ import annotations

import math
from pathlib import Path

from depthbench.fsutil import atomic_output


def plot_curves(path: Path, history: list[dict], *, title: str) -> Path:
    """Training and validation loss per epoch (log scale) as a PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] for h in history]
    fig, ax = plt.subplots(figsize=(5.5, 3.5), dpi=110)
    ax.plot(epochs, [h["train_loss"] for h in history], "o-", label="training")
    val = [h["val_loss"] for h in history]
    if any(v is not None and not math.isnan(v) for v in val):
        ax.plot(epochs, val, "s-", label="validation")
    ax.set_xlabel("epoch")
    ax.set_ylabel("eq. 32 loss (m, mean over pixels)")
    ax.set_yscale("log")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path
