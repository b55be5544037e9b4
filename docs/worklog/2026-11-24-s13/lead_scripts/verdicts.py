"""verdicts.py RESULTS...: per results folder, ranking_check in both strata: same order?, flips, wrong pairs; RGF-UNet."""
import sys
from bench import results as R
from bench.summary import ranking_check, edge_share
for root in sys.argv[1:]:
    t = R.load_results(root)
    line = [root.split("/")[-1], f"edge share {edge_share(t).mean()*100:.1f} %"]
    for st in ("interior", "all"):
        c = ranking_check(t, stratum=st)
        for m, short in (("mse_mm2", "MSE"), ("rmse_mm", "RMSE")):
            flips = sum((d["hq"][0] > 0) != (d["truth"][0] > 0) for _, _, d in c[m]["pairs"])
            line.append(f"{st} {short}: same {c[m]['same']}, flips {flips}, wrong {len(c[m]['wrong'])}")
        d = next(d for a, b, d in c["mse_mm2"]["pairs"] if {a.split("@")[0], b.split("@")[0]} == {"rolling_guidance", "ssdd_unet"})
        line.append(f"{st} RGF-UNet MSE hq {d['hq'][0]:+.2f} [{d['hq'][1]:+.2f},{d['hq'][2]:+.2f}] truth {d['truth'][0]:+.2f} [{d['truth'][1]:+.2f},{d['truth'][2]:+.2f}]")
    print(" | ".join(line), flush=True)
