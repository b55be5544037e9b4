"""One ConvBlock at 480x640 (c_in -> c, c -> c): eager vs mkldnn fused conv+leaky_relu (plain / prepacked weights)."""
import sys, time, torch, numpy as np
import os; torch.set_num_threads(int(os.environ.get("T", "2"))); clock = time.thread_time if os.environ.get("T") == "1" else time.perf_counter
cin, c, H, W = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
torch.manual_seed(0)
blk = torch.nn.Sequential(torch.nn.Conv2d(cin, c, 3, padding=1), torch.nn.LeakyReLU(0.1, inplace=True),
                          torch.nn.Conv2d(c, c, 3, padding=1), torch.nn.LeakyReLU(0.1, inplace=True)).eval()
blk = blk.to(memory_format=torch.channels_last)
x = torch.randn(1, cin, H, W).contiguous(memory_format=torch.channels_last)
conv = torch.ops.mkldnn._convolution_pointwise
def fused(ws):
    def f():
        h = conv(x, ws[0], blk[0].bias, [1, 1], [1, 1], [1, 1], 1, "leaky_relu", [0.1], "")
        return conv(h, ws[1], blk[2].bias, [1, 1], [1, 1], [1, 1], 1, "leaky_relu", [0.1], "")
    return f
plain = [blk[0].weight, blk[2].weight]
pre = [torch.ops.mkldnn._reorder_convolution_weight(blk[0].weight, [1, 1], [1, 1], [1, 1], 1, list(x.shape)),
       torch.ops.mkldnn._reorder_convolution_weight(blk[2].weight, [1, 1], [1, 1], [1, 1], 1, [1, c, H, W])]
nos = [torch.ops.mkldnn._reorder_convolution_weight(blk[0].weight, [1, 1], [1, 1], [1, 1], 1),
       torch.ops.mkldnn._reorder_convolution_weight(blk[2].weight, [1, 1], [1, 1], [1, 1], 1)]
fns = {"eager": lambda: blk(x), "fused": fused(plain), "fused_pre": fused(pre), "fused_nosize": fused(nos)}
with torch.inference_mode():
    ref = blk(x)
    for k, f in fns.items():
        o = f(); print(k, o.shape, o.is_contiguous(memory_format=torch.channels_last), (o - ref).abs().max().item())
    ts = {k: [] for k in fns}
    for r in range(int(sys.argv[5])):
        for k, f in fns.items():
            t0 = clock(); f(); ts[k].append((clock() - t0) * 1000)
for k in fns:
    print(f"{k:>10} min {min(ts[k]):6.2f} med {np.median(ts[k]):6.2f}  eager/this {np.median(ts['eager'])/np.median(ts[k]):.2f}")
