"""The one interface every depth-denoising method implements.

A method maps the LQ depth of a frame (``(H, W)`` float32 metres, NaN = no measurement), with the
LQ colour image and the LQ camera where it wants them, to denoised depth of the same shape and
convention. A method is a :class:`Denoiser` subclass with a ``name``, a ``version`` (bumped
whenever its output for the same input would change, so cached benchmark results are recomputed)
and its parameters; it is listed in :mod:`methods.registry`.

Four seams let the runner (:mod:`methods.run`, used by ``methods run`` and by the benchmark)
schedule any method, learned ones included, without knowing it:

* **What it needs** (:attr:`Denoiser.needs`): colour, camera, a sequence (state across frames),
  a device; the runner reads them, never the method's code.
* **State across frames** (``sequential = True``): the runner calls :meth:`Denoiser.start_sequence`
  and then :meth:`Denoiser.denoise_step` once per frame, in frame order. A long sequence may be
  cut into chunks of ``chunk_frames`` frames (``None``: the whole sequence is one chunk); each
  chunk starts from a fresh state and is first fed the ``warmup_frames`` frames before it, whose
  outputs are discarded. The chunking depends only on the method, never on the executor, so
  results are identical serially, on a process pool and on Dask.
* **Weights** (``weights_param``, conventionally ``"weights"``): a parameter naming a weights file
  (``.safetensors`` or ``.npz``, tensors only; loading never unpickles). Its sha256 replaces the
  path in the method :attr:`~Denoiser.key`, so changed weights recompute cached results and a
  leaderboard names the weights it scored; :meth:`Denoiser.weights_bytes` re-checks it.
* **Batches** (``batch_size > 1``): :meth:`Denoiser.denoise_batch` gets up to that many frames at
  once (override :meth:`Denoiser._denoise_batch`).

Heavy state (a network on a device) is built once per process by :meth:`Denoiser.prepare` into
:attr:`Denoiser.runtime`, which is never pickled: a method instance travels to worker processes
with its parameters only.
"""
from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Iterable, Iterator, Sequence

import numpy as np

from capture.camera import Intrinsics
from depthbench.fsutil import sha256_file
from methods.errors import MethodError

#: Weight-file suffixes :meth:`Denoiser.load_weights` reads (tensors only, never pickles).
WEIGHT_SUFFIXES = (".safetensors", ".npz")
#: Values of :attr:`Denoiser.device`.
DEVICES = ("cpu", "auto")


@dataclass(frozen=True)
class FrameInput:
    """One frame given to a method: ``depth`` ``(H, W)`` float32 metres (NaN = none), ``color``
    ``(H, W, 3)`` RGB (or ``None``), ``camera`` the LQ intrinsics (or ``None``), ``index`` the
    frame's index in its dataset."""

    index: int
    depth: np.ndarray
    color: np.ndarray | None = None
    camera: Intrinsics | None = None


@dataclass(frozen=True)
class MethodNeeds:
    """What the runner must give a method (see :attr:`Denoiser.needs`)."""

    color: bool = False
    camera: bool = False
    sequence: bool = False
    chunk_frames: int | None = None
    warmup_frames: int = 0
    batch_size: int = 1
    device: str = "cpu"

    def describe(self) -> str:
        """A short human-readable list, e.g. ``"colour, sequence (chunks of 64, 8 warm-up)"``."""
        parts = [name for name, on in (("colour", self.color), ("camera", self.camera)) if on]
        if self.sequence:
            chunk = "whole sequence" if self.chunk_frames is None else f"chunks of {self.chunk_frames}"
            parts.append(f"sequence ({chunk}, {self.warmup_frames} warm-up)")
        if self.batch_size > 1:
            parts.append(f"batches of {self.batch_size}")
        if self.device != "cpu":
            parts.append("a GPU when present" if self.device == "auto" else f"device {self.device}")
        return ", ".join(parts)


