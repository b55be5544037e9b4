"""vsfm.py NPZ...: level 2 against its own input (the fold models' mean), moving pixels, truth_roi, paired bootstrap"""
import sys
sys.path.insert(0, "/work/notes/ssdd3")
from evalv import load, scores, paired
for p in sys.argv[1:]:
    d = load(p)
    r = scores(d, {"fm": d["fm"], "lstm": d["lstm"], "unet": d["final"]})
    a = paired(r["lstm"][1], r["fm"][1]); b = paired(r["fm"][1], r["unet"][1])
    print(p, f"lstm - fm moving {a[0]:+.2f} [{a[1]:+.2f}, {a[2]:+.2f}]   fm - unet moving {b[0]:+.2f} [{b[1]:+.2f}, {b[2]:+.2f}]")
