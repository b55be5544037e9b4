"""roc.py NPZ: from photo.py's scores: for candidates (scored, edge_dist <= D), mask those with score >= t; per t:
masked pixels (share of ROI, added to aligned.json's), > 0.3 m pixels caught, and the ratio after."""
import sys, os
import numpy as np
from common import per_frame, ratio
z = np.load(sys.argv[1]); e, S, Dd = z['e'], z['score'], z['edge_dist']; tot = float(z['roi_total']); share = float(z['share'])
big = np.abs(np.nan_to_num(e)) > 300
mae, rmse = per_frame(e); print(f"base ratio {ratio(mae, rmse):.2f} masked {100*share:.2f} %; budget to 2 %: {int((0.02-share)*tot)} px")
for D in (0, 1, 2):
    cand = np.isfinite(e) & (Dd <= D)
    for t in [float(x) for x in os.environ.get("TS", "25 30 34 40 50").split()]:
        m = cand & (S >= t)
        mae, rmse = per_frame(np.where(m, np.nan, e))
        print(f"  dist<={D} score>={t}: +{100*m.sum()/tot:.2f} % ({m.sum()} px), caught {np.sum(m & big)}/{big.sum()}, ratio {ratio(mae, rmse):.2f}")
