"""island.py DATASET...: a shape prior on the reference image itself (no truth in the mask): a scored reference pixel
with at least k of its 8 neighbours 'other' (a hole, or > 10 % farther) is a convex corner, a peninsula or a bridge
across a gap. Per k: added masked share (of aligned.json's roi_pixels), > 0.3 m pixels caught, ratio after."""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio, boot
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset


def n_other(ref):
    H, W = ref.shape
    zp = np.pad(ref, 1, constant_values=np.nan)
    n = np.zeros((H, W), np.int8)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                zn = zp[1 + di:1 + di + H, 1 + dj:1 + dj + W]
                with np.errstate(invalid='ignore'):
                    n += (~np.isfinite(zn) | (zn > 1.1 * ref)).astype(np.int8)
    return n


if __name__ == '__main__':
    for root in sys.argv[1:]:
        e, share = frame_errors(root); ds = AlignedDataset(root); tot = ds.meta['reference_edges']['roi_pixels']
        N = np.stack([n_other(ds.reference(f)) for f in range(len(ds))])
        big = np.abs(np.nan_to_num(e)) > 300; sc = np.isfinite(e)
        mae, rmse = per_frame(e)
        print(f"{root}: ratio {ratio(mae, rmse):.2f} masked {100*share:.2f} %, budget to 2 %: {int((0.02-share)*tot)} px; big N: {N[big].tolist()}")
        for k in (4, 5, 6, 7):
            m = sc & (N >= k)
            mae, rmse = per_frame(np.where(m, np.nan, e))
            print(f"  k>={k}: +{100*m.sum()/tot:.2f} % ({m.sum()} px), caught {np.sum(m & big)}/{big.sum()}, ratio {ratio(mae, rmse):.2f}")
        np.save(f'/tmp/refedge4/nother_{root.rstrip("/").split("/")[-1]}.npy', N)
