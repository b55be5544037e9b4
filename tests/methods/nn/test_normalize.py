"""The networks' depth codes: the range coding and the centred coding (frame median, depth_scale_m)."""
import numpy as np
import torch

from methods.nn.normalize import decode_depth, encode_depth, frame_centre

RANGE = {"d_min": 0.2, "d_max": 6.0}


def _frames():
    g = torch.Generator().manual_seed(3)
    d = 1.0 + 3.0 * torch.rand(2, 3, 1, 8, 9, generator=g)
    d[torch.rand(d.shape, generator=g) < 0.2] = float("nan")
    d[1, 2] = float("nan")                                   # one frame without any depth
    return d


def test_centre_is_each_frames_median_of_valid_depth():
    d = _frames()
    c = frame_centre(d)
    assert c.shape == (2, 3, 1, 1, 1)
    for b in range(2):
        for t in range(3):
            v = d[b, t].numpy()
            expected = 1.0 if np.isnan(v).all() else np.sort(v[np.isfinite(v)])[(np.isfinite(v).sum() - 1) // 2]
            assert c[b, t].item() == np.float32(expected)      # torch's median: the lower middle value


def test_centred_code_is_offset_free_scaled_and_inverts():
    d = _frames()
    x, valid, centre = encode_depth(d, scale_m=0.1, **RANGE)
    x2, _, centre2 = encode_depth(d + 0.75, scale_m=0.1, **RANGE)
    torch.testing.assert_close(x2, x, atol=2e-5, rtol=0)      # a scene moved 75 cm away codes the same
    full = torch.tensor([[True, True, True], [True, True, False]])
    torch.testing.assert_close(centre2[full], centre[full] + 0.75)
    assert centre2[1, 2].item() == centre[1, 2].item() == 1.0  # the empty frame: 1 m, nothing to code
    ok = torch.isfinite(d)
    torch.testing.assert_close(x[ok], ((d - centre) / 0.1)[ok])  # 1 cm = 0.1 units
    assert (x[~ok] == 0).all() and torch.equal(valid, ok.float())
    back = decode_depth(x, centre=centre, scale_m=0.1, **RANGE)
    torch.testing.assert_close(back[ok], d[ok])


def test_range_code_is_the_clipped_range():
    d = _frames()
    x, valid, centre = encode_depth(d, **RANGE)
    assert centre is None
    ok = torch.isfinite(d)
    torch.testing.assert_close(x[ok], (d[ok] - 0.2) / 5.8)
    torch.testing.assert_close(decode_depth(x, **RANGE)[ok], d[ok])
