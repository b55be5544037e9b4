"""The leaderboard: statistics against loops, column order, rebuild from the table, headless Chromium."""
from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench import results as R
from bench.report import write_report
from bench.summary import bootstrap_summary, method_labels
from bench.runner import run_benchmark
from tests.bench.conftest import SMALL_CONFIG
from tests.bench.helpers import Shift, Smooth

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"


@pytest.fixture(scope="module")
def results(datasets, tmp_path_factory):
    root, a, b = datasets
    out = tmp_path_factory.mktemp("report") / "results"
    res = run_benchmark([a, b], ["raw", Shift(), Smooth()], out, config=SMALL_CONFIG, jobs=1)
    return out, res


def test_bootstrap_matches_a_loop_over_resamples():
    rng = np.random.default_rng(5)
    wide = pd.DataFrame(rng.normal(10, 2, size=(30, 3)), columns=["a", "b", "c"])
    wide.iloc[[2, 7], 1] = np.nan
    got = bootstrap_summary(wide, n_boot=500, seed=3)
    counts = np.random.default_rng(3).multinomial(30, np.full(30, 1 / 30), size=500)
    F = wide.to_numpy()
    for j, col in enumerate(wide.columns):
        means = []
        for c in counts:
            idx = np.repeat(np.arange(30), c)
            means.append(np.nanmean(F[idx, j]))
        assert got.loc[col, "mean"] == pytest.approx(np.nanmean(F[:, j]), rel=1e-12)
        assert got.loc[col, "lo"] == pytest.approx(np.quantile(means, 0.025), rel=1e-12)
        assert got.loc[col, "hi"] == pytest.approx(np.quantile(means, 0.975), rel=1e-12)
        assert got.loc[col, "n_frames"] == np.isfinite(F[:, j]).sum()
    # the interval is the usual one for a mean: about +-1.96 sigma / sqrt(n)
    big = pd.DataFrame({"x": np.random.default_rng(1).normal(0, 1, 400)})
    s = bootstrap_summary(big)
    assert (s.loc["x", "hi"] - s.loc["x", "lo"]) / 2 == pytest.approx(1.96 / 20, rel=0.15)
    const = bootstrap_summary(pd.DataFrame({"k": np.full(5, 3.0)}))
    assert const.loc["k", ["mean", "lo", "hi"]].tolist() == [3.0, 3.0, 3.0]


def test_columns_follow_table_i_order():
    names = ["test_smooth", "rolling_guidance", "ssdd_lstm", "raw", "bilateral", "ddd", "joint_bilateral",
             "ssdd_unet", "ddrnet", "gaussian"]
    df = pd.DataFrame({"method": names, "method_key": [f"{n}@1()" for n in names], "method_version": "1"})
    assert list(method_labels(df).values()) == ["Raw", "BF", "JBF", "RGF", "DDRNet", "DDD", "SSDD UNet",
                                                "SSDD LSTM", "gaussian", "test_smooth"]


def test_report_shows_summary_published_numbers_and_figures(results):
    out, res = results
    md = (out / "leaderboard.md").read_text()
    assert "## Summary against the HQ reference" in md and "## Summary against the simulator's truth" in md
    assert "| metric | Raw | test_shift | test_smooth |" in md
    assert "| metric | Raw | test_shift | test_smooth | HQ sensor |" in md
    assert "Published (seed report Table I), other data: not comparable" in md
    assert "57.22" in md and "SSDD [5]" in md and "DDD [4]" in md
    assert "### seq-a (A; 3 frames)" in md and "### seq-b (B; 3 frames)" in md
    for name in ("summary_hq.png", "summary_truth.png", "error_vs_depth_hq.png", "error_vs_depth_truth.png"):
        assert (out / "figures" / name).stat().st_size > 5000
        assert f"figures/{name}" in md
    assert len(list((out / "figures").glob("qualitative_*.png"))) == 2
    page = (out / "leaderboard.html").read_text()
    assert page.count("data:image/png;base64,") == 6
    assert "src=\"http" not in page and "<script" not in page          # self-contained, static


def test_report_rebuilds_from_the_table_alone(results, tmp_path, cli):
    out, res = results
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    before = (copy / "leaderboard.md").read_text()
    shutil.rmtree(copy / R.CACHE)
    for f in ("leaderboard.md", "leaderboard.html"):
        (copy / f).unlink()
    shutil.rmtree(copy / "figures")
    r = cli("bench", "report", copy)
    assert r.returncode == 0, r.stderr
    assert (copy / "leaderboard.md").read_text() == before                 # deterministic, nothing recomputed
    # without previews the table still gives every number; only the depth pictures are missing
    shutil.rmtree(copy / R.PREVIEWS)
    (copy / R.MANIFEST).unlink()
    paths = write_report(copy)
    text = paths.markdown.read_text()
    assert "No depth previews in this results folder" in text
    assert text.split("## Error against depth")[0].replace("metric parameters: see results.json", "") == \
        before.split("## Error against depth")[0].replace(
            "plane-fit radius 40 mm, at least 3 neighbours, depth bins of 0.25 m", "")


def test_html_report_opens_in_headless_chromium(results, artifacts, tmp_path):
    if not Path(CHROMIUM).exists():
        pytest.skip(f"Chromium not found at {CHROMIUM} (Debian package 'chromium'; 'make sysdeps' installs it)")
    out, res = results
    page = (out / "leaderboard.html").resolve()
    shot = artifacts / "bench_leaderboard.png"
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--enable-logging=stderr", "--v=0", "--window-size=1300,2600"]
    with tempfile.TemporaryDirectory() as profile:
        dom = subprocess.run([CHROMIUM, *flags, f"--user-data-dir={profile}", "--dump-dom", page.as_uri()],
                             capture_output=True, text=True, timeout=120)
    with tempfile.TemporaryDirectory() as profile:
        snap = subprocess.run([CHROMIUM, *flags, f"--user-data-dir={profile}", f"--screenshot={shot}", page.as_uri()],
                              capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0 and snap.returncode == 0, dom.stderr[-2000:] + snap.stderr[-2000:]
    for log in (dom.stderr, snap.stderr):      # page-level problems (console errors, failed loads), not dbus noise
        bad = [line for line in log.splitlines() if "CONSOLE" in line or "Uncaught" in line
               or "net::ERR" in line or "Failed to load resource" in line]
        assert not bad, bad
    html = dom.stdout
    assert "depthbench leaderboard" in html and "Summary against the HQ reference" in html
    assert html.count("<img") == 6 and "test_smooth" in html and "HQ sensor" in html
    import cv2
    img = cv2.imread(str(shot))
    assert img is not None and img.shape[1] == 1300 and img.std() > 20     # a rendered page, not a blank one
