"""Training DDRNet (``depthbench methods train ddrnet``): both methods in one run.

``ddrnet`` is the denoising net alone trained with ``L_dn`` (eq. 13), as DDD's comparison ran
DDRNet; ``ddrnet_refine`` is the paper's pipeline, denoising and refinement nets trained jointly
with eq. 20. Both on single frames of the manifest's aligned LQ/HQ datasets (``D_ref`` = the warped
HQ depth, ``W`` = the region of interest, ``I`` = the LQ colour in grey), with the data
(crops, flips, depth normalisation) and optimisation of :mod:`methods.nn.config`.

Run folder: ``RUN/ddrnet/`` and ``RUN/ddrnet_refine/`` (checkpoint, history, curves),
``RUN/ddrnet.safetensors`` and ``RUN/ddrnet_refine.safetensors`` (``--param weights=...``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from methods.ddrnet.model import LossConfig, ModelConfig, batch_loss, build
from methods.nn.config import DataConfig, OptimConfig
from methods.nn.data import AlignedSamples
from methods.nn.train import RunContext, Trainer, register_trainer
from methods.nn.trainer import FitJob, seeded

METHODS = {"ddrnet": False, "ddrnet_refine": True}


@dataclass
class DDRNetConfig:
    """``methods/configs/ddrnet/<name>.toml``: ``[model]``, ``[loss]``, ``[data]``, ``[optim]``;
    ``methods``: which of ``ddrnet``, ``ddrnet_refine`` to train."""

    methods: list[str] = field(default_factory=lambda: list(METHODS))
    model: ModelConfig = field(default_factory=ModelConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    data: DataConfig = field(default_factory=DataConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)

    def __post_init__(self) -> None:
        bad = [m for m in self.methods if m not in METHODS]
        if bad or not self.methods:
            raise ValueError(f"methods must name some of {', '.join(METHODS)}, got {self.methods}")
        if self.data.sequence_length != 1:
            raise ValueError("data.sequence_length must be 1 (DDRNet sees single frames)")
        if self.data.depth_scale_m:
            raise ValueError("data.depth_scale_m must be 0: DDRNet codes depth by its range "
                             "(data.depth_min_m, data.depth_max_m) as the paper does")


def _samples(datasets, cfg: DDRNetConfig, *, train: bool):
    if not datasets:
        return None
    d = cfg.data
    return AlignedSamples(datasets, crop=d.crop if train else 0, flip=d.flip and train, seed=cfg.optim.seed,
                          preload=d.preload, roi_crop=d.roi_crop if train else 0.0,
                          stride=1 if train else d.validation_stride)


def train_ddrnet(ctx: RunContext) -> dict[str, Path]:
    cfg: DDRNetConfig = ctx.config
    train, validation = ctx.manifest.split("train"), ctx.manifest.split("validation")
    out = {}
    for method in cfg.methods:
        refine = METHODS[method]
        job = FitJob(name=method, model=seeded(lambda: build(cfg.model, refine=refine), cfg.optim.seed),
                     loss=batch_loss(cfg.loss, d_min=cfg.data.depth_min_m, d_max=cfg.data.depth_max_m),
                     train=_samples(train, cfg, train=True), validation=_samples(validation, cfg, train=False),
                     optim=cfg.optim, folder=ctx.out / method, num_workers=cfg.data.num_workers,
                     meta={"trained_on": [ds.checksum for ds in train]})
        model = ctx.fit(job).model
        out[method] = ctx.save_weights(method, {f"net/{k}": v for k, v in model.state_dict().items()})
    return out


register_trainer(Trainer("ddrnet", "ddrnet", DDRNetConfig, train_ddrnet,
                         "DDRNet: denoising net (ddrnet) and denoise + shading refinement (ddrnet_refine), eq. 12-20"))
