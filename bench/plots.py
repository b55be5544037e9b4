"""Figures of the leaderboard (matplotlib, Agg backend). Each function returns PNG bytes.

Inputs are already-aggregated tables or preview arrays; no function here reads the results folder.
"""
from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from bench.metrics import normal_map  # noqa: E402
from capture.camera import Intrinsics  # noqa: E402

_COLORS = plt.get_cmap("tab10").colors


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def error_vs_depth(curves: pd.DataFrame, labels: dict[str, str], *, title: str) -> bytes:
    """Three panels against reference depth: MAE, plane-fit RMSE, share of points the plane fit excludes.

    ``curves``: columns ``method_key, depth_m`` (bin centre), ``mae_mm``, ``plane_fit_rmse_mm``,
    ``excluded_share``, ``n_valid``; ``labels``: method key -> column label, in display order.
    """
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    panels = (("mae_mm", "MAE (mm)"), ("plane_fit_rmse_mm", "plane-fit RMSE (mm)"),
              ("excluded_share", "plane fit: share of points excluded"))
    for k, (key, label) in enumerate(labels.items()):
        c = curves[curves["method_key"] == key].sort_values("depth_m")
        if c.empty:
            continue
        for ax, (col, _) in zip(axes, panels):
            ax.plot(c["depth_m"], c[col], marker="o", ms=3, lw=1.5, color=_COLORS[k % 10], label=label)
    for ax, (_, ylabel) in zip(axes, panels):
        ax.set_xlabel("reference depth (m)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[2].set_ylim(-0.02, 1.02)
    axes[0].legend(fontsize=8)
    fig.suptitle(title, fontsize=11)
    return _png(fig)


def summary_bars(summary: pd.DataFrame, labels: dict[str, str], *, metrics: dict[str, str], title: str) -> bytes:
    """Bars with 95 % bootstrap intervals: one panel per metric, one bar per method.

    ``summary``: rows ``(metric, method_key)`` with columns ``mean, lo, hi``.
    """
    fig, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.6), constrained_layout=True,
                             squeeze=False)
    for ax, (metric, mlabel) in zip(axes[0], metrics.items()):
        keys = [k for k in labels if (metric, k) in summary.index]
        means = np.array([summary.loc[(metric, k), "mean"] for k in keys], float)
        lo = np.array([summary.loc[(metric, k), "lo"] for k in keys], float)
        hi = np.array([summary.loc[(metric, k), "hi"] for k in keys], float)
        x = np.arange(len(keys))
        err = np.vstack([np.clip(means - lo, 0, None), np.clip(hi - means, 0, None)])
        ax.bar(x, np.nan_to_num(means), color=[_COLORS[i % 10] for i in range(len(keys))],
               yerr=np.nan_to_num(err), capsize=3)
        ax.set_xticks(x, [labels[k] for k in keys], rotation=30, ha="right", fontsize=8)
        ax.set_title(mlabel, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(title, fontsize=11)
    return _png(fig)


def _crop_box(mask: np.ndarray | None, shape: tuple[int, int], margin: int = 12) -> tuple[slice, slice]:
    if mask is None or not mask.any():
        return slice(0, shape[0]), slice(0, shape[1])
    v, u = np.nonzero(mask)
    return (slice(max(v.min() - margin, 0), min(v.max() + margin + 1, shape[0])),
            slice(max(u.min() - margin, 0), min(u.max() + margin + 1, shape[1])))


def shade(depth: np.ndarray, K: Intrinsics) -> np.ndarray:
    """Lambertian shading of the depth's surface normals (light from the upper left of the camera), ``(H, W)`` in [0, 1], NaN = none."""
    n = normal_map(depth, K)
    light = np.array([-0.4, -0.5, -0.77])
    light /= np.linalg.norm(light)
    return np.clip(n @ light, 0.0, 1.0)


def qualitative(inputs: dict[str, np.ndarray], denoised: dict[str, np.ndarray], labels: dict[str, str], *,
                title: str) -> bytes:
    """A figure like the seed report's Fig. 11: LQ, each method, reference (and truth), as depth and as shaded normals.

    ``inputs``: the preview arrays (``lq``, ``reference``, optional ``truth``, ``roi``, ``intrinsics``);
    ``denoised``: method key -> depth; ``labels``: method key -> column label, in display order.
    """
    w, h, fx, fy, cx, cy = inputs["intrinsics"]
    K = Intrinsics(int(w), int(h), float(fx), float(fy), float(cx), float(cy))
    roi = inputs.get("roi")
    cols = [("LQ input", inputs["lq"])]
    cols += [(labels[k], denoised[k]) for k in labels if k in denoised]
    cols.append(("HQ reference", inputs["reference"]))
    if "truth" in inputs:
        cols.append(("truth (simulated)", inputs["truth"]))
    box = _crop_box(roi, inputs["lq"].shape)
    ref = inputs["reference"]
    ref_in = ref[roi] if roi is not None and roi.any() else ref
    finite = ref_in[np.isfinite(ref_in)]
    if finite.size == 0:
        finite = inputs["lq"][np.isfinite(inputs["lq"])]
    vmin, vmax = (np.percentile(finite, [2, 98]) if finite.size else (0.0, 1.0))
    n = len(cols)
    crop_h, crop_w = box[0].stop - box[0].start, box[1].stop - box[1].start
    cell = 2.4
    fig, axes = plt.subplots(2, n, figsize=(cell * n, 2 * cell * crop_h / max(crop_w, 1) + 0.9),
                             constrained_layout=True, squeeze=False)
    cmap = plt.get_cmap("turbo").with_extremes(bad="black")
    gray = plt.get_cmap("gray").with_extremes(bad="black")
    for j, (label, depth) in enumerate(cols):
        d = np.where(roi, depth, np.nan) if roi is not None else depth
        im = axes[0, j].imshow(d[box], cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        axes[1, j].imshow(shade(d.astype(np.float32), K)[box], cmap=gray, vmin=0, vmax=1, interpolation="nearest")
        axes[0, j].set_title(label, fontsize=9)
        for a in axes[:, j]:
            a.set_xticks([])
            a.set_yticks([])
    axes[0, 0].set_ylabel("depth", fontsize=9)
    axes[1, 0].set_ylabel("shaded normals", fontsize=9)
    fig.colorbar(im, ax=axes[0, -1], fraction=0.046, pad=0.02, label="m")
    fig.suptitle(title, fontsize=10)
    return _png(fig)
