"""Small synthetic sessions and rig files for the session, replay and recorder tests."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from capture.camera import Intrinsics
from capture.session import SessionWriter


def stream_dict(kind: str, w: int, h: int, fps: float, encoding: str | None = None) -> dict:
    K = Intrinsics(w, h, 0.9 * w, 0.9 * w, (w - 1) / 2, (h - 1) / 2)
    d = {"type": kind, "width": w, "height": h, "fps": fps,
         "encoding": encoding or ("png" if kind == "color" else "png16"), "intrinsics": K.to_dict()}
    if kind == "depth":
        d["depth_unit_m"] = 0.001
    return d


def manifest(sensors=("lq", "hq"), *, w=64, h=48, fps=30.0, streams=("depth", "color"), name="synthetic") -> dict:
    return {"name": name, "sensors": {
        s: {"role": "lq" if s == "lq" else ("hq" if s == "hq" else "view"), "model": "synthetic", "serial": f"SER-{s}",
            "streams": {k: stream_dict(k, w, h, fps) for k in streams}} for s in sensors}}


def random_image(rng, kind: str, w: int, h: int) -> np.ndarray:
    if kind == "color":
        return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    img = rng.integers(300, 6000, (h, w), dtype=np.uint16)
    img[rng.random((h, w)) < 0.1] = 0  # holes
    return img


def write_source(path, *, n=30, sensors=("lq", "hq"), w=64, h=48, fps=30.0, streams=("depth", "color"),
                 shift_us=None, seed=0, force=False):
    """A session with ``n`` frames per stream at ``fps``; returns {(sensor, stream): [(fn, dev, host, image)]}.

    ``shift_us`` (sensor -> µs) offsets a sensor's host timestamps."""
    rng = np.random.default_rng(seed)
    frames: dict = {}
    period = 1e6 / fps
    with SessionWriter(path, manifest(sensors, w=w, h=h, fps=fps, streams=streams), force=force) as writer:
        for i in range(n):
            for s in sensors:
                for k in streams:
                    host = 5_000_000 + round(i * period) + (shift_us or {}).get(s, 0)
                    dev = 100_000 + round(i * period)
                    img = random_image(rng, k, w, h)
                    writer.add_frame(s, k, i, dev, host, img)
                    frames.setdefault((s, k), []).append((i, dev, host, img))
    return frames


def rig_toml(source, sensors: dict[str, dict], *, name="test-rig") -> str:
    """A replay rig: ``sensors`` maps sensor id -> replay options (plus optional 'serial', 'role')."""
    out = [f'name = "{name}"']
    for sid, opts in sensors.items():
        opts = dict(opts)
        serial = opts.pop("serial", sid)
        role = opts.pop("role", "lq" if sid.startswith("lq") else "hq")
        out += ["", "[[sensor]]", f'id = "{sid}"', f'role = "{role}"', 'driver = "replay"', f'serial = "{serial}"',
                "[sensor.options]", f'session = "{Path(source).as_posix()}"']
        for k, v in opts.items():
            out.append(f"{k} = {json.dumps(v)}")
    return "\n".join(out) + "\n"


def tree_digest(root) -> dict[str, str]:
    """{relative path: sha256} of every file under ``root`` (to show nothing was touched)."""
    root = Path(root)
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}
