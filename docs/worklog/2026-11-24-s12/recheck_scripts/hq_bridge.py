"""The same HQ frame, footprint HQ (new session) against point-sampled (371b651's session of the same seed): how many
HQ pixels read a near surface (> 0.5 m nearer) where the point sample saw the far one, and how many of those are
mixes (between the two) vs fully foreground. python hq_bridge.py NEW_SESSION OLD_SESSION HQ_FRAME_POSITION"""
import sys
import numpy as np
from capture.session import open_session
from align.pipeline import pair_setup

new, old, i = sys.argv[1], sys.argv[2], int(sys.argv[3])
a = pair_setup(open_session(new), lq="lq", hq="hq"); b = pair_setup(open_session(old), lq="lq", hq="hq")
zn = a.session.read_depth("hq", int(a.f_hq[i])); zo = b.session.read_depth("hq", int(b.f_hq[i]))
both = np.isfinite(zn) & np.isfinite(zo)
nearer = both & (zo - zn > 0.5)
farther = both & (zn - zo > 0.5)
print(f"HQ frame {i}: valid new {np.isfinite(zn).mean() * 100:.2f} %, old {np.isfinite(zo).mean() * 100:.2f} %; "
      f"new > 0.5 m nearer than old on {nearer.sum()} px, farther on {farther.sum()} px; "
      f"new valid where old invalid {(np.isfinite(zn) & ~np.isfinite(zo)).sum()} px, the reverse {(~np.isfinite(zn) & np.isfinite(zo)).sum()} px")
if nearer.any():
    print(f"  of the nearer: new depth median {np.median(zn[nearer]):.2f} m, old {np.median(zo[nearer]):.2f} m")
