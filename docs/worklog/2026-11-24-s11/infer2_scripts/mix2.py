"""Level-1 net w16/4 alone, 2 threads, with MODE: none (torch only), import (methods.bilateral imported), run (and
one prefilter run before timing). Run under chrt -f 1."""
import sys, time, torch, numpy as np
from methods.ssdd.networks import NetConfig, SSDDUNet
mode, rounds = sys.argv[1], int(sys.argv[2])
torch.set_num_threads(2)
if mode in ("import", "run"):
    from methods.bilateral import bilateral_filter
if mode == "run":
    bilateral_filter(np.ones((480, 640), np.float32), sigma_spatial=3.0, sigma_color=0.05)
torch.manual_seed(0)
net = SSDDUNet(NetConfig(width=16, levels=4, norm="none"), base=True).eval().to(memory_format=torch.channels_last)
x = torch.randn(1, 1, 480, 640); v = (torch.rand(1, 1, 480, 640) > 0.1).float(); b = x + 0.01 * torch.randn_like(x)
a = []
with torch.inference_mode():
    net(x, v, None, None, b)
    for r in range(rounds):
        t0 = time.perf_counter(); net(x, v, None, None, b); a.append((time.perf_counter() - t0) * 1000)
print(f"{mode}: net med {np.median(a):.1f} min {min(a):.1f} ms")
