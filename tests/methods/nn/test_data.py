"""Training samples: sequences, crops and flips keep depth, colour, masks and frames registered."""
import numpy as np
import pytest
import torch

from align.dataset import AlignedDataset
from methods.errors import TrainingError
from methods.nn.data import AlignedSamples
from tests.methods.nn.helpers import coded_dataset


@pytest.fixture(scope="module")
def coded(tmp_path_factory):
    root = tmp_path_factory.mktemp("coded")
    return [AlignedDataset(coded_dataset(root / n, name=n, frames=5)) for n in ("a", "b")]


def _decode(sample, t):
    """Pixel coordinates and frame of every pixel of frame ``t``, read back from the colour layer."""
    c = (sample["color"][t] * 255).round().numpy().astype(int)
    return c[0], c[1], c[2]      # x, y, frame


def test_sequences_crops_flips_stay_registered(coded):
    ds = AlignedSamples(coded, sequence_length=3, crop=16, flip=True, seed=5)
    flips = set()
    for epoch in range(2):
        ds.set_epoch(epoch)
        for k in range(len(ds)):
            s = ds[k]
            assert s["lq_depth"].shape == (3, 1, 16, 16) and s["color"].shape == (3, 3, 16, 16)
            d, start = s["index"].tolist()
            for t in range(3):
                x, y, f = _decode(s, t)
                assert (f == start + t).all()                      # consecutive frames, in order
                expected = 1.0 + 0.001 * x + 0.01 * y + 0.1 * f    # the depth at the decoded pixel
                np.testing.assert_allclose(s["lq_depth"][t, 0].numpy(), expected, atol=6e-5)
                ref = s["reference"][t, 0].numpy()
                hole = (x + y + f) % 7 == 0
                assert np.isnan(ref[hole]).all() and np.isfinite(ref[~hole]).all()
                np.testing.assert_allclose(ref[~hole], expected[~hole] + 0.5, atol=6e-5)
                np.testing.assert_array_equal(s["valid"][t, 0].numpy(), (~hole).astype(np.float32))
                np.testing.assert_array_equal(s["roi"][t, 0].numpy(), (x % 2 == 0).astype(np.float32))
            x0, y0, _ = _decode(s, 0)
            flipped = bool(x0[0, 0] > x0[0, -1])
            flips.add(flipped)
            # the crop's camera: pixel (i, j) of the sample sees the ray of the decoded source pixel
            K = coded[d].lq_intrinsics
            fx, fy, cx, cy = s["camera"].tolist()
            jj, ii = np.meshgrid(np.arange(16), np.arange(16))
            sign = -1 if flipped else 1
            np.testing.assert_allclose(sign * (x0 - K.cx) / K.fx, (jj - cx) / fx, atol=1e-5)
            np.testing.assert_allclose((y0 - K.cy) / K.fy, (ii - cy) / fy, atol=1e-5)
            assert (np.abs(np.diff(x0, axis=1)) == 1).all()        # contiguous columns, flipped or not
    assert flips == {True, False}


def test_same_seed_epoch_and_sample_same_draw_whatever_the_order(coded):
    a = AlignedSamples(coded, crop=16, flip=True, seed=1)
    b = AlignedSamples(coded, crop=16, flip=True, seed=1)
    a.set_epoch(3)
    b.set_epoch(3)
    order = list(range(len(a)))
    first = {k: a[k]["color"] for k in order}
    for k in reversed(order):
        assert torch.equal(b[k]["color"], first[k])
    b.set_epoch(4)
    assert any(not torch.equal(b[k]["color"], first[k]) for k in order)


def test_sequences_never_cross_datasets_and_whole_frames(coded):
    ds = AlignedSamples(coded, sequence_length=5)
    assert len(ds) == 2
    assert ds[1]["lq_depth"].shape == (5, 1, 40, 48)


def test_crop_larger_than_frames_and_too_long_sequences_are_errors(coded):
    with pytest.raises(TrainingError, match="smaller than the crop"):
        AlignedSamples(coded, crop=64)
    with pytest.raises(TrainingError, match="6 frames"):
        AlignedSamples(coded, sequence_length=6)


def test_roi_crops_hold_the_roi_and_stay_registered(tmp_path):
    # a 3x3 ROI that moves one pixel per frame, in a corner of the 48x40 frame: uniform 16-pixel
    # crops miss it most of the time, ROI-centred crops (roi_crop = 1) always hold it
    def roi(x, y, i):
        return (abs(x - 40 - i) <= 1) & (abs(y - 6) <= 1)
    ds = [AlignedDataset(coded_dataset(tmp_path / "r", name="r", frames=4, roi=roi))]
    centred = AlignedSamples(ds, sequence_length=2, crop=16, flip=True, seed=2, roi_crop=1.0)
    uniform = AlignedSamples(ds, sequence_length=2, crop=16, flip=True, seed=2)
    hits = {"centred": 0, "uniform": 0}
    for epoch in range(6):
        for name, samples in (("centred", centred), ("uniform", uniform)):
            samples.set_epoch(epoch)
            for k in range(len(samples)):
                s = samples[k]
                hits[name] += bool(s["roi"][0].sum() > 0)
                x, y, f = _decode(s, 1)                   # registration holds for the second frame too
                np.testing.assert_allclose(s["lq_depth"][1, 0].numpy(), 1.0 + 0.001 * x + 0.01 * y + 0.1 * f, atol=6e-5)
                np.testing.assert_array_equal(s["roi"][1, 0].numpy(), roi(x, y, f).astype(np.float32))
    n = 6 * len(centred)
    assert hits["centred"] == n and hits["uniform"] < n / 2, hits
