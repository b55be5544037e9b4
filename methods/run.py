"""Running a method over an aligned dataset: the one path every caller takes.

``depthbench methods run`` (:func:`denoise_dataset`), the benchmark's tasks
(:class:`FrameRunner` in ``bench.compute``) and the demo all feed frames to a method through this
module, so they schedule it the same way and treat every frame alike.

Scheduling (:func:`plan_chunks`): a frame method gets frames one by one (or in batches of its
``batch_size``); a sequence method gets the frames of a sequence in frame order from a fresh state,
in chunks of its ``chunk_frames`` (the whole sequence when ``None``), each chunk first fed the
``warmup_frames`` frames before it (their outputs are discarded). The plan depends only on the
method and the frame count, so any executor gives the same outputs.

What happens to a frame (one rule for every caller):

* **empty**: the LQ depth has no valid pixel. The method is not called (a sequence method does
  not see the frame; its state carries over); the output is all NaN.
* **missing input**: the method needs the colour image and the frame has none. The method is not
  called and there is no output (``None``): the benchmark scores the frame as NaN; ``methods run``
  refuses a dataset in which any frame lacks colour before it starts.
* **rejected**: the method raises :class:`MethodError` on the frame (or returns something that is
  not a depth map of the input's size). The run stops with :class:`FrameRejectedError` naming the
  dataset, the frame and the method key, and publishes nothing (``methods run`` leaves no output
  folder; ``bench run`` publishes no table, keeping only the cache of results already computed).
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
from tqdm import tqdm

from methods.base import Denoiser, FrameInput
from methods.errors import FrameRejectedError, MethodError

DENOISED = "denoised"
EMPTY = "empty"
MISSING_INPUT = "missing_input"


@dataclass(frozen=True)
class Chunk:
    """Frames a method is fed in one go: ``warmup`` (outputs discarded), then ``frames``, in order."""

    frames: tuple[int, ...]
    warmup: tuple[int, ...] = ()


@dataclass(frozen=True)
class DenoisedFrame:
    """A method's output for one frame: ``depth`` ``(H, W)`` float32 metres (NaN = none), or None
    when the frame lacks an input the method needs; ``status`` is ``"denoised"``, ``"empty"`` or
    ``"missing_input"`` (see the module docstring)."""

    index: int
    depth: np.ndarray | None
    status: str


def plan_chunks(method: Denoiser, n_frames: int) -> list[Chunk]:
    """How ``method`` is fed a sequence of ``n_frames`` frames (see the module docstring)."""
    needs = method.needs
    if needs.sequence:
        size = n_frames if needs.chunk_frames is None else int(needs.chunk_frames)
        warm = int(needs.warmup_frames)
    else:
        size, warm = int(needs.batch_size), 0
    if size < 1:
        raise MethodError(f"{method.name}: chunk and batch sizes must be at least 1, got {size}")
    return [Chunk(frames=tuple(range(s, min(s + size, n_frames))), warmup=tuple(range(max(0, s - warm), s)))
            for s in range(0, n_frames, size)]


def frame_status(method: Denoiser, frame: FrameInput) -> str:
    """``"missing_input"``, ``"empty"`` or ``"denoised"`` (the frame is given to the method)."""
    if method.uses_color and frame.color is None:
        return MISSING_INPUT
    if not np.isfinite(frame.depth).any():
        return EMPTY
    return DENOISED


class FrameRunner:
    """Feeds one method the frames of one chunk, in order, applying the frame rule of this module.

    :meth:`push` takes the next frame and returns the outputs that are ready (a sequence method's at
    once, a batch method's when its batch is full; warm-up frames give none); :meth:`finish` returns
    the rest. ``where`` names the data in errors (a dataset folder).
    """

    def __init__(self, method: Denoiser, *, where: str, warmup: int = 0) -> None:
        self.method, self.where, self._warmup = method, where, int(warmup)
        self._seen = 0
        self._pending: list[tuple[FrameInput, str]] = []
        try:
            method.ensure_prepared()
            self._state = method.start_sequence() if method.sequential else None
        except MethodError as exc:
            raise MethodError(f"{where}: {method.key}: {exc}") from None

    def push(self, frame: FrameInput) -> list[DenoisedFrame]:
        if frame.color is not None and not self.method.uses_color:   # every caller gives a method the same inputs
            frame = dataclasses.replace(frame, color=None)
        warm = self._seen < self._warmup
        self._seen += 1
        status = frame_status(self.method, frame)
        if self.method.sequential:
            out = None
            if status == DENOISED:
                out, self._state = self._guarded([frame], self.method.denoise_step, frame, self._state)
            return [] if warm else [_result(frame, status, out)]
        self._pending.append((frame, status))
        if sum(s == DENOISED for _, s in self._pending) >= self.method.batch_size:
            return self.finish()
        return []

    def finish(self) -> list[DenoisedFrame]:
        """Outputs of the frames still held (a partial batch)."""
        pending, self._pending = self._pending, []
        fed = [f for f, s in pending if s == DENOISED]
        outs = iter(self._guarded(fed, self.method.denoise_batch, fed) if fed else [])
        return [_result(f, s, next(outs) if s == DENOISED else None) for f, s in pending]

    def _guarded(self, frames: list[FrameInput], fn, *args):
        try:
            return fn(*args)
        except MethodError as exc:
            which = f"frame {frames[0].index}" if len(frames) == 1 else \
                f"frames {frames[0].index}-{frames[-1].index}"
            raise FrameRejectedError(f"{self.where}: {which}: {self.method.key} refused it: {exc}") from None


def _result(frame: FrameInput, status: str, out: np.ndarray | None) -> DenoisedFrame:
    if status == EMPTY:
        out = np.full(frame.depth.shape, np.nan, np.float32)
    return DenoisedFrame(index=frame.index, depth=out, status=status)


def read_input(dataset, index: int, method: Denoiser) -> FrameInput:
    """Frame ``index`` of an aligned dataset as ``method`` needs it (colour only when it uses colour)."""
    color = dataset.lq_color(index) if method.uses_color else None
    return FrameInput(index=index, depth=dataset.lq_depth(index), color=color, camera=dataset.lq_intrinsics)


def iter_dataset(method: Denoiser, dataset, *, progress: bool | None = None) -> Iterator[DenoisedFrame]:
    """Every frame of an aligned dataset through ``method``, in frame order (see :func:`plan_chunks`)."""
    bar = tqdm(total=len(dataset), desc=method.name, unit="frame", file=sys.stderr, leave=False,
               disable=None if progress is None else not progress)
    try:
        for chunk in plan_chunks(method, len(dataset)):
            runner = FrameRunner(method, where=str(dataset.root), warmup=len(chunk.warmup))
            for i in chunk.warmup + chunk.frames:
                for done in runner.push(read_input(dataset, i, method)):
                    bar.update(1)
                    yield done
            for done in runner.finish():
                bar.update(1)
                yield done
    finally:
        bar.close()


@dataclass
class DenoiseResult:
    """What :func:`denoise_dataset` wrote: the folder, the method key, frame counts and seconds."""

    out: Path
    method_key: str
    frames: int
    empty: int
    seconds: float


def check_inputs(method: Denoiser, dataset) -> None:
    """Refuse, before any work, a dataset without frames, without colour for a colour method, or one
    the method itself refuses (:meth:`methods.base.Denoiser.check_dataset`)."""
    if len(dataset) == 0:
        raise MethodError(f"{dataset.root}: the aligned dataset has no frames")
    method.check_dataset(dataset)
    if method.uses_color:
        lacking = [i for i, row in enumerate(dataset.rows) if not row.get("lq_color_file")]
        if lacking:
            raise MethodError(f"{method.name} needs the LQ colour image, and {dataset.root} has none "
                              f"for {len(lacking)} of its {len(dataset)} frames (first: frame {lacking[0]})")


def denoise_dataset(method: Denoiser, data, out: str | os.PathLike, *, force: bool = False,
                    progress: bool | None = None) -> DenoiseResult:
    """Run ``method`` on every frame of the aligned dataset ``data``; write the denoised-output folder ``out``.

    Args:
        method: a :class:`methods.base.Denoiser` instance.
        data: an aligned dataset folder or an opened ``AlignedDataset``.
        out: the output folder (format: ``data_manifests/denoised.md``); built aside, published complete.
        force: replace an existing ``out``.
        progress: tqdm bar on stderr (None: only when stderr is a terminal).

    Raises:
        MethodError (:class:`FrameRejectedError` for a frame the method refuses): one line; nothing written.
    """
    from align.dataset import AlignedDataset   # methods may import align (data formats); never bench
    from methods.output import DenoisedWriter

    dataset = data if isinstance(data, AlignedDataset) else AlignedDataset(data)
    check_inputs(method, dataset)
    dataset.check_frame_files()   # every frame file present and readable before the long work
    started = time.perf_counter()
    writer = DenoisedWriter(out, method, dataset_checksum=dataset.checksum, dataset_name=dataset.name,
                            dataset_path=str(dataset.root), depth_unit_m=dataset.depth_unit_m, force=force)
    empty = 0
    try:
        for done in iter_dataset(method, dataset, progress=progress):
            empty += done.status == EMPTY
            writer.add(done.index, done.depth)
        seconds = time.perf_counter() - started
        root = writer.close(seconds=seconds)
    except BaseException as exc:
        writer.abort(exc)
        raise
    return DenoiseResult(out=Path(root), method_key=method.key, frames=len(dataset), empty=empty, seconds=seconds)

