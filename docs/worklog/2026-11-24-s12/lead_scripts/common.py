"""Shared helpers: per-frame HQ-sensor errors of an aligned dataset, as the leaderboard's column scores them
(bench.compute: the reference against truth_strata()['truth'] inside the ROI; summary = mean over frames of
per-frame RMSE and MAE)."""
import json, sys
from pathlib import Path
import numpy as np
sys.path.insert(0, '/work/wt/footprint')
from align.dataset import AlignedDataset
from bench.masks import truth_strata, valid_mask

CACHE = Path('/tmp/fp/cache')


def frame_errors(root):
    """list of (err_mm (H,W) float64 NaN outside scored pixels), and masked share from aligned.json."""
    root = Path(root)
    key = CACHE / (root.parent.name + '_' + root.name + '.npz')
    meta = json.load(open(root / 'aligned.json'))
    re = meta['reference_edges']
    share = re.get('masked_roi_pixels', 0) / re['roi_pixels']
    if key.exists() and key.stat().st_mtime > (root / 'aligned.json').stat().st_mtime:
        return np.load(key)['e'], share
    ds = AlignedDataset(root)
    out = []
    for i in range(len(ds)):
        ref, tru, roi = ds.reference(i), ds.truth(i), ds.roi(i)
        t = truth_strata(tru, ref)['truth']
        m = valid_mask(ref, t, roi)
        e = np.full(ref.shape, np.nan)
        e[m] = (ref[m].astype(np.float64) - t[m].astype(np.float64)) * 1000.0
        out.append(e)
    e = np.stack(out)
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(key, e=e)
    return e, share


def per_frame(e):
    """per-frame (mae, rmse) arrays."""
    a = np.abs(e)
    n = np.sum(np.isfinite(e), axis=(1, 2))
    mae = np.nansum(a, axis=(1, 2)) / n
    rmse = np.sqrt(np.nansum(a * a, axis=(1, 2)) / n)
    return mae, rmse


def ratio(mae, rmse):
    return rmse.mean() / mae.mean()


def boot(fn, n_frames, B=2000, seed=0):
    rng = np.random.default_rng(seed)
    vals = [fn(rng.integers(0, n_frames, n_frames)) for _ in range(B)]
    return np.percentile(vals, [2.5, 97.5])