def resolve_device(preference: str) -> str:
    """``"cpu"`` -> ``"cpu"``; ``"auto"`` -> ``"cuda"`` when PyTorch sees a GPU in this process, else ``"cpu"``."""
    if preference != "auto":
        return "cpu"
    try:
        import torch
    except ImportError:   # pragma: no cover - torch is a dependency
        return "cpu"
    return "cuda" if torch.cuda.is_available() else "cpu"


def check_depth(depth: np.ndarray, *, name: str = "depth") -> np.ndarray:
    """The shared input check: ``(H, W)`` float32 metres, NaN holes, not all holes.

    Depth must be positive where it is not NaN: ``0`` and negative values, or infinities, are
    refused (a zero-for-hole map would silently pull every filter toward zero).
    """
    if not isinstance(depth, np.ndarray):
        raise MethodError(f"{name} must be a numpy array, got {type(depth).__name__}")
    if depth.ndim != 2:
        raise MethodError(f"{name} must have shape (H, W), got {depth.shape}")
    if depth.dtype != np.float32:
        raise MethodError(f"{name} must be float32 metres with NaN holes, got {depth.dtype}")
    finite = np.isfinite(depth)
    if not finite.any():
        raise MethodError(f"{name} has no valid pixel (all NaN)")
    if np.isinf(depth).any():
        raise MethodError(f"{name} has infinite values; mark missing depth with NaN")
    if (depth[finite] <= 0).any():
        raise MethodError(f"{name} has zero or negative values; mark missing depth with NaN, not 0")
    return depth


def check_color(color: np.ndarray | None, depth: np.ndarray) -> np.ndarray | None:
    """Colour guide: ``(H, W, 3)`` RGB or ``(H, W)``, the depth's size; uint8, uint16 or float32."""
    if color is None:
        return None
    if not isinstance(color, np.ndarray) or color.ndim not in (2, 3) or color.shape[:2] != depth.shape \
            or (color.ndim == 3 and color.shape[2] != 3):
        shape = getattr(color, "shape", None)
        raise MethodError(f"color must have shape {depth.shape} or {depth.shape + (3,)} like the depth, got {shape}")
    if color.dtype not in (np.uint8, np.uint16, np.float32):
        raise MethodError(f"color must be uint8, uint16 or float32, got {color.dtype}")
    if color.dtype == np.float32 and not np.isfinite(color).all():
        raise MethodError("color has NaN or infinite values")
    return color


def guide_planes(color: np.ndarray) -> np.ndarray:
    """A checked colour image as a float32 guide in its own units: ``(H, W)`` or planar ``(3, H, W)``."""
    guide = color.astype(np.float32)
    return guide if guide.ndim == 2 else np.ascontiguousarray(np.moveaxis(guide, 2, 0))


