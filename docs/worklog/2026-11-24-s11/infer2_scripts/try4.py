"""Two fold nets' 3x3 convs at one level: two separate convs vs one grouped conv (groups=2), fused+prepacked."""
import os, sys, time, torch, numpy as np
T = int(os.environ.get("T", "2")); torch.set_num_threads(T)
clock = time.thread_time if T == 1 else time.perf_counter
cin, c, H, W, rounds = (int(a) for a in sys.argv[1:6])
torch.manual_seed(0)
ca, cb = torch.nn.Conv2d(cin, c, 3, padding=1), torch.nn.Conv2d(cin, c, 3, padding=1)
cg = torch.nn.Conv2d(2 * cin, 2 * c, 3, padding=1, groups=2)
with torch.no_grad():
    cg.weight.copy_(torch.cat([ca.weight, cb.weight])); cg.bias.copy_(torch.cat([ca.bias, cb.bias]))
cl = torch.channels_last
xa, xb = torch.randn(1, cin, H, W).contiguous(memory_format=cl), torch.randn(1, cin, H, W).contiguous(memory_format=cl)
xg = torch.cat([xa, xb], 1).contiguous(memory_format=cl)
op = torch.ops.mkldnn._convolution_pointwise
pk = lambda conv, g, shape: torch.ops.mkldnn._reorder_convolution_weight(conv.weight.detach().contiguous(), [1, 1], [1, 1], [1, 1], g, shape)
pa, pb, pg = pk(ca, 1, list(xa.shape)), pk(cb, 1, list(xa.shape)), pk(cg, 2, list(xg.shape))
fns = {"two": lambda: (op(xa, pa, ca.bias, [1, 1], [1, 1], [1, 1], 1, "leaky_relu", [0.1], ""), op(xb, pb, cb.bias, [1, 1], [1, 1], [1, 1], 1, "leaky_relu", [0.1], "")),
       "grouped": lambda: op(xg, pg, cg.bias, [1, 1], [1, 1], [1, 1], 2, "leaky_relu", [0.1], ""),
       "two_eager": lambda: (torch.nn.functional.leaky_relu(ca(xa), 0.1), torch.nn.functional.leaky_relu(cb(xb), 0.1)),
       "grouped_eager": lambda: torch.nn.functional.leaky_relu(cg(xg), 0.1)}
with torch.inference_mode():
    a, b = fns["two"](); g = fns["grouped"]()
    print("diff", (torch.cat([a, b], 1) - g).abs().max().item())
    ts = {k: [] for k in fns}
    for r in range(rounds):
        for k, f in fns.items():
            t0 = clock(); f(); ts[k].append((clock() - t0) * 1000)
for k in fns:
    print(f"T{T} {cin}->{c} {H}x{W} {k:>14} min {min(ts[k]):7.2f} med {np.median(ts[k]):7.2f}  two/this med {np.median(ts['two'])/np.median(ts[k]):.2f}")
