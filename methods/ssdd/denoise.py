"""SSDD through the Denoiser interface: ``ssdd_unet`` (frames, batched) and ``ssdd_lstm`` (sequences).

Both take ``weights=RUN/<method>.safetensors`` from ``depthbench methods train``; the networks are
rebuilt from the config stored in the file. ``fill_holes=false`` (default) keeps the LQ sensor's
holes as holes (NaN), so scores compare like with like; ``true`` returns the networks' value at
every pixel. Each refuses a dataset of its own training or validation split
(:func:`methods.nn.weights.leak`) unless ``allow_train_frames=true``, which the leaderboard shows
in the method key and provenance.

With a level-1 prefilter in the weights' config (:mod:`methods.ssdd.prefilter`) each frame is
bilateral-filtered first (the base level 1 corrects). With level-2 motion (:mod:`methods.ssdd.motion`)
``ssdd_lstm`` finds each frame's optical flow into the previous frame (from the LQ colour, which it
then needs, or the LQ depth) and warps its state by it, exactly as in training.

On the CPU ``ssdd_unet`` runs the frames of a batch one at a time (at 640x480 a batch of 4 took 1.5x as long
per frame), and with two or more torch threads independent passes run side by side, one thread each
(:mod:`methods.nn.lanes`): the frames of an ``ssdd_unet`` batch, ``ssdd_lstm``'s k fold models of the fold mean.
The depth equals the one-pass path's to float rounding (1e-6 m on trained tiny models). Two quiet cores,
640x480, per frame: ``ssdd_unet`` in batches 1.7x faster, ``ssdd_lstm`` 1.07x (width 16) to 1.2x (width 8);
on shared cores about 2x (issue 10 worklog, session 11). ``DEPTHBENCH_LANES=0`` turns lanes off.
``DEPTHBENCH_COMPILE=1`` compiles the level-1 networks with ``torch.compile`` instead (:mod:`methods.nn.compiled`;
lanes off): ``ssdd_unet`` at the default width 1.4x faster once compiled, after tens of seconds of compilation.

Options of the weights' config that are not in the paper (:attr:`_SSDDBase.not_in_paper`) are named in
the provenance, so the leaderboard's config column shows them.

torch is imported only when a network is built (``prepare``), so listing methods stays fast.
"""
from __future__ import annotations

from itertools import repeat
from typing import Any

import numpy as np

from methods.base import FrameInput, check_flag, resolve_device
from methods.errors import MethodError
from methods.nn.learned import LearnedDenoiser


_HELP = {
    "weights": "weights file from 'depthbench methods train' (RUN/<method>.safetensors)",
    "fill_holes": "true: output depth also where the LQ sensor has none (default false: keep its holes)",
    "allow_train_frames": "true: score even on the weights' own training/validation datasets (marked loudly)",
}


class _SSDDBase(LearnedDenoiser):
    """Leakage guard and provenance from :class:`methods.nn.learned.LearnedDenoiser`; SSDD's own config and nets."""

    learned = True
    weights_param = "weights"
    device = "auto"
    trained_as: tuple[str, ...] = ()
    levels = 1
    defaults = {"weights": None, "fill_holes": False, "allow_train_frames": False}
    param_help = _HELP
    # the paper's SSDD is the default of each: level 1 on the raw LQ depth, level 2 without motion, eq. 32 ungated
    not_in_paper = ("level1.prefilter.kind", "level2.motion.kind", "level1.gate.sigmas", "level2.gate.sigmas",
                    "level2.level1_input", "level2.offset")

    @staticmethod
    def schema():
        """The default training config (:func:`methods.nn.learned.deviations` compares against it)."""
        from methods.ssdd.config import SSDDConfig

        return SSDDConfig()

    def check_params(self, params: dict[str, Any]) -> None:
        from methods.nn.weights import weights_meta

        check_flag(params["fill_holes"], "fill_holes", method=self.name)
        check_flag(params["allow_train_frames"], "allow_train_frames", method=self.name)
        self.meta = weights_meta(self.params["weights"], methods=self.trained_as)
        self.config = self._config(self.meta)
        self.net_color = bool(self.config.level1.model.use_color)
        self.uses_color = self.net_color or (self.levels == 2 and self.config.level2.motion.kind == "color")
        self.leaked: list[str] = []

    def _config(self, meta: dict):
        from methods.nn.config import from_dict
        from methods.ssdd.config import SSDDConfig

        return from_dict(SSDDConfig, meta.get("config") or {}, where=str(self.params["weights"]))

    def _load(self) -> dict:
        import torch

        from methods.nn import compiled
        from methods.nn.checkpoint import decode_tensors, load_state
        from methods.nn.lanes import Lanes
        from methods.ssdd.config import FOLD_PREFIX
        from methods.ssdd.model import build_level1, build_level2
        from methods.ssdd.motion import FlowSource

        f = decode_tensors(self.weights_bytes(), where=self.weights_path, kind="weights")
        dev = torch.device(resolve_device(self.device))
        nets = {"level1": build_level1(self.config.level1)}
        if self.levels == 2:
            nets["level2"] = build_level2(self.config.level2)
            if self.config.level2.level1_input == "fold_mean":
                nets.update({f"{FOLD_PREFIX}{k}": build_level1(self.config.level1) for k in range(self.config.folds)})
        for name, net in nets.items():
            load_state(net, f.prefixed(f"{name}/"), where=self.weights_path)
            net.to(dev, memory_format=torch.channels_last).eval()   # 1.3-2.5x faster convolutions on CPU
            if name != "level2":                                     # opt-in: DEPTHBENCH_COMPILE=1
                nets[name] = compiled.for_inference(net, device=dev.type)
        feeders = [n for k, n in nets.items() if k.startswith(FOLD_PREFIX)] or [nets["level1"]]
        flow = FlowSource(self.config.level2.motion) if self.config.level2.motion.enabled else None
        lanes = Lanes.split(1 if compiled.enabled() else len(feeders) if self.levels == 2 else self.batch_size,
                            device=dev.type)
        return {"device": dev, "feeders": feeders, "flow": flow, "lanes": lanes, **nets}

    def prepare(self) -> None:
        self.runtime.update(self._load())

    def _tensors(self, frames: list[FrameInput]):
        """``(depth, rgb, base)`` tensors of a batch of frames (``base``: level 1's prefiltered depth or None)."""
        import torch

        from methods.ssdd.prefilter import prefilter_frames

        dev = self.runtime["device"]
        depth = torch.from_numpy(np.stack([f.depth for f in frames])[:, None]).to(dev)
        rgb = None
        if self.net_color:
            rgb = torch.from_numpy(np.stack([f.color for f in frames]).transpose(0, 3, 1, 2).astype(np.float32)
                                   / 255.0).to(dev)
        base = prefilter_frames((f.depth for f in frames), self.config.level1.prefilter)
        return depth, rgb, None if base is None else torch.from_numpy(base[:, None]).to(dev)

    def _finish(self, out, depth_np: np.ndarray) -> np.ndarray:
        out = out.float().cpu().numpy()
        if not self.params["fill_holes"]:
            out = np.where(np.isfinite(depth_np), out, np.nan)
        return out.astype(np.float32)


