"""Where the multiply-adds of one ssdd_lstm step (fold_mean, bilateral) and one ssdd_unet frame go, by module."""
import sys, tempfile
from collections import defaultdict
from pathlib import Path
import numpy as np, torch
sys.path.insert(0, "perf")
import ssdd_inference as P
from methods import get
from methods.base import FrameInput
from methods.tools.synthetic import synthetic_scene
width = int(sys.argv[1]) if len(sys.argv) > 1 else 8
_, depth = synthetic_scene((480, 640), seed=1)
acc = defaultdict(float)
def hook(m, i, o):
    if isinstance(m, torch.nn.Conv2d):
        acc[(getattr(m, "_tag", "?"), tuple(o.shape[-2:]))] += o.numel() * m.weight[0].numel() / 1e9
with tempfile.TemporaryDirectory() as tmp:
    path = P._weights(Path(tmp), width, 4, "bilateral", True)
    lstm = get("ssdd_lstm", weights=str(path)); lstm.ensure_prepared()
    for label, net in [("L2", lstm.runtime["level2"])] + [("L1", n) for n in lstm.runtime["feeders"]]:
        for n, m in net.named_modules():
            m._tag = label + " " + n.replace("unet.", "").replace(".block", "").replace(".body", "")
    h = torch.nn.modules.module.register_module_forward_hook(hook)
    lstm.denoise_step(FrameInput(0, depth), None)
    h.remove()
tot = sum(acc.values())
print(f"width {width}: {tot:.2f} GMAC per ssdd_lstm step (2 fold level-1 nets + level 2)")
for k, v in sorted(acc.items(), key=lambda kv: -kv[1]):
    print(f"  {k[0]:>10} {str(k[1]):>12} {v:6.3f} GMAC {100 * v / tot:5.1f} %")
