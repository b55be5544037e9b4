"""paired.py A B: paired bootstrap (2000 frame resamples) of ratio(B) - ratio(A), and RMSE(B) - RMSE(A)."""
import sys
import numpy as np
from common import frame_errors, per_frame, ratio, boot

ea, sa = frame_errors(sys.argv[1]); eb, sb = frame_errors(sys.argv[2])
ma, ra = per_frame(ea); mb, rb = per_frame(eb)
d = ratio(mb, rb) - ratio(ma, ra)
lo, hi = boot(lambda i: ratio(mb[i], rb[i]) - ratio(ma[i], ra[i]), len(ma))
dr = rb.mean() - ra.mean()
lo2, hi2 = boot(lambda i: rb[i].mean() - ra[i].mean(), len(ma))
print(f"ratio {ratio(ma, ra):.2f} -> {ratio(mb, rb):.2f}: {d:+.2f} [{lo:+.2f}, {hi:+.2f}]; RMSE {dr:+.2f} [{lo2:+.2f}, {hi2:+.2f}] mm; "
      f"masked {100*sa:.2f} -> {100*sb:.2f} %")
