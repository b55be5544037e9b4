"""Training DDD (``depthbench methods train ddd``): self-supervised on calibrated multi-view sessions.

The manifest names the per-view aligned datasets of multi-view alignments (``ALIGNED/view0`` ...
with ``ALIGNED/rig.json`` beside them; :mod:`methods.ddd.multiview`); samples are simultaneous
frames of all views of one session, whole frames (optionally halved), no augmentation. The loss is
eq. 22 (:mod:`methods.ddd.model`); no reference depth and no truth is read. ``[warmup]`` (``tiny``):
the network is first fitted to a smoothing of its own input on crops of the training views
(:mod:`methods.ddd.warmup`: self-supervised too), then trained with eq. 22.

Run folder: ``RUN/ddd/`` (checkpoint, history, curves) and ``RUN/ddd.safetensors``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from methods.ddd.model import LossConfig, ModelConfig, batch_loss, build
from methods.ddd.multiview import MultiViewSamples, rig_groups
from methods.ddd.warmup import WarmupConfig, warm_start
from methods.nn.config import OptimConfig
from methods.nn.train import RunContext, Trainer, register_trainer
from methods.nn.trainer import FitJob, seeded


@dataclass
class MultiViewDataConfig:
    """``downsample``: 1, 2 or 4 (train at reduced resolution; the network is fully convolutional);
    ``preload``: keep decoded samples in memory; ``num_workers``: loader processes."""

    downsample: int = 1
    preload: bool = True
    num_workers: int = 0

    def __post_init__(self) -> None:
        if self.downsample not in (1, 2, 4) or self.num_workers < 0:
            raise ValueError(f"data.downsample must be 1, 2 or 4 and data.num_workers >= 0, got {self.downsample}, {self.num_workers}")


@dataclass
class DDDConfig:
    """``methods/configs/ddd/<name>.toml``: ``[model]``, ``[loss]``, ``[data]``, ``[optim]``."""

    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    data: MultiViewDataConfig = field(default_factory=MultiViewDataConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    warmup: WarmupConfig = field(default_factory=WarmupConfig)


def _samples(datasets, cfg: DDDConfig):
    if not datasets:
        return None
    return MultiViewSamples(rig_groups(datasets), downsample=cfg.data.downsample, preload=cfg.data.preload,
                            foreground=cfg.loss.foreground_weight > 0)


def _views(samples: MultiViewSamples) -> list:
    """Every view of every sample as ``(depth (1, h, w), mask (1, h, w))`` for the warm start."""
    out = []
    for k in range(len(samples)):
        s = samples[k]
        out += [(s["depth"][v], s["valid"][v]) for v in range(s["depth"].shape[0])]
    return out


def train_ddd(ctx: RunContext) -> dict[str, Path]:
    cfg: DDDConfig = ctx.config
    train = ctx.manifest.split("train")
    samples = _samples(train, cfg)

    def model():
        net = build(cfg.model)
        return warm_start(net, _views(samples), cfg.warmup, seed=cfg.optim.seed) if cfg.warmup.steps else net

    job = FitJob(name="ddd", model=seeded(model, cfg.optim.seed), loss=batch_loss(cfg.loss),
                 train=samples, validation=_samples(ctx.manifest.split("validation"), cfg),
                 optim=cfg.optim, folder=ctx.out / "ddd", num_workers=cfg.data.num_workers,
                 meta={"trained_on": [ds.checksum for ds in train]})
    model = ctx.fit(job).model
    return {"ddd": ctx.save_weights("ddd", {f"net/{k}": v for k, v in model.state_dict().items()})}


register_trainer(Trainer("ddd", "ddd", DDDConfig, train_ddd,
                         "DDD: partial-convolution autoencoder, self-supervised by multi-view splatting (eq. 21-27)"))
