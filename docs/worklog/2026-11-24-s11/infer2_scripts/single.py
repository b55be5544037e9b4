"""Level-1 net (w, levels, bilateral base) on one 640x480 frame, 2 threads: eager channels_last vs fused oneDNN
(fused.py) vs torch.compile (inductor, compile time printed). Alternating calls; run under chrt -f 1."""
import sys, time, torch, numpy as np
sys.path.insert(0, __import__("os").path.dirname(__import__("os").path.abspath(__file__)))
import fused as FU
from methods.ssdd.networks import NetConfig, SSDDUNet
torch.set_num_threads(2)
width, levels, rounds, modes = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4].split(",")
torch.manual_seed(0)
net = SSDDUNet(NetConfig(width=width, levels=levels, norm="none"), base=True).eval().to(memory_format=torch.channels_last)
x = torch.randn(1, 1, 480, 640); v = (torch.rand(1, 1, 480, 640) > 0.1).float(); b = x + 0.01 * torch.randn_like(x)
fns = {"eager": net}
if "fused" in modes:
    fns["fused"] = FU.fused_copy(net)
with torch.inference_mode():
    ref = net(x, v, None, None, b)
    if "compile" in modes:
        t0 = time.perf_counter(); c = torch.compile(net); c(x, v, None, None, b); print(f"compile + first call {time.perf_counter() - t0:.1f} s")
        fns["compile"] = c
    for k, f in fns.items():
        print(k, "max|diff|", (f(x, v, None, None, b) - ref).abs().max().item())
    ts = {k: [] for k in fns}
    for r in range(rounds):
        for k, f in fns.items():
            t0 = time.perf_counter(); f(x, v, None, None, b); ts[k].append((time.perf_counter() - t0) * 1000)
for k in fns:
    print(f"w{width}/{levels} {k:>8} med {np.median(ts[k]):7.1f} min {min(ts[k]):7.1f}  eager/this med {np.median(ts['eager'])/np.median(ts[k]):.2f} min {min(ts['eager'])/min(ts[k]):.2f}")
