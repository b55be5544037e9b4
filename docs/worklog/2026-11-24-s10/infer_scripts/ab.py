"""A/B of the inference path, alternating old/new per round in one process (shared machine).

    PYTHONPATH=$PWD python ab.py [rounds] [frames]
Old = torch.cat in Up / ConvLSTM (patched back in); new = methods.nn.layers.cat_channels.
Times ssdd_unet.denoise and ssdd_lstm.denoise_step (width 8, 4 levels, bilateral prefilter,
fold_mean) on the perf script's synthetic 640x480 frame, plus bf; checks outputs agree."""
import sys, tempfile, time
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
import methods.nn.layers as L, methods.nn.convlstm as C
from methods import get
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene
torch.set_num_threads(2)
rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 4
nfr = int(sys.argv[2]) if len(sys.argv) > 2 else 5
new_cat = L.cat_channels
old_cat = lambda ts: torch.cat(ts, dim=1)
def use(f):
    L.cat_channels = f; C.cat_channels = f
_, depth = synthetic_scene((480, 640), seed=1)
frames = [FrameInput(0, depth), FrameInput(1, np.roll(depth, 3, axis=1))]
bf = get("bf")
res = {}
def _time(fn, n):
    fn(); out = []
    for _ in range(n):
        t0 = time.process_time(); fn(); out.append((time.process_time() - t0) * 1000)
    return out
P._time = _time   # CPU ms of this process (both threads), steadier than wall time on the shared machine
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), 8, 4, "bilateral", True)
    unet = get("ssdd_unet", weights=str(path)); lstm = get("ssdd_lstm", weights=str(path))
    # equality: 3 frames of lstm and unet, old vs new
    outs = {}
    for name, f in (("old", old_cat), ("new", new_cat)):
        use(f); s = None; o = []
        for i in range(3):
            y, s = lstm.denoise_step(frames[i % 2], s); o.append(y)
        o.append(unet.denoise(depth)); outs[name] = o
    d = max(float(np.nanmax(np.abs(a - b))) for a, b in zip(outs["old"], outs["new"]))
    print("max |old - new| m:", d, "nan masks equal:", all((np.isnan(a) == np.isnan(b)).all() for a, b in zip(outs["old"], outs["new"])))
    st = {"s": None, "n": 0}
    def step():
        st["n"] += 1; _, st["s"] = lstm.denoise_step(frames[st["n"] % 2], st["s"])
    for r in range(rounds):
        for name, f in (("old", old_cat), ("new", new_cat)) if r % 2 == 0 else (("new", new_cat), ("old", old_cat)):
            use(f)
            res.setdefault("bf", []).extend(P._time(lambda: bf.denoise(depth), nfr))
            res.setdefault(("unet", name), []).extend(P._time(lambda: unet.denoise(depth), nfr))
            res.setdefault(("lstm", name), []).extend(P._time(step, nfr))
ref = np.median(res["bf"])
print(f"bf median {ref:.1f} ms over {len(res['bf'])} frames")
for k, v in res.items():
    if k != "bf":
        print(f"{k[0]:>5} {k[1]:>4} median {np.median(v):7.1f} CPU ms  min {min(v):7.1f}  x bf {np.median(v)/ref:5.2f}")
