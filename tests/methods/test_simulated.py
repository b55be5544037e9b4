"""On simulated lq-hq data every edge-aware filter, with its swept defaults, lowers the error against the truth.

(The range-blind Gaussian does not: it blurs depth edges; methods/defaults_sweep.md has its numbers.)

The full numbers (full resolution, held-out seed) are in methods/defaults_sweep.md, written by
``python -m methods.tools.sweep_defaults``; this test checks the property on a small simulation.
"""
import numpy as np
import pytest

from methods import get


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    from capture.session import open_session
    from capture.sim.simulator import simulate
    from capture.truth import read_truth

    root = tmp_path_factory.mktemp("sim") / "S"
    simulate(root, rig="lq-hq", scene="people", seconds=1.0, seed=13, lq_fps=2.0, hq_fps=2.0, progress=False)
    session, truth = open_session(root), read_truth(root)
    return [(session.read_depth("lq", int(fn)), session.read_color("lq", int(fn)), truth.depth("lq", int(fn)))
            for fn in session.frames("lq", "depth")["frame_number"]]


def rmse_mm(outputs, frames):
    se, n = 0.0, 0
    for out, (d, _, z) in zip(outputs, frames):
        m = np.isfinite(d) & np.isfinite(z) & (z >= 1.0) & (z <= 3.0)
        assert np.isfinite(out[m]).all()
        e = (out[m] - z[m]).astype(np.float64)
        se, n = se + float(e @ e), n + int(m.sum())
    return 1e3 * np.sqrt(se / n)


@pytest.mark.parametrize("name", ["bilateral", "joint_bilateral", "rolling_guidance"])
def test_each_filter_lowers_the_error(frames, name):
    method = get(name)
    raw = rmse_mm([d for d, _, _ in frames], frames)
    out = rmse_mm([method.denoise(d, c if method.uses_color else None) for d, c, _ in frames], frames)
    print(f"{name}: RMSE {out:.2f} mm vs raw {raw:.2f} mm ({100 * (out / raw - 1):+.1f} %)")
    assert out < 0.97 * raw
