"""The frame codec (``depthbench.frames``) against frames written before it existed.

``tests/data/codec_v1/`` holds a tiny session, aligned dataset, denoised output and simulator
frames written by the five separate frame writers of commit 10f5d8d (``make.py`` there). Today's
readers must read them to the pixel (the formats did not change), and today's writers must write
the same pixels to the same bytes (so checksums, dataset checksums and cached results stay valid).
"""
from __future__ import annotations

import importlib.util
import io
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from align.dataset import AlignedDataset
from capture.session import open_session
from capture.truth import SessionFormatError
from depthbench import frames as codec
from methods.output import DenoisedOutput

FIXTURE = Path(__file__).resolve().parents[1] / "data" / "codec_v1"


def _make_module():
    spec = importlib.util.spec_from_file_location("codec_v1_make", FIXTURE / "make.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def px():
    return _make_module().pixels()   # the seeded pixels the fixture's frames were written from


def _metres(depth_m, unit):
    """The documented depth format by hand: counts = round(d / unit), kept when 1..65535, else none."""
    out = np.full(depth_m.shape, np.nan, np.float32)
    for idx in np.ndindex(depth_m.shape):
        d = float(depth_m[idx])
        if np.isfinite(d):
            c = round(d / unit)
            if 1 <= c <= 65535:
                out[idx] = np.float32(c) * np.float32(unit)
    return out


def test_old_session_reads_to_the_pixel(px):
    s = open_session(FIXTURE / "session", verify="full")
    for i in range(2):
        assert np.array_equal(s.read_depth("lq", i), _metres(px["depth_m"][i], 0.001), equal_nan=True)
        assert np.array_equal(s.read_image("hq", "depth", i), px["counts"][i])
        assert np.array_equal(s.read_color("lq", i), px["color"][i])
        jpeg = s.read_color("hq", i).astype(int)    # lossy: compared with another decoder, in RGB order
        pil = np.asarray(Image.open(s.frame_path("hq", "color", i)).convert("RGB"), dtype=int)
        assert np.abs(jpeg - pil).mean() < 2
    assert np.array_equal(s.read_depth("lq", 2), _metres(px["depth_m"][1], 0.001), equal_nan=True)  # stored PNG
    assert s.check_frame_files() == 9


def test_old_aligned_and_denoised_read_to_the_pixel(px):
    a = AlignedDataset(FIXTURE / "aligned")
    for i in range(2):
        f = a.frame(i)
        assert np.array_equal(f.lq_depth, _metres(px["depth_m"][i], 1e-4), equal_nan=True)
        assert np.array_equal(f.reference, _metres(px["depth_m"][1 - i], 1e-4), equal_nan=True)
        assert np.array_equal(f.truth, _metres(px["depth_m"][i] * 0.5, 1e-4), equal_nan=True)
        assert np.array_equal(f.roi, px["roi"][i]) and np.array_equal(f.lq_color, px["color"][i])
    d = DenoisedOutput(FIXTURE / "denoised")
    for i in range(2):
        assert np.array_equal(d.depth(i), _metres(px["depth_m"][i], 1e-4), equal_nan=True)


def _files(root: Path) -> dict[str, bytes]:
    skip = {"denoised.json", "opencv_version.txt", "make.py"}  # denoised.json holds the time
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.name not in skip}


def test_todays_writers_write_the_old_bytes(tmp_path):
    made_with = (FIXTURE / "opencv_version.txt").read_text().strip()
    if cv2.__version__ != made_with:
        pytest.skip(f"the fixture's PNG/JPEG bytes come from OpenCV {made_with}, this is {cv2.__version__} "
                    "(the read tests above still check the format)")

    def png16(counts):   # the simulator's settings until 2026-11-23 (it writes PNG_FAST now: same pixels, below)
        return codec.encode_png(counts, params=codec.PNG_RLE)

    def color(rgb, encoding):
        return codec.encode_color(rgb, encoding=encoding)

    _make_module().write_fixture(tmp_path, encode_png16=png16, encode_color=color)
    old, new = _files(FIXTURE), _files(tmp_path)
    assert sorted(old) == sorted(new)
    differ = [name for name in old if old[name] != new[name]]
    assert not differ, differ


