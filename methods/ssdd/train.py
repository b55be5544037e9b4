"""Training SSDD: level 1 (UNet), out-of-fold level-1 predictions, level 2 (LSTM-UNet).

``ssdd_unet`` trains level 1 on every training sequence. ``ssdd_lstm`` trains both levels:

1. the training sequences are split into ``k`` folds (:func:`assign_folds`, seeded, stratified by the
   manifest's ``scene`` where it names one);
2. for each fold f a level-1 model is trained on the other folds (``RUN/level1/fold<f>/``) and
   predicts every frame of fold f: those are the out-of-fold (OOF) predictions, made by a model
   that never saw the frame's sequence;
3. a final level-1 model is trained on all training sequences (``RUN/level1/final/``): it is the
   level 1 of inference, and predicts the validation sequences for level 2's validation;
4. level 2 is trained on sequences of (OOF level-1 prediction, LQ depth) against the reference
   (``RUN/level2/``); with ``[level2.motion]`` (:mod:`methods.ssdd.motion`) each frame's optical flow
   into the previous frame is computed once on whole frames (:func:`flows`) and cropped with the rest.

``RUN/oof.json`` records, for every training sequence, its fold, the model that predicted it and
the checksums of the sequences that model was trained on; each fold's checkpoint records the same
list independently (``trained_on``), and ``RUN/oof_predictions.safetensors`` holds the predictions
level 2 was trained on. Weights: ``RUN/ssdd_unet.safetensors`` (level 1) and
``RUN/ssdd_lstm.safetensors`` (both levels; with ``level2.level1_input = "fold_mean"`` also the fold
models, whose mean prediction then feeds level 2, for its validation here and at inference).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from align.dataset import AlignedDataset
from depthbench.fsutil import atomic_write_json
from methods.errors import TrainingError
from methods.nn.checkpoint import save_tensors
from methods.nn.data import AlignedSamples
from methods.nn.train import RunContext, Trainer, register_trainer
from methods.nn.trainer import FitJob, seeded
from methods.ssdd.config import FOLD_PREFIX, Level1Config, SSDDConfig
from methods.ssdd.model import PREFILTERED, build_level1, build_level2, level1_depth, level1_loss, level2_loss
from methods.ssdd.motion import FLOW_X, FLOW_Y, FlowSource, MotionConfig, sequence_flows
from methods.ssdd.networks import SSDDUNet
from methods.ssdd.prefilter import prefilter_frames

OOF_JSON = "oof.json"
OOF_PREDICTIONS = "oof_predictions.safetensors"


def assign_folds(datasets: list[AlignedDataset], k: int, *, seed: int, groups: list | None = None) -> list[int]:
    """Fold of each dataset (sequence): a seeded permutation dealt round-robin into ``k`` folds.

    ``groups`` (one label per dataset, e.g. the corpus manifest's ``scene``; None: one group) stratifies
    the deal: the permutation is ordered by group before dealing, so every fold gets its share of each
    group. Without it two people sequences could make one fold and two balloon sequences the other:
    each fold model would then predict a scene it never saw, and level 2 would learn to correct
    errors the final level-1 model (which saw every scene) does not make."""
    if k > len(datasets):
        raise TrainingError(f"folds = {k} needs at least {k} training sequences, the manifest has {len(datasets)}")
    order = np.random.default_rng([seed, 104729]).permutation(len(datasets))
    if groups is not None:
        labels = [str(g) for g in groups]
        order = sorted(order, key=lambda i: labels[int(i)])      # stable: the permutation within a group
    folds = [0] * len(datasets)
    for pos, i in enumerate(order):
        folds[int(i)] = pos % k
    return folds


def _samples(datasets, data, *, seed: int, train: bool, extra=None) -> AlignedSamples | None:
    if not datasets:
        return None
    return AlignedSamples(datasets, sequence_length=data.sequence_length, crop=data.crop if train else 0,
                          flip=data.flip and train, seed=seed, preload=data.preload, extra=extra,
                          stride=1 if train else max(data.sequence_length, data.validation_stride),
                          roi_crop=data.roi_crop if train else 0.0)


def prefiltered(datasets: list[AlignedDataset], cfg: Level1Config) -> dict[str, dict[str, np.ndarray]] | None:
    """The prefiltered base of every frame as an extra sample layer (``{PREFILTERED: {checksum: (F, H, W)}}``),
    or None when level 1 has no prefilter."""
    if not cfg.prefilter.enabled:
        return None
    return {PREFILTERED: {ds.checksum: prefilter_frames((ds.lq_depth(i) for i in range(len(ds))), cfg.prefilter)
                          for ds in datasets}}


def flows(datasets: list[AlignedDataset], cfg: MotionConfig) -> dict[str, dict[str, np.ndarray]]:
    """Every frame's backward flow (:func:`methods.ssdd.motion.sequence_flows`) as the extra sample layers
    ``FLOW_X`` and ``FLOW_Y`` (``{layer: {checksum: (F, H, W)}}``); empty when ``cfg`` is off."""
    if not cfg.enabled:
        return {}
    out: dict[str, dict[str, np.ndarray]] = {FLOW_X: {}, FLOW_Y: {}}
    src = FlowSource(cfg)
    for ds in datasets:
        if cfg.kind == "color" and not any(r["lq_color_file"] for r in ds.rows):
            raise TrainingError(f"{ds.root}: no LQ colour, which level2.motion.kind = 'color' needs "
                                "(kind = 'depth' finds the flow on the depth)")
        f = sequence_flows([src.image(ds.lq_depth(i), ds.lq_color(i)) for i in range(len(ds))], cfg)
        out[FLOW_X][ds.checksum], out[FLOW_Y][ds.checksum] = f[:, 0], f[:, 1]
    return out


def _fit_level1(ctx: RunContext, cfg: Level1Config, train: list[AlignedDataset], validation: list[AlignedDataset],
                folder: str, name: str, *, pre: dict | None = None) -> SSDDUNet:
    holes = ctx.config.loss_on_holes
    job = FitJob(name=name, model=seeded(lambda: build_level1(cfg), cfg.optim.seed),
                 loss=level1_loss(cfg.data, holes=holes, gate=cfg.gate),
                 train=_samples(train, cfg.data, seed=cfg.optim.seed, train=True, extra=pre),
                 validation=_samples(validation, cfg.data, seed=cfg.optim.seed, train=False, extra=pre),
                 optim=cfg.optim, folder=ctx.out / folder, num_workers=cfg.data.num_workers,
                 meta={"trained_on": [ds.checksum for ds in train]})
    model = ctx.fit(job).model
    model.eval()
    return model


@torch.no_grad()
def predict_level1(model: SSDDUNet, ds: AlignedDataset, cfg: Level1Config, *, batch: int = 8,
                   pre: dict | None = None) -> np.ndarray:
    """Level-1 prediction of every frame of ``ds`` (whole frames): ``(F, H, W)`` float32 metres, no holes.
    ``pre``: :func:`prefiltered` of a list holding ``ds`` (None: computed here when level 1 has a prefilter)."""
    device = next(model.parameters()).device
    model.eval()
    base = (pre or prefiltered([ds], cfg) or {}).get(PREFILTERED, {}).get(ds.checksum)
    out = np.empty((len(ds),) + ds.lq_intrinsics.shape, np.float32)
    for s in range(0, len(ds), batch):
        idx = range(s, min(s + batch, len(ds)))
        depth = torch.from_numpy(np.stack([ds.lq_depth(i) for i in idx])[:, None]).to(device)
        rgb = None
        if cfg.model.use_color:
            rgb = torch.from_numpy(np.stack([_rgb(ds, i) for i in idx])).to(device)
        b = None if base is None else torch.from_numpy(base[s:s + len(idx), None]).to(device)
        out[s:s + len(idx)] = level1_depth(model, depth, rgb, cfg.data, b)[:, 0].cpu().numpy()
    return out


def _rgb(ds: AlignedDataset, i: int) -> np.ndarray:
    c = ds.lq_color(i)
    if c is None:
        return np.zeros((3,) + ds.lq_intrinsics.shape, np.float32)
    return c.transpose(2, 0, 1).astype(np.float32) / 255.0


def _prefixed(model: torch.nn.Module, prefix: str) -> dict:
    return {f"{prefix}{k}": v for k, v in model.state_dict().items()}


def train_unet(ctx: RunContext) -> dict[str, Path]:
    """``ssdd_unet``: level 1 on every training sequence."""
    cfg: SSDDConfig = ctx.config
    train, validation = ctx.manifest.split("train"), ctx.manifest.split("validation")
    final = _fit_level1(ctx, cfg.level1, train, validation, "level1/final", "level 1",
                        pre=prefiltered(train + validation, cfg.level1))
    return {"ssdd_unet": ctx.save_weights("ssdd_unet", _prefixed(final, "level1/"))}


def out_of_fold(ctx: RunContext, cfg: SSDDConfig,
                pre: dict | None = None) -> tuple[dict[str, np.ndarray], dict, list[SSDDUNet]]:
    """Steps 1-2: the OOF level-1 prediction of every training sequence, the record of who made it,
    and the k fold models (``pre``: :func:`prefiltered` of the training and validation sequences,
    when level 1 has a prefilter)."""
    train = ctx.manifest.split("train")
    scenes = [e.info.get("scene") for e in ctx.manifest.entries if e.split == "train"]
    folds = assign_folds(train, cfg.folds, seed=cfg.level1.optim.seed, groups=scenes)
    preds: dict[str, np.ndarray] = {}
    record = {"folds": cfg.folds, "datasets": []}
    models = []
    for f in range(cfg.folds):
        fit_on = [ds for ds, g in zip(train, folds) if g != f]
        held = [ds for ds, g in zip(train, folds) if g == f]
        model = _fit_level1(ctx, cfg.level1, fit_on, ctx.manifest.split("validation"), f"level1/fold{f}",
                            f"level 1 fold {f + 1}/{cfg.folds}", pre=pre)
        models.append(model)
        for ds in held:
            preds[ds.checksum] = predict_level1(model, ds, cfg.level1, pre=pre)
            record["datasets"].append({"name": ds.name, "checksum": ds.checksum, "fold": f,
                                       "model": f"level1/fold{f}",
                                       "model_trained_on": [o.checksum for o in fit_on]})
    return preds, record, models


def train_lstm(ctx: RunContext) -> dict[str, Path]:
    """``ssdd_lstm``: both levels, level 2 on out-of-fold level-1 predictions."""
    cfg: SSDDConfig = ctx.config
    train, validation = ctx.manifest.split("train"), ctx.manifest.split("validation")
    motion = flows(train + validation, cfg.level2.motion)     # first: a dataset it cannot use fails before training
    pre = prefiltered(train + validation, cfg.level1)
    oof, record, fold_models = out_of_fold(ctx, cfg, pre)
    if ctx.dist.main:
        atomic_write_json(ctx.out / OOF_JSON, record)
        save_tensors(ctx.out / OOF_PREDICTIONS, {k: torch.from_numpy(v) for k, v in oof.items()}, kind="predictions",
                     meta={"what": "out-of-fold level-1 predictions (metres) by dataset checksum", "oof": record})
    final = _fit_level1(ctx, cfg.level1, train, validation, "level1/final", "level 1 final", pre=pre)
    unet_weights = ctx.save_weights("ssdd_unet", _prefixed(final, "level1/"))
    l2 = cfg.level2
    feeders = fold_models if l2.level1_input == "fold_mean" else [final]   # level 2's level 1 at inference
    val_preds = {ds.checksum: np.mean([predict_level1(m, ds, cfg.level1, pre=pre) for m in feeders], axis=0)
                 for ds in validation}
    job = FitJob(name="level 2", model=seeded(lambda: build_level2(l2), l2.optim.seed),
                 loss=level2_loss(l2.data, holes=cfg.loss_on_holes, sequence_centre=l2.centre == "sequence",
                                  motion=l2.motion, gate=l2.gate, offset=l2.offset),
                 train=_samples(train, l2.data, seed=l2.optim.seed, train=True, extra={"level1": oof, **motion}),
                 validation=_samples(validation, l2.data, seed=l2.optim.seed, train=False,
                                     extra={"level1": val_preds, **motion}),
                 optim=l2.optim, folder=ctx.out / "level2", num_workers=l2.data.num_workers,
                 meta={"trained_on": [ds.checksum for ds in train], "oof": record})
    level2 = ctx.fit(job).model
    tensors = {**_prefixed(final, "level1/"), **_prefixed(level2, "level2/")}
    if l2.level1_input == "fold_mean":
        for f, m in enumerate(fold_models):
            tensors.update(_prefixed(m, f"{FOLD_PREFIX}{f}/"))
    lstm_weights = ctx.save_weights("ssdd_lstm", tensors, oof=record)
    return {"ssdd_unet": unet_weights, "ssdd_lstm": lstm_weights}


register_trainer(Trainer("ssdd_unet", "ssdd", SSDDConfig, train_unet,
                         "SSDD level 1: UNet on LQ depth, eq. 32 loss against the warped HQ depth"))
register_trainer(Trainer("ssdd_lstm", "ssdd", SSDDConfig, train_lstm,
                         "SSDD levels 1 and 2: k-fold out-of-fold level-1 predictions, then the LSTM-UNet"))
