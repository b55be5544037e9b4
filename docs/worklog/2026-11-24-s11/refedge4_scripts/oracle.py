"""oracle.py DATASET...: ratio after removing the k largest |error| pixels (truth-chosen, an oracle bound; greedy
by |e|), and the share of the summed squared error from pixels above thresholds."""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio

for d in sys.argv[1:]:
    e, share = frame_errors(d)
    a = np.abs(e).ravel(); fin = np.isfinite(a)
    order = np.argsort(-np.nan_to_num(a, nan=-1))
    s = []
    for k in (0, 5, 10, 12, 15, 21, 30, 50, 100, 200, 500):
        e2 = e.copy().ravel(); e2[order[:k]] = np.nan
        mae, rmse = per_frame(e2.reshape(e.shape))
        s.append(f"k{k}:{ratio(mae, rmse):.2f}")
    sq = np.nansum(a ** 2)
    fr = " ".join(f">{t}mm {np.nansum(a[a > t] ** 2) / sq:.0%}({int(np.sum(a > t))})" for t in (20, 50, 100, 300, 1000))
    print(d, " ".join(s), "|", fr)
