"""Two level-1 nets (fold_mean) at 640x480: sequential on 2 intra-op threads vs concurrently, one Python thread each
with 1 intra-op thread."""
import os, sys, time, threading, torch, numpy as np
from concurrent.futures import ThreadPoolExecutor
from methods.ssdd.networks import NetConfig, SSDDUNet
torch.set_num_threads(2)
width, levels, rounds = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
torch.manual_seed(0)
nets = [SSDDUNet(NetConfig(width=width, levels=levels), base=True).eval().to(memory_format=torch.channels_last) for _ in range(2)]
x = torch.randn(1, 1, 480, 640); v = (torch.rand(1, 1, 480, 640) > 0.1).float(); b = x + 0.01 * torch.randn_like(x)
pool = ThreadPoolExecutor(2, initializer=lambda: torch.set_num_threads(1))
def one(n):
    with torch.inference_mode():
        return n(x, v, None, None, b)
print("main threads after pool init:", list(pool.map(lambda _: torch.get_num_threads(), range(2))), torch.get_num_threads())
fns = {"seq": lambda: [one(n) for n in nets], "par": lambda: list(pool.map(one, nets))}
a, c = fns["seq"](), fns["par"]()
print("diff", max((p - q).abs().max().item() for p, q in zip(a, c)), "threads now", torch.get_num_threads())
ts = {k: [] for k in fns}; cpu = {k: [] for k in fns}
for r in range(rounds):
    for k, f in fns.items():
        t0, c0 = time.perf_counter(), time.process_time(); f(); ts[k].append((time.perf_counter() - t0) * 1000); cpu[k].append((time.process_time() - c0) * 1000)
for k in fns:
    print(f"w{width}/{levels} {k:>4} wall min {min(ts[k]):7.1f} med {np.median(ts[k]):7.1f}  seq/this med {np.median(ts['seq'])/np.median(ts[k]):.2f} min {min(ts['seq'])/min(ts[k]):.2f}; cpu med {np.median(cpu[k]):7.1f}")
