"""Training configs: TOML files checked against a method's config dataclasses.

A method declares its config as a (nested) dataclass whose fields all have defaults; a TOML file
overrides any of them. Every key must name a field (``unknown key 'model.widht'`` is an error,
never silently ignored), every value must have the field's type. Built-in configs ship with the
package under ``methods/configs/<method family>/<name>.toml`` (``tiny``: minutes on two CPU cores;
``paper``: full resolution for a GPU); ``--config`` takes such a name or a path to a file.

The resolved config (every field, defaults included) is saved beside the weights, so a run can be
repeated from its folder alone: :func:`to_toml` writes it, :func:`load_config` reads it back.
"""
from __future__ import annotations

import dataclasses
import os
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from methods.errors import ConfigError

CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs"
T = TypeVar("T")


def builtin_configs(family: str) -> list[str]:
    """Names of the configs shipped for ``family`` (e.g. ``"ssdd"``)."""
    return sorted(p.stem for p in (CONFIG_DIR / family).glob("*.toml"))


def config_path(name_or_path: str | os.PathLike, family: str) -> Path:
    """A built-in config name (``tiny``) or a TOML file path -> the file."""
    text = str(name_or_path)
    if not text.endswith(".toml") and os.sep not in text and "/" not in text:
        path = CONFIG_DIR / family / f"{text}.toml"
        if not path.is_file():
            raise ConfigError(f"{text}: no such built-in {family} config (built-in: "
                              f"{', '.join(builtin_configs(family)) or 'none'}; or give a .toml file)")
        return path
    path = Path(text)
    if not path.is_file():
        raise ConfigError(f"{path}: no such config file")
    return path


def load_config(name_or_path: str | os.PathLike, schema: type[T], *, family: str) -> tuple[T, Path]:
    """Read a config (built-in name or file) into ``schema``; returns ``(config, file)``."""
    path = config_path(name_or_path, family)
    try:
        data = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    return from_dict(schema, data, where=str(path)), path