def test_encode_decode_round_trip_and_bad_images():
    rng = np.random.default_rng(1)
    depth = rng.uniform(0.2, 7.0, (5, 7)).astype(np.float32)
    depth[0, 0], depth[1, 1], depth[2, 2] = np.nan, -1.0, 0.00004   # none, negative, rounds to 0 counts
    for params in (codec.PNG_RLE, codec.PNG_STORED, codec.PNG_LEVEL1):
        data = codec.encode_depth_png(depth, unit_m=1e-4, params=params)
        back = codec.decode_depth_png(data, unit_m=1e-4, where="x.png")
        assert np.array_equal(back, _metres(depth, 1e-4), equal_nan=True)
    with pytest.raises(SessionFormatError, match=r"^x\.png: truncated PNG"):
        codec.decode_depth_png(data[:-30], unit_m=1e-4, where="x.png", error=SessionFormatError)
    colour_png, _ = codec.encode_color(rng.integers(0, 255, (5, 7, 3), dtype=np.uint8))
    with pytest.raises(SessionFormatError, match="single-channel 16-bit"):
        codec.decode_depth_png(colour_png, unit_m=1e-4, where="x.png", error=SessionFormatError)
    with pytest.raises(SessionFormatError, match="16-bit frames must be"):
        codec.encode_depth_png(np.zeros((5, 7), np.uint8), unit_m=1e-4, error=SessionFormatError)


def test_fast_png_has_the_pixels_of_opencvs_png():
    """:data:`PNG_FAST` (written by the codec, ISA-L deflate) decodes, with PIL and with OpenCV, to
    the pixels given and to what OpenCV's :data:`PNG_RLE` file decodes to; depth, colour, mask."""
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:37, 0:53]
    counts = (1500 + 7 * xx + 3 * yy + rng.integers(0, 40, xx.shape)).astype(np.uint16)  # a noisy slanted plane
    counts[5:9, 10:30] = 0
    counts[0, 0], counts[-1, -1] = 65535, 1        # both bytes of the big-endian samples exercised
    rgb = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    depth = codec.encode_png(counts, params=codec.PNG_FAST)
    colour, ext = codec.encode_color(rgb, params=codec.PNG_FAST)
    mask = codec.encode_mask_png(counts > 1600, params=codec.PNG_FAST)
    assert ext == "png" and codec.image_structure_problem(depth) is None and codec.image_structure_problem(colour) is None
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(depth))).astype(np.uint16), counts)
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(colour)).convert("RGB")), rgb)
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(mask))), np.where(counts > 1600, 255, 0))
    slow = codec.encode_png(counts, params=codec.PNG_RLE)
    assert np.array_equal(cv2.imdecode(np.frombuffer(depth, np.uint8), cv2.IMREAD_UNCHANGED),
                          cv2.imdecode(np.frombuffer(slow, np.uint8), cv2.IMREAD_UNCHANGED))
    assert np.array_equal(codec.decode_color(colour, where="x.png"), rgb)
    with pytest.raises(SessionFormatError, match=r"^x\.png: could not encode float32"):
        codec.encode_png(counts.astype(np.float32), params=codec.PNG_FAST, where="x.png", error=SessionFormatError)


def test_size_bound_holds_for_the_largest_png():
    rng = np.random.default_rng(2)
    for shape, bps in (((48, 64, 3), 1), ((48, 64), 2), ((480, 640), 2)):
        img = rng.integers(0, 255 if bps == 1 else 65535, shape, dtype=np.uint8 if bps == 1 else np.uint16)
        size = len(codec.encode_png(img, params=codec.PNG_STORED))
        bound = codec.encoded_size_bound(shape[1], shape[0], channels=1 if len(shape) == 2 else 3, bytes_per_sample=bps)
        assert size <= bound < size + 2048
        assert len(codec.encode_png(img, params=codec.PNG_FAST)) <= bound   # noise: ISA-L falls back to stored blocks


def test_unreadable_frame_files_are_one_line_errors(tmp_path):
    folder = tmp_path / "a.png"
    folder.mkdir()                      # a folder where a file is expected: unreadable, even for root
    fifo = tmp_path / "f.png"
    os.mkfifo(fifo)                     # opening a FIFO would block: it must be refused without opening
    link = tmp_path / "l.png"
    link.symlink_to(tmp_path / "nowhere.png")
    (tmp_path / "ok.png").write_bytes(b"x")
    for path, problem in ((folder, "not a regular file"), (fifo, "not a regular file"), (link, "missing")):
        with pytest.raises(SessionFormatError, match=f"{path.name}: frame file is {problem}$"):
            codec.read_frame_bytes(path, sha256=None, table="t.csv", error=SessionFormatError)
    with pytest.raises(SessionFormatError, match=r"a\.png: frame file listed in t\.csv is not a regular file$"):
        codec.check_frame_files([tmp_path / "ok.png", folder], table="t.csv", error=SessionFormatError)


def test_check_frame_files_reads_nothing_and_counts(tmp_path):
    paths = [tmp_path / f"{i}.png" for i in range(3)]
    for p in paths:
        p.write_bytes(b"not even a PNG")      # content is not looked at: only presence and readability
    assert codec.check_frame_files(paths, table="t.csv") == 3
