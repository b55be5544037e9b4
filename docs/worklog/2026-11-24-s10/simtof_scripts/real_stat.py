import sys; sys.path.insert(0, "/work/notes/simtof")
import numpy as np
from edgestat import per_pixel, clusters, report
r = np.load("/work/notes/simtof/real.npz")
d = r["depth"].astype(np.float32) / 1000; ir = r["ir"]
d[d == 0] = np.nan
fov = ir > 0
print("fov share", fov.mean(), "valid in fov", np.isfinite(d)[fov].mean())
for lo, hi in ((0.1, 0.2), (0.2, None), (0.1, None)):
    report(f"real jump {lo}-{hi}", clusters(per_pixel(d, fov, lo, hi), 32))