def from_dict(schema: type[T], data: dict, *, where: str, prefix: str = "") -> T:
    """Build dataclass ``schema`` from ``data``; unknown keys and wrong types are one-line errors."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: {prefix.rstrip('.') or 'config'} must be a table, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(schema)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key {prefix + unknown[0]!r} (known in "
                          f"{prefix.rstrip('.') or 'the top level'}: {', '.join(fields)})")
    hints = typing.get_type_hints(schema)
    values = {}
    for name, value in data.items():
        values[name] = _coerce(hints[name], value, where=where, key=prefix + name)
    try:
        return schema(**values)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _coerce(hint: Any, value: Any, *, where: str, key: str) -> Any:
    if dataclasses.is_dataclass(hint):
        return from_dict(hint, value, where=where, prefix=key + ".")
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _coerce(inner[0], value, where=where, key=key)
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise ConfigError(f"{where}: {key} must be a list, got {value!r}")
        item = args[0] if args else Any
        out = [_coerce(item, v, where=where, key=f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: {key} must be a number, got {value!r}")
        return float(value)
    if hint in (int, bool, str):
        if type(value) is not hint:
            raise ConfigError(f"{where}: {key} must be {'an' if hint is int else 'a'} {hint.__name__}, got {value!r}")
        return value
    return value


@dataclasses.dataclass
class DataConfig:
    """How training samples are drawn from aligned datasets (see :mod:`methods.nn.data`).

    ``crop``: square crop side in pixels (0: whole frames); ``flip``: random horizontal flips;
    ``sequence_length``: consecutive frames per sample (1: single frames); ``depth_min_m`` /
    ``depth_max_m``: the clipped range of the depth normalisation; ``depth_scale_m``: 0 for that
    range coding, > 0 for the centred coding (the frame's median depth subtracted, then divided by
    ``depth_scale_m``; :func:`methods.nn.normalize.encode_depth`); ``preload``: decode every
    frame once into memory (small corpora); ``roi_crop``: probability that a training crop is
    centred on a random pixel of the region of interest (0: uniform crops); ``validation_stride``:
    frames between the first frames of two validation samples (1: every frame; never below
    ``sequence_length``), to make the per-epoch validation cheaper.
    """

    crop: int = 64
    flip: bool = True
    sequence_length: int = 1
    depth_min_m: float = 0.2
    depth_max_m: float = 6.0
    depth_scale_m: float = 0.0
    preload: bool = True
    num_workers: int = 0
    roi_crop: float = 0.0
    validation_stride: int = 1

    def __post_init__(self) -> None:
        if self.validation_stride < 1:
            raise ValueError(f"data.validation_stride must be at least 1, got {self.validation_stride}")
        if not 0.0 <= self.roi_crop <= 1.0:
            raise ValueError(f"data.roi_crop must be in [0, 1], got {self.roi_crop}")
        if self.crop < 0 or (self.crop and self.crop % 8):
            raise ValueError(f"data.crop must be 0 (whole frames) or a positive multiple of 8, got {self.crop}")
        if self.sequence_length < 1:
            raise ValueError(f"data.sequence_length must be at least 1, got {self.sequence_length}")
        if not 0 <= self.depth_min_m < self.depth_max_m:
            raise ValueError(f"data.depth_min_m must be >= 0 and below data.depth_max_m, got "
                             f"{self.depth_min_m}, {self.depth_max_m}")
        if self.depth_scale_m < 0:
            raise ValueError(f"data.depth_scale_m must be >= 0 (0: range coding), got {self.depth_scale_m}")
        if self.num_workers < 0:
            raise ValueError(f"data.num_workers must be >= 0, got {self.num_workers}")


LR_SCHEDULES = ("constant", "cosine")


@dataclasses.dataclass
class OptimConfig:
    """The optimisation: Adam with learning rate ``lr`` and a global batch of ``batch_size``.

    ``samples_per_epoch``: samples drawn per epoch (0: every sample once); ``seed`` fixes the
    initial weights, the sample order and the augmentations (one seed, same weights on CPU);
    ``grad_clip``: clip the global gradient norm (0: off). ``lr_schedule``: ``"constant"`` (default)
    or ``"cosine"``: step ``s`` of ``S`` in the whole run uses ``lr * (1 + cos(pi s / S)) / 2``
    (:func:`methods.nn.trainer.step_lr`). Why: with a constant rate, Adam moves every weight by about
    ``lr`` per step to the end, so a short run stops at a random point of that walk; for a residual
    depth net the head's bias alone is a uniform offset of ``lr`` code units per step (SSDD's tiny: 2e-3
    units of 10 cm = 0.2 mm), and the trained nets' offsets differed by 1-1.5 mm between models
    trained alike (issue 10 worklog, session 9). Annealing to 0 ends the walk.
    """

    epochs: int = 4
    batch_size: int = 8
    lr: float = 1e-3
    weight_decay: float = 0.0
    samples_per_epoch: int = 0
    grad_clip: float = 0.0
    seed: int = 0
    lr_schedule: str = "constant"

    def __post_init__(self) -> None:
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"optim.lr_schedule must be one of {', '.join(LR_SCHEDULES)}, got {self.lr_schedule!r}")
        for name in ("epochs", "batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"optim.{name} must be at least 1, got {getattr(self, name)}")
        if self.lr <= 0 or self.weight_decay < 0 or self.samples_per_epoch < 0 or self.grad_clip < 0 or self.seed < 0:
            raise ValueError("optim.lr must be > 0; weight_decay, samples_per_epoch, grad_clip and seed >= 0")


def to_dict(config: Any) -> dict:
    """A config dataclass as plain nested dicts (tuples as lists)."""
    return _plain(dataclasses.asdict(config))


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    return obj


def to_toml(config: Any) -> str:
    """The resolved config as TOML text (every field; ``None`` values are left out = default)."""
    lines: list[str] = []
    _emit(to_dict(config), [], lines)
    return "\n".join(lines).strip() + "\n"


def _emit(d: dict, path: list[str], lines: list[str]) -> None:
    scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in d.items() if isinstance(v, dict)}
    if path and scalars:
        lines.append(f"\n[{'.'.join(path)}]")
    for k, v in scalars.items():
        if v is not None:
            lines.append(f"{k} = {_toml_value(v)}")
    for k, v in tables.items():
        _emit(v, path + [k], lines)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ConfigError(f"cannot write {v!r} to TOML")
