"""A session written from data_manifests/session.md alone (no depthbench writer) is accepted."""
from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from capture.session import open_session

DOC = Path(__file__).resolve().parents[2] / "data_manifests" / "session.md"


def example_manifest() -> dict:
    """The ```json block of session.md's "complete minimal example"."""
    text = DOC.read_text()
    example = text[text.index("## A complete minimal example"):]
    return json.loads(re.search(r"```json\n(.*?)```", example, re.S).group(1))


def write_by_hand(root: Path, *, colour_with_pil: bool = True) -> dict:
    """Follow session.md with OpenCV/PIL only; returns what was written."""
    manifest = example_manifest()
    (root / "lq" / "depth").mkdir(parents=True)
    (root / "lq" / "color").mkdir(parents=True)
    rows = ["stream,frame_number,device_timestamp_us,host_timestamp_us,file,sha256"]
    written = {}
    rng = np.random.default_rng(7)
    for n, (dev, host) in enumerate([(1000000, 5000000), (1033333, 5033400)]):
        depth_m = rng.uniform(0.5, 4.0, (48, 64)).astype(np.float32)
        depth_m[:5, :5] = np.nan
        counts = np.nan_to_num(np.round(depth_m / 0.001)).astype(np.uint16)
        rgb = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
        cv2.imwrite(str(root / f"lq/depth/{n:08d}.png"), counts)
        if colour_with_pil:
            Image.fromarray(rgb, "RGB").save(root / f"lq/color/{n:08d}.png")
        else:
            cv2.imwrite(str(root / f"lq/color/{n:08d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        for stream, offset in (("depth", 0), ("color", 200)):
            rel = f"lq/{stream}/{n:08d}.png"
            sha = hashlib.sha256((root / rel).read_bytes()).hexdigest()
            rows.append(f"{stream},{n},{dev},{host + offset},{rel},{sha}")
        written[n] = (counts, rgb, dev, host)
    (root / "lq" / "frames.csv").write_text("\n".join(rows) + "\n")
    (root / "session.json").write_text(json.dumps(manifest, indent=2))
    return written


def test_documented_example_is_accepted(tmp_path, cli):
    root = tmp_path / "minimal"
    written = write_by_hand(root)
    result = cli("capture", "validate", root)
    assert result.returncode == 0, result.stderr
    assert "valid session 'minimal'" in result.stdout
    s = open_session(root, verify="full")
    assert s.time_base == "host" and s.sensors["lq"].role == "lq"
    assert s.intrinsics("lq", "color").coeffs == (0.01, -0.002, 0.0, 0.0, 0.0)
    for n, (counts, rgb, dev, host) in written.items():
        assert np.array_equal(s.read_image("lq", "depth", n), counts)
        assert np.array_equal(s.read_color("lq", n), rgb)  # PIL wrote RGB; the reader returns RGB
        d = s.read_depth("lq", n)
        assert np.isnan(d[:5, :5]).all() and np.allclose(d[5:, 5:], counts[5:, 5:] * 0.001, atol=1e-6)
    assert s.timestamps_us("lq", "depth").tolist() == [5000000, 5033400]
    assert s.timestamps_us("lq", "color").tolist() == [5000200, 5033600]
    info = cli("capture", "info", root)
    assert info.returncode == 0 and "lq" in info.stdout


def test_documented_python_snippet_runs(tmp_path, cli):
    """The Python snippet in session.md, run as written (with the JSON example beside it)."""
    text = DOC.read_text()
    snippet = re.search(r"```python\n(.*?)```", text[text.index("## A complete minimal example"):], re.S).group(1)
    (tmp_path / "session.json.example").write_text(json.dumps(example_manifest()))
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-c", snippet], cwd=tmp_path, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    result = cli("capture", "validate", tmp_path / "minimal")
    assert result.returncode == 0, result.stderr
