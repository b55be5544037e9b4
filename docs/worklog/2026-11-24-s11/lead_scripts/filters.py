"""filters.py: on fresh 210/211, ssdd_unet / ssdd_lstm (C, seeds 0..40) against every filter (truth_roi, MSE all and moving),
paired per frame; the filters' runs are /tmp/lead11/F_{S}, the learned ones /tmp/lead11/R_C{s}_{S}."""
import sys
import pandas as pd
sys.path.insert(0, ".")
from bench.truth_roi import with_truth_roi
from perf.ssdd_paired import paired

def table(path, metric):
    df = with_truth_roi(pd.read_parquet(path + "/results.parquet"))
    df = df[(df.reference == "truth_roi") & (df.metric == metric) & df.bin_lo_m.isna()]
    return df.pivot_table(index=["dataset", "frame"], columns="method", values="value")

f = lambda r: "%+.2f [%+.2f, %+.2f]" % r[:3]
for metric in ("mse_mm2", "mse_moving_mm2"):
    for S in (210, 211):
        F = table(f"/tmp/lead11/F_{S}", metric)
        print(metric, S, "filters:", " ".join(f"{c} {F[c].mean():.2f}" for c in F.columns))
        for s in (0, 10, 20, 30, 40):
            L = table(f"/tmp/lead11/R_C{s}_{S}", metric)
            assert (L.bilateral - F.bilateral).abs().max() < 1e-9
            t = pd.concat([F, L[["ssdd_unet", "ssdd_lstm"]]], axis=1)
            print(f"  seed {s}: UNet-RGF {f(paired(t, 'ssdd_unet', 'rolling_guidance'))}  UNet-JBF {f(paired(t, 'ssdd_unet', 'joint_bilateral'))}"
                  f"  LSTM-RGF {f(paired(t, 'ssdd_lstm', 'rolling_guidance'))}")