class SSDDUNetDenoiser(_SSDDBase):
    """SSDD level 1 (section III-C): a UNet on the LQ depth, trained with eq. 32."""

    name = "ssdd_unet"
    version = "1"
    description = "SSDD level 1: UNet trained against the aligned HQ depth (eq. 32); needs weights"
    trained_as = ("ssdd_unet", "ssdd_lstm")
    batch_size = 4

    def _denoise_batch(self, frames: list[FrameInput]) -> list[np.ndarray]:
        import torch

        from methods.ssdd.model import level1_depth

        shapes = {f.depth.shape for f in frames}
        if len(shapes) > 1:
            return [self._denoise_batch([f])[0] for f in frames]
        depth, rgb, base = self._tensors(frames)
        lanes, net, data = self.runtime["lanes"], self.runtime["level1"], self.config.level1.data
        # on the CPU one frame at a time (1.5x faster than a batch of 4 at 640x480), the frames side by side on lanes
        each = 1 if self.runtime["device"].type == "cpu" else len(frames)
        parts = [repeat(None) if t is None else torch.split(t, each) for t in (depth, rgb, base)]  # depth: never None
        with torch.inference_mode():
            outs = lanes.map(lambda p: level1_depth(net, p[0], p[1], data, p[2]), list(zip(*parts)))
        out = torch.cat(outs)[:, 0]
        return [self._finish(o, f.depth) for o, f in zip(out, frames)]


class SSDDLSTMDenoiser(_SSDDBase):
    """SSDD level 2: the LSTM-UNet over the frames of a sequence, fed the level-1 prediction (of the
    final level-1 model, or the mean of the fold models' with ``level2.level1_input = "fold_mean"``)."""

    name = "ssdd_lstm"
    version = "1"
    description = "SSDD level 2: LSTM-UNet over each sequence on level-1 predictions (eq. 32); needs weights"
    trained_as = ("ssdd_lstm",)
    levels = 2
    sequential = True

    def start_sequence(self) -> Any:
        return None

    def _flow(self, frame: FrameInput, state: Any):
        """This frame's flow image and its backward flow ``(1, 2, H, W)`` into the previous frame's (None at
        a sequence's first frame or without motion)."""
        import torch

        src = self.runtime["flow"]
        if src is None:
            return None, None
        if src.cfg.kind == "color" and frame.color is None:
            raise MethodError(f"{self.name}: these weights follow motion by the LQ colour's flow; the frame has no colour")
        image = src.image(frame.depth, frame.color)
        if state is None:
            return image, None
        return image, torch.from_numpy(src(image, state[1]))[None].to(self.runtime["device"])

    def _step(self, frame: FrameInput, state: Any) -> tuple[np.ndarray, Any]:
        import torch

        from methods.ssdd.model import level1_depth, level2_step

        l2 = self.config.level2
        depth, rgb, base = self._tensors([frame])
        image, flow = self._flow(frame, state)
        with torch.inference_mode():   # the fold models side by side on the CPU's lanes (methods/nn/lanes.py)
            l1s = self.runtime["lanes"].map(lambda net: level1_depth(net, depth, rgb, self.config.level1.data, base),
                                            self.runtime["feeders"])
            l1 = l1s[0] if len(l1s) == 1 else torch.stack(l1s).mean(dim=0)
            out, net_state = level2_step(self.runtime["level2"], l1, depth, rgb, l2.data,
                                         None if state is None else state[0], sequence_centre=l2.centre == "sequence",
                                         flow=flow, motion=l2.motion)
        return self._finish(out[0, 0], frame.depth), (net_state, image)
