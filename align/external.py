"""Importers of external datasets that are already aligned (the reference lies on the LQ image plane).

``import_ddrnet`` reads the layout of DDRNet's released samples (Yan et al., neycyanshi/DDRNet,
``dataset/<date>/<group>/``): per group ``depth_map/`` (the raw depth of a consumer structured-light
camera), ``high_quality_depth/`` (a multi-frame fused reference on the same image plane), ``mask/``
(the person) and, for some frames, ``color_map/``; uint16 PNG in millimetres, 640x480,
``frame_NNNNNN.png``. Each group becomes one aligned dataset (its sequence is the group name), with
the authors' intrinsics, an identity extrinsic and zero time shift (the pairs come aligned).
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np

from align.dataset import AlignedDatasetWriter
from align.errors import AlignError
from capture.camera import Intrinsics
from depthbench.fsutil import check_output_free, staged_directory

#: Intrinsics of the DDRNet samples (640x480) as used by the authors' loss code.
DDRNET_INTRINSICS = Intrinsics(640, 480, 536.628, 536.606, 310.591, 234.759)
DDRNET_UNIT_M = 1e-3
_FRAME = re.compile(r"^frame_(\d+)\.png$")


class ExternalDatasetError(AlignError):
    """An external dataset folder that does not have the expected layout or content."""


def _frames(folder: Path) -> dict[int, Path]:
    out = {}
    for p in sorted(folder.iterdir()):
        m = _FRAME.match(p.name)
        if m:
            out[int(m.group(1))] = p
    return out


def _read(path: Path, *, depth: bool, shape: tuple[int, int]) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ExternalDatasetError(f"{path}: not a readable image")
    if img.shape[:2] != shape:
        raise ExternalDatasetError(f"{path}: image is {img.shape[1]}x{img.shape[0]}, expected {shape[1]}x{shape[0]}")
    if depth and (img.dtype != np.uint16 or img.ndim != 2):
        raise ExternalDatasetError(f"{path}: depth must be single-channel 16-bit PNG (millimetres), got {img.dtype} "
                                   f"with {1 if img.ndim == 2 else img.shape[2]} channel(s)")
    return img


def _is_group(folder: Path) -> bool:
    return (folder / "depth_map").is_dir()


def _write_group(src: Path, dst: Path, name: str, *, force: bool = False) -> Path:
    K = DDRNET_INTRINSICS
    raw_dir, hq_dir, mask_dir, color_dir = (src / d for d in ("depth_map", "high_quality_depth", "mask", "color_map"))
    for d in (hq_dir, mask_dir):
        if not d.is_dir():
            raise ExternalDatasetError(f"{d}: missing (a DDRNet group needs depth_map/, high_quality_depth/ and mask/)")
    raw, hq, mask = _frames(raw_dir), _frames(hq_dir), _frames(mask_dir)
    color = _frames(color_dir) if color_dir.is_dir() else {}
    if not raw:
        raise ExternalDatasetError(f"{raw_dir}: no frame_NNNNNN.png files")
    for what, have in (("high_quality_depth", hq), ("mask", mask)):
        missing = sorted(set(raw) - set(have))
        if missing:
            raise ExternalDatasetError(f"{src / what}: no frame_{missing[0]:06d}.png for depth_map/frame_{missing[0]:06d}.png")
    meta = {"name": name, "sequence": src.name, "lq_intrinsics": K.to_dict(), "time_shift_us": 0,
            "T_lq_hq": np.eye(4).tolist(),
            "lq_sensor": "consumer structured-light camera (DDRNet samples; raw depth_map)",
            "hq_sensor": "multi-frame fused depth of the same camera (DDRNet high_quality_depth)",
            "source": {"kind": "ddrnet", "path": str(src.resolve()), "repository": "neycyanshi/DDRNet",
                       "license": "MIT", "note": "reference already on the LQ image plane; mask = ROI"}}
    with AlignedDatasetWriter(dst, meta, depth_unit_m=DDRNET_UNIT_M, force=force) as w:
        for n in sorted(raw):
            lq = _read(raw[n], depth=True, shape=K.shape).astype(np.float32) * np.float32(DDRNET_UNIT_M)
            ref = _read(hq[n], depth=True, shape=K.shape).astype(np.float32) * np.float32(DDRNET_UNIT_M)
            lq[lq == 0] = np.nan
            ref[ref == 0] = np.nan
            m = _read(mask[n], depth=False, shape=K.shape)
            roi = (m if m.ndim == 2 else m[..., 0]) > 0
            col = None
            if n in color:
                c = _read(color[n], depth=False, shape=K.shape)
                col = cv2.cvtColor(c, cv2.COLOR_BGR2RGB) if c.ndim == 3 else cv2.cvtColor(c, cv2.COLOR_GRAY2RGB)
            w.add_frame(lq, ref, lq_color=col, roi=roi, lq_frame=n, hq_frame=n)
    return dst


def import_ddrnet(src: str | os.PathLike, out: str | os.PathLike, *, force: bool = False) -> list[Path]:
    """Import DDRNet's aligned raw/fused depth pairs as aligned datasets.

    Args:
        src: a group folder (holding ``depth_map/``) or a folder of such groups.
        out: output folder. A single group becomes the aligned dataset ``out``; a folder of groups
            becomes ``out/<group>/`` for each (``depthbench bench run --data out`` takes them all).
        force: replace an existing ``out``.

    Returns:
        The aligned dataset folders written.

    Raises:
        ExternalDatasetError: missing folders or frames, wrong image size or type (one line, naming the file).
    """
    src, out = Path(src), Path(out)
    if not src.is_dir():
        raise ExternalDatasetError(f"{src}: no such folder")
    check_output_free(out, force=force, what="aligned dataset")
    if _is_group(src):
        return [_write_group(src, out, f"ddrnet/{src.name}", force=force)]
    groups = sorted(d for d in src.iterdir() if d.is_dir() and _is_group(d))
    if not groups:
        raise ExternalDatasetError(f"{src}: neither a DDRNet group (no depth_map/) nor a folder of groups")
    with staged_directory(out, force=force, what="aligned datasets folder") as tmp:
        for g in groups:
            _write_group(g, tmp / g.name, f"{src.name}/{g.name}")
    return [out / g.name for g in groups]

