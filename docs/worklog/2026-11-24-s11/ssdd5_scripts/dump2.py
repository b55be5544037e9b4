"""dump2.py RUN ALIGNED OUT.npz (ssdd3's dump.py + lstm0: level 2 with its state reset every frame): per frame the final level 1, the fold models' mean, and level 2 (as the
ssdd_lstm denoiser runs it: fold-mean input, state over the whole sequence), plus LQ depth, reference, truth, ROI.
All float32 metres, values at every pixel (holes are applied at scoring)."""
import sys
import numpy as np
import torch
from align.dataset import AlignedDataset
from methods.base import FrameInput
from methods.ssdd.denoise import SSDDLSTMDenoiser
from methods.ssdd.model import level1_depth, level2_step

torch.set_num_threads(1)
run, root, out = sys.argv[1:4]
ds = AlignedDataset(root)
m = SSDDLSTMDenoiser(weights=f"{run}/ssdd_lstm.safetensors", allow_train_frames=True, fill_holes=True)
m.ensure_prepared()
rt, cfg = m.runtime, m.config
keys = ("lq", "ref", "truth", "roi", "final", "fm", "lstm", "lstm0")
acc = {k: [] for k in keys}
state = None
for i in range(len(ds)):
    fr = FrameInput(index=i, depth=ds.lq_depth(i), color=ds.lq_color(i))
    depth, rgb, base = m._tensors([fr])
    with torch.inference_mode():
        fin = level1_depth(rt["level1"], depth, rgb, cfg.level1.data, base)
        fm = torch.stack([level1_depth(n, depth, rgb, cfg.level1.data, base) for n in rt["feeders"]]).mean(0)
        y, st = level2_step(rt["level2"], fm, depth, rgb, cfg.level2.data, state,
                            sequence_centre=cfg.level2.centre == "sequence")
    state = st
    with torch.inference_mode():   # the same level 2 with its state reset at every frame (no memory)
        y0, _ = level2_step(rt["level2"], fm, depth, rgb, cfg.level2.data, None,
                            sequence_centre=cfg.level2.centre == "sequence")
    acc["lstm0"].append(y0[0, 0].numpy())
    t = ds.truth(i)
    acc["lq"].append(fr.depth); acc["ref"].append(ds.reference(i))
    acc["truth"].append(t if t is not None else np.full_like(fr.depth, np.nan))
    r = ds.roi(i); acc["roi"].append(np.ones_like(fr.depth, bool) if r is None else r.astype(bool))
    acc["final"].append(fin[0, 0].numpy()); acc["fm"].append(fm[0, 0].numpy()); acc["lstm"].append(y[0, 0].numpy())
np.savez(out, **{k: np.stack(v) for k, v in acc.items()})
print(out, len(ds))
