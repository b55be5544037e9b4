"""align.external.import_ddrnet on a hand-made folder in DDRNet's layout (the real one is in test_cli)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from align.dataset import AlignedDataset
from align.external import DDRNET_INTRINSICS, ExternalDatasetError, import_ddrnet
from depthbench.errors import OutputExistsError


def fake_group(root, frames=(1, 2, 3), color=(2,), shape=(480, 640)):
    rng = np.random.default_rng(0)
    for d in ("depth_map", "high_quality_depth", "mask", "color_map"):
        (root / d).mkdir(parents=True)
    for n in frames:
        raw = rng.integers(1200, 2000, shape).astype(np.uint16)
        raw[:10] = 0
        cv2.imwrite(str(root / "depth_map" / f"frame_{n:06d}.png"), raw)
        cv2.imwrite(str(root / "high_quality_depth" / f"frame_{n:06d}.png"), (raw // 2 + 600).astype(np.uint16))
        m = np.zeros(shape, np.uint8)
        m[100:300, 200:400] = 255
        cv2.imwrite(str(root / "mask" / f"frame_{n:06d}.png"), m)
        if n in color:
            bgr = np.zeros(shape + (3,), np.uint8)
            bgr[..., 0] = 255                      # blue in OpenCV's BGR order
            cv2.imwrite(str(root / "color_map" / f"frame_{n:06d}.png"), bgr)
    return root


def test_group_becomes_an_aligned_dataset(tmp_path):
    src = fake_group(tmp_path / "g1")
    (out,) = import_ddrnet(src, tmp_path / "A")
    ds = AlignedDataset(out)
    assert len(ds) == 3 and ds.sequence == "g1" and ds.lq_intrinsics == DDRNET_INTRINSICS
    assert ds.depth_unit_m == 1e-3 and not ds.simulated
    f = ds.frame(1)
    raw = cv2.imread(str(src / "depth_map" / "frame_000002.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_allclose(f.lq_depth[raw > 0], raw[raw > 0] / 1000.0, rtol=1e-6)
    assert np.isnan(f.lq_depth[:10]).all()
    assert f.roi.sum() == 200 * 200 and f.lq_color is not None and tuple(f.lq_color[0, 0]) == (0, 0, 255)
    assert ds.frame(0).lq_color is None and [r["lq_frame"] for r in ds.rows] == ["1", "2", "3"]


def test_folder_of_groups_and_force(tmp_path):
    fake_group(tmp_path / "src" / "a")
    fake_group(tmp_path / "src" / "b", frames=(5,))
    outs = import_ddrnet(tmp_path / "src", tmp_path / "A")
    assert [p.name for p in outs] == ["a", "b"] and len(AlignedDataset(outs[1])) == 1
    with pytest.raises(OutputExistsError):
        import_ddrnet(tmp_path / "src", tmp_path / "A")
    assert len(import_ddrnet(tmp_path / "src", tmp_path / "A", force=True)) == 2


def test_bad_layouts_are_one_line_errors(tmp_path):
    src = fake_group(tmp_path / "g")
    (src / "high_quality_depth" / "frame_000002.png").unlink()
    with pytest.raises(ExternalDatasetError, match="high_quality_depth: no frame_000002.png"):
        import_ddrnet(src, tmp_path / "A")
    assert not (tmp_path / "A").exists()
    src2 = fake_group(tmp_path / "small", shape=(240, 320))
    with pytest.raises(ExternalDatasetError, match="320x240, expected 640x480"):
        import_ddrnet(src2, tmp_path / "B")
    src3 = fake_group(tmp_path / "eight")
    cv2.imwrite(str(src3 / "depth_map" / "frame_000001.png"), np.zeros((480, 640), np.uint8))
    with pytest.raises(ExternalDatasetError, match="16-bit"):
        import_ddrnet(src3, tmp_path / "C")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ExternalDatasetError, match="neither a DDRNet group"):
        import_ddrnet(tmp_path / "empty", tmp_path / "D")
