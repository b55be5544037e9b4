"""8-seq (E) vs 4-seq (L) runs on the same session, paired per frame: E's ssdd_unet/ssdd_lstm - L's, and
LSTM - UNet / UNet - BF per run.  usage: cross.py SESSION SEED [SEED ...]   (reads /tmp/s4/R_{E,L}{seed}_{session})"""
import sys
import pandas as pd
sys.path.insert(0, ".")
from bench.truth_roi import with_truth_roi
from perf.ssdd_paired import paired

def table(path):
    df = with_truth_roi(pd.read_parquet(path + "/results.parquet"))
    df = df[(df.reference == "truth_roi") & (df.metric == "mse_moving_mm2") & df.bin_lo_m.isna()]
    return df.pivot_table(index=["dataset", "frame"], columns="method", values="value")

S = sys.argv[1]
for s in sys.argv[2:]:
    e, l = table(f"/tmp/s4/R_E{s}_{S}"), table(f"/tmp/s4/R_L{s}_{S}")
    t = pd.concat({"E_" + c: e[c] for c in e} | {"L_" + c: l[c] for c in l}, axis=1)
    f = lambda a, b: "%+.2f [%+.2f, %+.2f]" % paired(t, a, b)[:3]
    print(f"session {S} seed {s}: LSTM-UNet 4seq {f('L_ssdd_lstm','L_ssdd_unet')} 8seq {f('E_ssdd_lstm','E_ssdd_unet')} | "
          f"UNet-BF 4seq {f('L_ssdd_unet','L_bilateral')} 8seq {f('E_ssdd_unet','E_bilateral')} | "
          f"8-4 UNet {f('E_ssdd_unet','L_ssdd_unet')} LSTM {f('E_ssdd_lstm','L_ssdd_lstm')} | BF same {(t.E_bilateral-t.L_bilateral).abs().max():.2g}")
