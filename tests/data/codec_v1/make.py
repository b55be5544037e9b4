"""Writes this fixture with the frame writers as they were before the one-codec refactor.

Run once, on commit 10f5d8d (the last commit before ``depthbench/frames.py``), as
``PYTHONPATH=<that checkout> python tests/data/codec_v1/make.py``; the files it wrote are committed.
``tests/depthbench/test_frames.py`` reads them with today's readers and re-writes the same pixels
with today's writers, expecting the same bytes (when OpenCV is the version recorded here).
"""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
W, H = 32, 24


def pixels() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    depth = rng.uniform(0.3, 5.0, (2, H, W)).astype(np.float32)
    depth[:, :3, :4] = np.nan                      # holes
    depth[0, 5, 5], depth[1, 6, 6] = 0.0, 70.0     # out of range: written as 0
    counts = rng.integers(0, 6000, (2, H, W)).astype(np.uint16)
    color = rng.integers(0, 256, (2, H, W, 3)).astype(np.uint8)
    color[:, :, :W // 2] //= 8                     # some structure for JPEG
    roi = rng.random((2, H, W)) > 0.3
    return {"depth_m": depth, "counts": counts, "color": color, "roi": roi}


def write_fixture(root: Path, *, encode_png16, encode_color) -> None:
    """Write the session, aligned dataset, denoised output and simulator frames into ``root``
    with the public writers; ``encode_png16(counts) -> bytes`` and ``encode_color(rgb, encoding)
    -> (bytes, ext)`` are the simulator's frame encoders."""
    from align.dataset import AlignedDatasetWriter
    from capture.camera import Intrinsics
    from capture.session import SessionWriter
    from methods import get
    from methods.output import DenoisedWriter

    p = pixels()
    K = Intrinsics(W, H, 30.0, 30.0, (W - 1) / 2, (H - 1) / 2)

    def stream(kind, enc):
        d = {"type": kind, "width": W, "height": H, "fps": 30.0, "encoding": enc, "intrinsics": K.to_dict()}
        return d | ({"depth_unit_m": 0.001} if kind == "depth" else {})

    manifest = {"name": "codec-v1", "created_utc": "2026-11-22T00:00:00+00:00", "sensors": {
        "lq": {"role": "lq", "model": "m", "serial": "1",
               "streams": {"depth": stream("depth", "png16"), "color": stream("color", "png")}},
        "hq": {"role": "hq", "model": "m", "serial": "2",
               "streams": {"depth": stream("depth", "png16"), "color": stream("color", "jpeg")}}}}
    w = SessionWriter(root / "session", manifest)
    for i in range(2):
        w.add_frame("lq", "depth", i, 1000 * i, 1000 * i, p["depth_m"][i])      # float metres
        w.add_frame("lq", "color", i, 1000 * i, 1000 * i, p["color"][i])
        w.add_frame("hq", "depth", i, 1000 * i, 1000 * i, p["counts"][i])       # uint16 counts
        rel, sha = w.write_frame_file("hq", "color", i, p["color"][i], fast=i == 1)  # JPEG: fast changes nothing
        w.index_frame("hq", "color", i, 1000 * i, 1000 * i, rel, sha)
    rel, sha = w.write_frame_file("lq", "depth", 2, p["depth_m"][1], fast=True)   # the recorder's fast PNG
    w.index_frame("lq", "depth", 2, 2000, 2000, rel, sha)
    w.close()

    a = AlignedDatasetWriter(root / "aligned", {"name": "codec-v1", "lq_intrinsics": K.to_dict(), "time_shift_us": 0,
                                                "T_lq_hq": np.eye(4).tolist()})
    for i in range(2):
        a.add_frame(p["depth_m"][i], p["depth_m"][1 - i], lq_color=p["color"][i], roi=p["roi"][i],
                    truth=p["depth_m"][i] * 0.5, lq_frame=i, hq_frame=i, lq_timestamp_us=1000 * i)
    a.close()

    d = DenoisedWriter(root / "denoised", get("raw"), dataset_checksum="0" * 64, dataset_name="codec-v1",
                       dataset_path="aligned", depth_unit_m=1e-4)
    for i in range(2):
        d.add(i, p["depth_m"][i])
    d.close()

    (root / "sim").mkdir()
    (root / "sim" / "depth.png").write_bytes(encode_png16(p["counts"][0]))
    for enc in ("png", "jpeg"):
        data, ext = encode_color(p["color"][0], enc)
        (root / "sim" / f"color.{ext}").write_bytes(data)


def main() -> None:
    from capture.sim.pipeline import encode_color, encode_png16   # the pre-refactor simulator encoders

    for name in ("session", "aligned", "denoised", "sim"):
        shutil.rmtree(HERE / name, ignore_errors=True)
    write_fixture(HERE, encode_png16=encode_png16, encode_color=encode_color)
    (HERE / "opencv_version.txt").write_text(cv2.__version__ + "\n")


if __name__ == "__main__":
    main()
