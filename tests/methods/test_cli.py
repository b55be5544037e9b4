"""``depthbench methods list`` and ``depthbench methods run`` as a user runs them."""
import json

import numpy as np
import pytest

from align.dataset import AlignedDatasetWriter
from capture.camera import Intrinsics, Transform
from methods import get
from methods.output import DenoisedOutput
from methods.tools.synthetic import synthetic_scene
from tests.conftest import CliResult, assert_one_line_error

H, W = 36, 48


def make_dataset(root, *, color=True, n=3):
    K = Intrinsics(W, H, fx=40.0, fy=40.0, cx=23.5, cy=17.5)
    meta = {"name": "tiny", "lq_intrinsics": K.to_dict(), "time_shift_us": 0,
            "T_lq_hq": Transform.identity().to_list() if hasattr(Transform, "to_list") else np.eye(4).tolist()}
    frames = []
    with AlignedDatasetWriter(root, meta, depth_unit_m=0.001) as w:
        for i in range(n):
            truth, noisy = synthetic_scene((H, W), seed=i)
            rgb = np.full((H, W, 3), 80, np.uint8) if color else None
            w.add_frame(noisy, truth, lq_color=rgb, truth=truth, lq_frame=i, hq_frame=i, lq_timestamp_us=i * 33333)
            frames.append(noisy)
    return frames


@pytest.fixture
def main(capsys):
    """``depthbench ARGS...`` in this process (the CLI start-up costs seconds; a few tests use ``cli``)."""
    from depthbench.cli import main as depthbench_main

    def run(*args):
        try:
            rc = depthbench_main([str(a) for a in args])
        except SystemExit as exc:
            rc = exc.code
        out, err = capsys.readouterr()
        return CliResult(rc, out, err)

    return run


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("aligned") / "A"
    frames = make_dataset(root)
    return root, frames


def test_list_shows_every_method_with_parameters(cli, main):
    r = cli("methods", "list")
    assert r.returncode == 0, r.stderr
    for name in ("raw", "gaussian", "bilateral", "joint_bilateral", "rolling_guidance"):
        assert f"{name}  (version" in r.stdout
    assert "sigma_color    = " in r.stdout and "metres" in r.stdout and "iterations" in r.stdout
    r = main("methods", "list", "--json")
    listed = {m["name"]: m for m in json.loads(r.stdout)}
    rgf = {p["name"]: p["default"] for p in listed["rolling_guidance"]["params"]}
    assert rgf["iterations"] == get("rolling_guidance").params["iterations"]
    assert listed["joint_bilateral"]["uses_color"] is True
    # methods that cannot be built without weights still say what they need
    assert listed["ddrnet_refine"]["needs"] == "weights file (weights=PATH), colour, a GPU when present"
    assert listed["ssdd_lstm"]["needs"].startswith("weights file (weights=PATH), sequence (")
    assert listed["raw"]["needs"] == "depth only"


def test_run_writes_depth_in_the_dataset_unit_and_json(cli, dataset, tmp_path):
    root, frames = dataset
    out = tmp_path / "D"
    r = cli("methods", "run", "bilateral", "--data", root, "--out", out, "--param", "sigma_color=0.05",
            "--param", "depth_adaptive=true")
    assert r.returncode == 0, r.stderr
    meta = json.loads((out / "denoised.json").read_text())
    assert meta["method"] == "bilateral" and meta["params"]["sigma_color"] == 0.05 and meta["params"]["depth_adaptive"]
    from align.dataset import AlignedDataset
    ds = AlignedDataset(root)
    assert meta["dataset"]["checksum"] == ds.checksum and meta["depth_unit_m"] == ds.depth_unit_m
    res = DenoisedOutput(out)
    assert len(res) == 3 and res.key == get("bilateral", sigma_color=0.05, depth_adaptive=True).key
    import cv2
    png = cv2.imread(str(out / "depth" / "000001.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.shape == (H, W)
    expect = get("bilateral", sigma_color=0.05, depth_adaptive=True).denoise(ds.lq_depth(1))
    got = res.depth(1)
    assert np.array_equal(np.isnan(got), np.isnan(expect)) and np.array_equal(png == 0, np.isnan(expect))
    np.testing.assert_allclose(got, expect, atol=0.0005 + 1e-6, equal_nan=True)   # 1 mm counts, rounded


def test_run_raw_is_the_input_and_output_is_not_overwritten(cli, main, dataset, tmp_path):
    root, _ = dataset
    out = tmp_path / "R"
    assert main("methods", "run", "raw", "--data", root, "--out", out).returncode == 0
    from align.dataset import AlignedDataset
    ds = AlignedDataset(root)
    np.testing.assert_array_equal(DenoisedOutput(out).depth(2), ds.lq_depth(2))
    before = (out / "denoised.json").read_text()
    assert_one_line_error(cli("methods", "run", "raw", "--data", root, "--out", out), "exists", "--force")
    assert (out / "denoised.json").read_text() == before
    r = main("methods", "run", "rolling_guidance", "--data", root, "--out", out, "--force")
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "denoised.json").read_text())["method"] == "rolling_guidance"


@pytest.mark.parametrize("args, fragments", [
    (("nosuch",), ("unknown method", "bilateral")),
    (("bilateral", "--param", "sigma_color=-0.1"), ("sigma_color must be a positive",)),
    (("bilateral", "--param", "sigma_spatial=-2"), ("sigma_spatial must be a positive",)),
    (("bilateral", "--param", "sigma=2"), ("unknown parameter 'sigma'",)),
    (("bilateral", "--param", "sigma_color"), ("expected NAME=VALUE",)),
    (("rolling_guidance", "--param", "iterations=0"), ("iterations",)),
])
def test_bad_input_is_one_line(main, dataset, tmp_path, args, fragments):
    root, _ = dataset
    out = tmp_path / "X"
    assert_one_line_error(main("methods", "run", args[0], "--data", root, "--out", out, *args[1:]), *fragments)
    assert not out.exists()


def test_missing_dataset_and_missing_colour(main, tmp_path):
    assert_one_line_error(main("methods", "run", "raw", "--data", tmp_path / "none", "--out", tmp_path / "o"),
                          "aligned.json")
    root = tmp_path / "nocolor"
    make_dataset(root, color=False, n=1)
    assert_one_line_error(main("methods", "run", "joint_bilateral", "--data", root, "--out", tmp_path / "o"),
                          "needs the LQ colour")
    assert not (tmp_path / "o").exists()


def test_help_is_useful(main):
    r = main("methods", "run", "--help")
    assert r.returncode == 0 and "--param" in r.stdout and "--force" in r.stdout and "uint16" in r.stdout


def test_seed_report_aliases_name_the_same_methods():
    from methods.registry import get

    assert get("bf").name == "bilateral" and get("jbf").name == "joint_bilateral" and get("rgf").name == "rolling_guidance"
    assert get("rgf", iterations=3).params["iterations"] == 3