def _number(method: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise MethodError(f"{method}: {name} must be a number, got {value!r}")
    return float(value)


def check_sigma(value: Any, name: str, *, method: str, unit: str, allow_inf: bool = False) -> float:
    """A Gaussian width: a finite number > 0 (``inf`` too where ``allow_inf``: the kernel is off)."""
    v = _number(method, name, value)
    if np.isnan(v) or v <= 0 or (np.isinf(v) and not allow_inf):
        raise MethodError(f"{method}: {name} must be a positive number of {unit}, got {value!r}")
    return v


def _integer_in(value: Any, low: int, high: int) -> bool:
    """True for an integral number (``3`` or ``3.0``, not ``True``) within ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)):
        return False
    v = float(value)
    return bool(np.isfinite(v)) and v == int(v) and low <= int(v) <= high


def check_radius(value: Any, sigma_spatial: float, *, method: str) -> int:
    """Window radius in pixels: an integer >= 1; ``None`` derives ``max(1, ceil(2 * sigma_spatial))``."""
    if value is None:
        return max(1, int(np.ceil(2.0 * sigma_spatial - 1e-9)))
    if not _integer_in(value, 1, 100):
        raise MethodError(f"{method}: radius must be an integer number of pixels from 1 to 100 (or none), got {value!r}")
    return int(value)


def check_iterations(value: Any, *, method: str) -> int:
    """An iteration count: an integer >= 1."""
    if not _integer_in(value, 1, 1000):
        raise MethodError(f"{method}: iterations must be an integer from 1 to 1000, got {value!r}")
    return int(value)


def check_flag(value: Any, name: str, *, method: str) -> bool:
    """A yes/no option: a bool (``true``/``false`` on the command line)."""
    if not isinstance(value, (bool, np.bool_)):
        raise MethodError(f"{method}: {name} must be true or false, got {value!r}")
    return bool(value)


class Denoiser:
    """Base class of every method.

    A frame method sets ``name``, ``version``, ``defaults`` (parameter -> default, ``None`` meaning
    "derive the documented default") and implements :meth:`_denoise` (and, to use batches,
    :meth:`_denoise_batch`). A sequence method sets ``sequential = True`` and implements
    :meth:`start_sequence` and :meth:`_step`. A learned method sets ``learned = True`` and
    ``weights_param = "weights"`` (with ``"weights": None`` in ``defaults``) and loads its network
    in :meth:`prepare` from :meth:`weights_bytes` / :meth:`load_weights`.
    """

    name: ClassVar[str] = ""
    version: ClassVar[str] = "1"
    description: ClassVar[str] = ""
    defaults: ClassVar[dict[str, Any]] = {}
    #: one line per parameter: meaning and unit (shown by ``depthbench methods list``)
    param_help: ClassVar[dict[str, str]] = {}
    learned: ClassVar[bool] = False
    #: needs the LQ colour image (a frame without one is not given to the method)
    uses_color: ClassVar[bool] = False
    #: needs the LQ intrinsics (the runner always passes them; this documents the dependency)
    uses_camera: ClassVar[bool] = False
    #: keeps state across the frames of a sequence (see the module docstring)
    sequential: ClassVar[bool] = False
    #: sequence methods: frames per chunk (``None``: the whole sequence is one chunk)
    chunk_frames: ClassVar[int | None] = None
    #: sequence methods: frames fed before each chunk (outputs discarded); chunk 0 has none before it
    warmup_frames: ClassVar[int] = 0
    #: frames per :meth:`denoise_batch` call the method can use (1: one at a time)
    batch_size: ClassVar[int] = 1
    #: ``"cpu"``, or ``"auto"``: CUDA when the process has a GPU (:func:`resolve_device`)
    device: ClassVar[str] = "cpu"
    #: the parameter naming a weights file (conventionally ``"weights"``), or None
    weights_param: ClassVar[str | None] = None

    def __init__(self, **params: Any) -> None:
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            raise MethodError(f"{self.name}: unknown parameter {unknown[0]!r} (known: {', '.join(self.defaults) or 'none'})")
        self.params = {**self.defaults, **params}
        self.weights_sha256: str | None = None
        if self.weights_param is not None:
            self.params[self.weights_param], self.weights_sha256 = _check_weights(
                self.name, self.weights_param, self.params.get(self.weights_param))
        self.check_params(self.params)
        self.runtime: dict[str, Any] = {}

    # ------------------------------------------------------------------ identity and needs
    def check_params(self, params: dict[str, Any]) -> None:
        """Raise :class:`MethodError` for impossible parameters (negative sigmas, ...)."""

    @classmethod
    def needs_weights(cls) -> bool:
        """True when the method cannot run without a weights file given as a parameter."""
        return cls.weights_param is not None and cls.defaults.get(cls.weights_param) is None

    @classmethod
    def declared_needs(cls) -> MethodNeeds:
        """The needs the class declares (no instance: a method that needs weights can be described too)."""
        return MethodNeeds(color=bool(cls.uses_color), camera=bool(cls.uses_camera),
                           sequence=bool(cls.sequential), chunk_frames=cls.chunk_frames,
                           warmup_frames=int(cls.warmup_frames), batch_size=int(cls.batch_size),
                           device=cls.device)

    @property
    def needs(self) -> MethodNeeds:
        """What the runner must give this method (colour, camera, sequence scheduling, batch, device)."""
        return self.declared_needs()

    @property
    def key(self) -> str:
        """Identity for caching: name, version and parameters (a weights file by its content hash)."""
        shown = dict(self.params)
        if self.weights_param is not None:
            shown[self.weights_param] = f"sha256:{self.weights_sha256[:16]}"
        items = ",".join(f"{k}={v}" for k, v in sorted(shown.items()))
        return f"{self.name}@{self.version}({items})"

    @property
    def weights_path(self) -> Path | None:
        """The weights file (absolute), or None for a method without weights."""
        return None if self.weights_param is None else Path(self.params[self.weights_param])

    def check_dataset(self, dataset: Any) -> None:
        """Refuse (raise :class:`MethodError`) a dataset this method must not be scored on, before any work.

        Called by the runners with each aligned dataset (an ``align.dataset.AlignedDataset``); a
        learned method refuses the datasets of its own training or validation split. Default: accept.
        """

    def provenance(self) -> dict[str, Any]:
        """Extra facts a leaderboard should name (training manifest, config, ...). Default: none."""
        return {}

    def describe(self) -> dict[str, Any]:
        """The method as a results manifest records it: name, version, key, weights, provenance."""
        out = {"name": self.name, "version": str(self.version), "key": self.key, "learned": bool(self.learned),
               "description": self.description or ""}
        if self.weights_param is not None:
            out["weights"] = {"file": str(self.weights_path), "sha256": self.weights_sha256}
        extra = self.provenance()
        if extra:
            out["provenance"] = extra
        return out

    # ------------------------------------------------------------------ weights and runtime state
    def weights_bytes(self) -> bytes:
        """The weights file's content, checked against the hash in :attr:`key` (changed since: an error)."""
        path = self.weights_path
        if path is None:
            raise MethodError(f"{self.name}: has no weights")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise MethodError(f"{path}: cannot read the weights ({exc.strerror or exc})") from None
        if hashlib.sha256(data).hexdigest() != self.weights_sha256:
            raise MethodError(f"{path}: weights changed since {self.name} was configured (sha256 differs)")
        return data

    def load_weights(self) -> dict[str, np.ndarray]:
        """The weights as named numpy arrays (``.safetensors`` or ``.npz``; never unpickles)."""
        return read_weights(self.weights_bytes(), self.weights_path)

    def prepare(self) -> None:
        """Build heavy state (a network on its device) into :attr:`runtime`, once per process.

        Called by the runner before the first frame in each process; the default does nothing.
        """

    def ensure_prepared(self) -> None:
        """Run :meth:`prepare` once in this process (the runner calls it before the first frame)."""
        if not self.runtime.get("_prepared"):
            self.prepare()
            self.runtime["_prepared"] = True

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["runtime"] = {}          # a network, a device handle: rebuilt by prepare() where it lands
        return state

    # ------------------------------------------------------------------ denoising
    def denoise(self, depth: np.ndarray, color: np.ndarray | None = None,
                camera: Intrinsics | None = None) -> np.ndarray:
        """One frame: ``(H, W)`` float32 metres with NaN holes in, the same out.

        A sequence method denoises the frame as a sequence of one frame.
        """
        frame = FrameInput(index=0, depth=depth, color=color, camera=camera)
        if self.sequential:
            return self.denoise_step(frame, self.start_sequence())[0]
        return self.denoise_batch([frame])[0]

    def denoise_batch(self, frames: Sequence[FrameInput]) -> list[np.ndarray]:
        """Several frames of a frame method at once (at most :attr:`batch_size` are useful)."""
        if self.sequential:
            raise MethodError(f"{self.name}: a sequence method denoises frame by frame (denoise_step)")
        frames = [_checked(f) for f in frames]
        self.ensure_prepared()
        outs = list(self._denoise_batch(frames))
        if len(outs) != len(frames):
            raise MethodError(f"{self.name} returned {len(outs)} depth maps for a batch of {len(frames)} frames")
        return [_as_output(self, f, out) for f, out in zip(frames, outs)]

    def denoise_sequence(self, frames: Iterable[FrameInput]) -> Iterator[np.ndarray]:
        """Every frame of one sequence, in order, from a fresh state (frame methods: one at a time)."""
        state = self.start_sequence() if self.sequential else None
        for frame in frames:
            if self.sequential:
                out, state = self.denoise_step(frame, state)
            else:
                out = self.denoise_batch([frame])[0]
            yield out

    def start_sequence(self) -> Any:
        """Sequence methods: the state before a sequence's (or chunk's) first frame."""
        raise MethodError(f"{self.name}: not a sequence method")

    def denoise_step(self, frame: FrameInput, state: Any) -> tuple[np.ndarray, Any]:
        """Sequence methods: the next frame in order -> ``(denoised depth, new state)``."""
        frame = _checked(frame)
        self.ensure_prepared()
        out, state = self._step(frame, state)
        return _as_output(self, frame, out), state

    # ------------------------------------------------------------------ what subclasses implement
    def _denoise(self, depth: np.ndarray, color: np.ndarray | None, camera: Intrinsics | None) -> np.ndarray:
        raise NotImplementedError

    def _denoise_batch(self, frames: list[FrameInput]) -> list[np.ndarray]:
        """Override for batched inference; the default calls :meth:`_denoise` per frame."""
        return [self._denoise(f.depth, f.color, f.camera) for f in frames]

    def _step(self, frame: FrameInput, state: Any) -> tuple[np.ndarray, Any]:
        raise NotImplementedError

    def __repr__(self) -> str:
        return self.key


def _checked(frame: FrameInput) -> FrameInput:
    depth = check_depth(frame.depth)
    return FrameInput(index=frame.index, depth=depth, color=check_color(frame.color, depth), camera=frame.camera)


def _as_output(method: Denoiser, frame: FrameInput, out: Any) -> np.ndarray:
    if not isinstance(out, np.ndarray) or out.shape != frame.depth.shape:
        raise MethodError(f"{method.name} returned {getattr(out, 'shape', type(out).__name__)} for a "
                          f"{frame.depth.shape} depth")
    return out.astype(np.float32, copy=False)


def _check_weights(method: str, param: str, value: Any) -> tuple[str, str]:
    """A weights parameter -> (absolute path, sha256 of the file)."""
    if value is None:
        raise MethodError(f"{method}: needs a weights file (parameter {param}=PATH, {' or '.join(WEIGHT_SUFFIXES)})")
    path = Path(str(value)).expanduser().resolve()
    if path.suffix not in WEIGHT_SUFFIXES:
        raise MethodError(f"{path}: weights must be a {' or '.join(WEIGHT_SUFFIXES)} file")
    if not path.is_file():
        raise MethodError(f"{path}: no such weights file")
    try:
        return str(path), sha256_file(path)
    except OSError as exc:
        raise MethodError(f"{path}: cannot read the weights ({exc.strerror or exc})") from None


def read_weights(data: bytes, path: str | Path) -> dict[str, np.ndarray]:
    """Named arrays from the bytes of a ``.safetensors`` or ``.npz`` file (no pickles: a pickle is an error)."""
    try:
        if Path(path).suffix == ".safetensors":
            from safetensors.numpy import load

            return dict(load(data))
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except Exception as exc:   # noqa: BLE001 - any decoder failure is a bad file, reported in one line
        raise MethodError(f"{path}: not a readable weights file ({type(exc).__name__}: {exc})") from None
