"""SSDD's training config (``methods/configs/ssdd/<name>.toml``): one section per level.

::

    folds = 2                     # k of the out-of-fold level-1 predictions (>= 2)
    loss_on_holes = false         # true: eq. 32 also on pixels where the LQ depth is missing (hole filling)
    [level1.model]  width, levels, use_mask, use_color, absolute_depth, stem, norm  (methods.ssdd.networks.NetConfig)
    [level1.data]   crop, flip, sequence_length = 1, depth_min_m, depth_max_m, preload
    [level1.prefilter] kind = "none" | "bilateral", sigma_spatial, sigma_color, depth_adaptive, radius
                    (level 1 corrects the filtered LQ depth: methods.ssdd.prefilter)
    [level1.gate]   sigmas = 0 (off), floor_m, noise_z2 (not in the paper: eq. 32 only where the reference
                    is within the LQ's noise of the LQ depth, methods.ssdd.gate; also [level2.gate])
    [level1.optim]  epochs, batch_size, lr, weight_decay, samples_per_epoch, grad_clip, seed
    [level2]        level1_input = "final" | "fold_mean" (what feeds level 2 at inference, below)
                    centre = "frame" | "sequence" (the centred depth code of level 2's frames, below)
                    offset = "free" | "level1" (whether level 2 may learn a uniform shift, below)
    [level2.motion] kind = "none" | "color" | "depth", flow_scale, warp_state, previous = "none" | "level1" | "output"
                    (not in the paper: state and previous depth warped by optical flow, methods.ssdd.motion)
    [level2.model]  ... and recurrent = [-1] (ConvLSTM levels; -1 = bottleneck)
    [level2.data]   ... sequence_length = N (frames per training sequence)
    [level2.optim]  ...

``level2.level1_input``: level 2 trains on out-of-fold level-1 predictions, made by the k fold
models (each trained on (k-1)/k of the sequences). ``"final"`` (default, the issue's scheme) feeds
it the final level-1 model (trained on all sequences) at inference; ``"fold_mean"`` feeds it the
mean of the k fold models' predictions instead, so the inputs at inference come from the same models
as those it was trained on (stacking); the weights then hold the fold models too (k level-1 passes
per frame). ``ssdd_unet`` is the final model either way.

``level2.centre`` (with the centred depth code, ``data.depth_scale_m > 0``): ``"frame"`` (default)
codes each frame around its own median; ``"sequence"`` codes every frame of a sequence around its
first frame's median, in training and at inference (:func:`methods.ssdd.model.level2_depth`), so the
ConvLSTM state and the frame it meets share one code.

``level2.offset`` (not in the paper): ``"free"`` (default, the paper's) trains level 2 against the
reference as it is; ``"level1"`` trains it against the reference shifted, on every frame of every
training crop, by the median of (reference - level-1 input) over the loss's pixels
(:func:`methods.ssdd.model.offset_free_target`). The optimum of eq. 32 over a uniform shift of that
frame is then level 1's own depth offset, so level 2 learns only spatial and temporal corrections
and leaves the offset to level 1, which learned it from all training frames. Why: level 2 learns
its offset from the out-of-fold residuals of a handful of training sequences, where it is mostly
each sequence's own reference offset (the motion step's, which depends on the sequence's time
shift). With ``tiny`` (session 10, the demo's corpus: 4 training sequences; training seeds 0/10/20)
the free level 2 moved the ROI 0.26-0.32 mm nearer on every seed, on the validation sequence and on
the simulated session 201 alike, where the validation reference wanted the level-1 input 0.4-0.6 mm
deeper and the truth of 201 0.45-0.9 mm deeper; with ``"level1"`` the shift is -0.03 to +0.15 mm.
Inference is unchanged (it needs neither the ROI nor the reference). tiny's numbers: its TOML file.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from methods.nn.config import DataConfig, OptimConfig
from methods.ssdd.gate import GateConfig
from methods.ssdd.motion import MotionConfig
from methods.ssdd.networks import NetConfig
from methods.ssdd.prefilter import PrefilterConfig


LEVEL1_INPUTS = ("final", "fold_mean")
OFFSETS = ("free", "level1")
CENTRES = ("frame", "sequence")
FOLD_PREFIX = "level1_fold"   # + "<f>/": the fold models in ssdd_lstm's weights with level1_input = "fold_mean"


@dataclass
class Level1Config:
    model: NetConfig = field(default_factory=NetConfig)
    data: DataConfig = field(default_factory=DataConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    prefilter: PrefilterConfig = field(default_factory=PrefilterConfig)
    gate: GateConfig = field(default_factory=GateConfig)

    def __post_init__(self) -> None:
        if self.model.recurrent:
            raise ValueError("level1.model.recurrent must be empty (level 1 sees single frames)")
        if self.data.sequence_length != 1:
            raise ValueError("level1.data.sequence_length must be 1 (level 1 sees single frames)")


@dataclass
class Level2Config:
    model: NetConfig = field(default_factory=lambda: NetConfig(recurrent=[-1]))
    data: DataConfig = field(default_factory=lambda: DataConfig(sequence_length=4))
    optim: OptimConfig = field(default_factory=OptimConfig)
    level1_input: str = "final"
    centre: str = "frame"
    offset: str = "free"
    motion: MotionConfig = field(default_factory=MotionConfig)
    gate: GateConfig = field(default_factory=GateConfig)

    def __post_init__(self) -> None:
        if self.centre not in CENTRES:
            raise ValueError(f"level2.centre must be one of {', '.join(CENTRES)}, got {self.centre!r}")
        if self.offset not in OFFSETS:
            raise ValueError(f"level2.offset must be one of {', '.join(OFFSETS)}, got {self.offset!r}")
        if self.level1_input not in LEVEL1_INPUTS:
            raise ValueError(f"level2.level1_input must be one of {', '.join(LEVEL1_INPUTS)}, "
                             f"got {self.level1_input!r}")
        if not self.model.recurrent:
            raise ValueError("level2.model.recurrent must name at least one level (-1 = bottleneck)")


@dataclass
class SSDDConfig:
    folds: int = 2
    loss_on_holes: bool = False
    level1: Level1Config = field(default_factory=Level1Config)
    level2: Level2Config = field(default_factory=Level2Config)

    def __post_init__(self) -> None:
        if self.folds < 2:
            raise ValueError(f"folds must be at least 2, got {self.folds}")
