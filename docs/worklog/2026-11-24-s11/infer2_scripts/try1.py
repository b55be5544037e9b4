"""Level-1 net forward at 640x480: eager channels_last vs jit.freeze / optimize_for_inference / mkldnn."""
import sys, time, torch, copy
from methods.ssdd.networks import NetConfig, SSDDUNet
torch.set_num_threads(2)
width, levels = int(sys.argv[1]), int(sys.argv[2])
modes = sys.argv[3].split(",")
torch.manual_seed(0)
net = SSDDUNet(NetConfig(width=width, levels=levels), base=True).eval()
net = net.to(memory_format=torch.channels_last)
x = torch.randn(1, 1, 480, 640); v = (torch.rand(1,1,480,640) > 0.1).float(); b = x + 0.01*torch.randn_like(x)
args = (x, v, None, None, b)
class W(torch.nn.Module):
    def __init__(s, n): super().__init__(); s.n = n
    def forward(s, x, v, b): return s.n(x, v, None, None, b)
fns = {}
with torch.inference_mode():
    ref = net(*args)
for m in modes:
    t0 = time.perf_counter()
    if m == "eager":
        f = lambda: net(*args)
    elif m in ("freeze", "ofi"):
        with torch.no_grad():
            tr = torch.jit.trace(W(copy.deepcopy(net)).eval(), (x, v, b))
            fr = torch.jit.freeze(tr) if m == "freeze" else torch.jit.optimize_for_inference(torch.jit.freeze(tr))
        f = (lambda fr=fr: fr(x, v, b))
    elif m == "compile":
        c = torch.compile(W(net))
        f = (lambda c=c: c(x, v, b))
    elif m == "compile_ft":
        import torch._inductor.config as ic
        ic.freezing = True
        c = torch.compile(W(copy.deepcopy(net)))
        f = (lambda c=c: c(x, v, b))
    with torch.no_grad():
        out = f()
    setup = time.perf_counter() - t0
    d = (out - ref).abs().max().item()
    fns[m] = f
    print(f"{m}: setup+first {setup:.1f} s, max|diff| {d:.2e}", flush=True)
ts = {m: [] for m in modes}
with torch.no_grad():
    for r in range(int(sys.argv[4]) if len(sys.argv) > 4 else 10):
        for m in modes:
            t0 = time.perf_counter(); fns[m](); ts[m].append((time.perf_counter() - t0) * 1000)
import numpy as np
for m in modes:
    print(f"{m:>10}: min {min(ts[m]):7.1f} median {np.median(ts[m]):7.1f} ms  ratio(med) eager/this {np.median(ts[modes[0]])/np.median(ts[m]):.2f}")
