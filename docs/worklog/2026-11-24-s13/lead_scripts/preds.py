"""preds.py ALIGNED OUT.npz: every demo method's output on every frame of ALIGNED, with reference, truth, ROI."""
import os, sys
os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np, torch
torch.set_num_threads(1)
from align.dataset import AlignedDataset
from bench.runner import resolve_methods
from methods.run import iter_dataset
R = "/tmp/fp/demo/runs"
params = {"ddrnet": {"weights": f"{R}/ddrnet/ddrnet.safetensors"}, "ddrnet_refine": {"weights": f"{R}/ddrnet/ddrnet_refine.safetensors"},
          "ddd": {"weights": f"{R}/ddd/ddd.safetensors"}, "ssdd_unet": {"weights": f"{R}/ssdd/ssdd_unet.safetensors"},
          "ssdd_lstm": {"weights": f"{R}/ssdd/ssdd_lstm.safetensors"}}
names = "raw,gaussian,bilateral,joint_bilateral,rolling_guidance,ddrnet,ddrnet_refine,ddd,ssdd_unet,ssdd_lstm"
ds = AlignedDataset(sys.argv[1])
n = len(ds)
out = {}
for m in resolve_methods(names, params):
    arr = None
    for d in iter_dataset(m, ds, progress=False):
        if arr is None:
            arr = np.full((n, *d.depth.shape), np.nan, np.float32)
        arr[d.index] = d.depth
    out[m.name] = arr
    print(m.name, flush=True)
f = [ds.frame(i) for i in range(n)]
out["reference"] = np.stack([x.reference for x in f]); out["truth"] = np.stack([x.truth for x in f]); out["roi"] = np.stack([x.roi for x in f])
np.savez(sys.argv[2], **out)
