"""Trained tiny SSDD (RUN) on a held-out aligned dataset (DATA): level 1 compiled (DEPTHBENCH_COMPILE=1) vs plain (lanes off), 2 threads.
Max |difference| of the outputs (metres and depth-code units), and ms per frame of each, alternating per batch/step."""
import os, sys, time, numpy as np, torch
from align.dataset import AlignedDataset
from methods.base import FrameInput
from methods.registry import get
from methods.nn.lanes import ENV
torch.set_num_threads(2)
run, data, nframes = sys.argv[1], sys.argv[2], int(sys.argv[3])
ds = AlignedDataset(data)
frames = [FrameInput(i, ds.lq_depth(i)) for i in range(min(nframes, len(ds)))]
print("frames", len(frames), frames[0].depth.shape)
m = {}
for mode in ("0", "c"):
    os.environ[ENV] = "0"; os.environ["DEPTHBENCH_COMPILE"] = "1" if mode == "c" else "0"
    u, l = get("ssdd_unet", weights=f"{run}/ssdd_unet.safetensors", allow_train_frames=True), get("ssdd_lstm", weights=f"{run}/ssdd_lstm.safetensors", allow_train_frames=True)
    u.ensure_prepared(); l.ensure_prepared(); m[mode] = (u, l)
    print(mode, "lanes", u.runtime["lanes"].lanes, l.runtime["lanes"].lanes)
outs = {k: ([], []) for k in m}; ts = {k: ([], []) for k in m}
states = {k: m[k][1].start_sequence() for k in m}
for b in range(0, len(frames), 4):
    for k, (u, l) in m.items():
        t0 = time.perf_counter(); outs[k][0].extend(u.denoise_batch(frames[b:b + 4])); ts[k][0].append((time.perf_counter() - t0) * 1000 / len(frames[b:b + 4]))
    for f in frames[b:b + 4]:
        for k, (u, l) in m.items():
            t0 = time.perf_counter(); y, states[k] = l.denoise_step(f, states[k]); outs[k][1].append(y); ts[k][1].append((time.perf_counter() - t0) * 1000)
for i, name in enumerate(("ssdd_unet", "ssdd_lstm")):
    d = max(float(np.nanmax(np.abs(a - b))) for a, b in zip(outs["0"][i], outs["c"][i]))
    same_nan = all(np.array_equal(np.isnan(a), np.isnan(b)) for a, b in zip(outs["0"][i], outs["c"][i]))
    off, on = np.array(ts["0"][i][1:]), np.array(ts["c"][i][1:])
    print(f"{name}: max|diff| {d:.3g} m = {d / 0.1:.3g} code units, same NaN {same_nan}; ms/frame off med {np.median(off):.1f} min {off.min():.1f}, on med {np.median(on):.1f} min {on.min():.1f}; x off med {np.median(off)/np.median(on):.2f} min {off.min()/on.min():.2f}")
