"""hqsensor.py DIR...: the HQ sensor column (MAE, RMSE, ratio with a 2000-resample frame bootstrap interval)
and the masked share from aligned.json; also the count of scored pixels > 0.3 m / > 1 m off."""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio, boot

for d in sys.argv[1:]:
    e, share = frame_errors(d)
    mae, rmse = per_frame(e)
    lo, hi = boot(lambda i: ratio(mae[i], rmse[i]), len(mae))
    a = np.abs(e)
    print(f"{d}: MAE {mae.mean():.2f} RMSE {rmse.mean():.2f} ratio {ratio(mae, rmse):.2f} [{lo:.2f}, {hi:.2f}] "
          f"masked {100 * share:.2f} % | >0.3 m {int(np.sum(a > 300))} >1 m {int(np.sum(a > 1000))} "
          f"scored {int(np.sum(np.isfinite(e)))}")
