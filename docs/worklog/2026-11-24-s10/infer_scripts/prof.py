"""cProfile + torch.profiler of ssdd_lstm denoise_step (width 8, bilateral, fold-mean) and ssdd_unet."""
import sys, tempfile, cProfile, pstats, time
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods import get
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene
torch.set_num_threads(2)
_, depth = synthetic_scene((480, 640), seed=1)
frames = [FrameInput(0, depth), FrameInput(1, np.roll(depth, 3, axis=1))]
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), 8, 4, "bilateral", True)
    lstm = get("ssdd_lstm", weights=str(path))
    st = {"s": lstm.start_sequence(), "n": 0}
    def step():
        st["n"] += 1
        _, st["s"] = lstm.denoise_step(frames[st["n"] % 2], st["s"])
    step(); step()
    pr = cProfile.Profile(); pr.enable()
    for _ in range(5): step()
    pr.disable()
    pstats.Stats(pr).sort_stats("cumtime").print_stats(35)
    pstats.Stats(pr).sort_stats("tottime").print_stats(25)
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
        for _ in range(3): step()
    print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=30))
