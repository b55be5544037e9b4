"""combo.py NAME...: shape candidates (island.py's N >= k) ranked by a colour score (photo.py's, RGB 'l0' or luma
'l1'), the highest masked until the budget left under 2 % of the ROI (aligned.json's share + these <= 2 %); also
'shape only' ranked by N then at random (no colour), to see what the colour adds. No truth in the masks."""
import sys
import numpy as np
from common import per_frame, ratio, boot

for name in sys.argv[1:]:
    N = np.load(f'/tmp/refedge4/nother_{name}.npy')
    out = []
    for lab in ('l0w1', 'l1w1', 'rand'):
        z = np.load(f'/tmp/refedge4/photo_{name}_{"l0w1" if lab == "rand" else lab}.npz')
        e, tot, share = z['e'], float(z['roi_total']), float(z['share'])
        S = np.random.default_rng(0).random(e.shape) if lab == 'rand' else np.nan_to_num(z['score'], nan=-1)
        big = np.abs(np.nan_to_num(e)) > 300
        B = int((0.02 - share) * tot)
        for k in (4, 5, 6):
            cand = np.isfinite(e) & (N >= k)
            key = np.where(cand, N * 1000.0 + S, -np.inf) if lab == 'rand' else np.where(cand, S, -np.inf)
            order = np.argsort(-key.ravel())[:min(B, int(cand.sum()))]
            m = np.zeros(e.size, bool); m[order] = True; m = m.reshape(e.shape)
            mae, rmse = per_frame(np.where(m, np.nan, e))
            lo, hi = boot(lambda i: ratio(mae[i], rmse[i]), len(mae), B=500)
            out.append(f"  {lab} k>={k}: mask {m.sum()} of {cand.sum()} cand (budget {B}), caught {np.sum(m & big)}/{big.sum()}, "
                       f"ratio {ratio(mae, rmse):.2f} [{lo:.2f}, {hi:.2f}], masked {100 * (share + m.sum() / tot):.2f} %")
    print(name); print("\n".join(out))
