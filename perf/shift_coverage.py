"""Is align's stated time-shift uncertainty honest? Coverage of ``std_us`` over simulated seeds.

For each seed: simulate an lq-hq session (cached under --cache), fit the pair as ``align`` does
(``fit_pair``, never truth) and compare the estimated time shift with the truth: the error in units
of the stated ``std_us`` (RMS of error/std should be about 1, and |error| < 1.96 std in about 95 %
of seeds). Beside the stated deviation it prints its parts, recomputed from the same fit: the
per-feature information (``std_feat``), the scatter of one-probe estimates as if probes were
independent (``probe_se``), the lag-1 autocorrelation of those one-probe estimates in time order,
a delete-one-block jackknife over contiguous blocks of probes (``jackknife``), and the alignment
loop's joint fit (pose and Delta together, :mod:`align.loop`): its Delta and cluster-robust deviation.

    perf/shift_coverage.py --seeds 20-31 --seconds 2
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import minimize_scalar  # noqa: E402

from align.pipeline import AlignOptions, fit_pair, pair_setup  # noqa: E402
from align.time_shift import ShiftLoss, _information, _SubLoss, block_jackknife_se, probe_estimates  # noqa: E402
from bench.cli import parse_seeds  # noqa: E402
from capture.session import open_session  # noqa: E402
from capture.sim import simulate  # noqa: E402
from capture.truth import read_truth  # noqa: E402


def one(seed: int, args) -> dict:
    root = Path(args.cache) / f"{args.scene}-s{seed}-{args.seconds:g}s-x{args.scale:g}"
    if not (root / "session.json").is_file():
        simulate(root, rig="lq-hq", scene=args.scene, seconds=args.seconds, seed=seed, scale=args.scale,
                 progress=False, force=True)
    setup = pair_setup(open_session(root), lq="lq", hq="hq")
    pf = fit_pair(setup, AlignOptions(progress=False, probes=args.probes))
    s = pf.shift
    truth = float(read_truth(root).info["time_shift_us"])
    loss = ShiftLoss([p for p in pf.probes if p.n_features > 0 and p.tracks.shape[0] >= 2], s.T_init, setup.K_lq_color,
                     t0_us=s.t0_us)
    b = s.drift_ppm * 1e-6
    std_feat = _information(loss, s.time_shift_us, b, moving_px=1.0)[0]
    t, est = probe_estimates(loss, s.time_shift_us, b, 1000.0)
    se_ind = 1.4826 * np.median(np.abs(est - np.median(est))) / np.sqrt(est.size) if est.size >= 4 else 0.0
    rho = float(np.corrcoef(est[:-1], est[1:])[0, 1]) if est.size >= 4 else float("nan")
    jack = block_jackknife_se(loss, s.time_shift_us, b, 1000.0)
    full = minimize_scalar(_SubLoss(loss, np.ones(len(loss), bool), b), bounds=(s.time_shift_us - 1000,
                                                                                  s.time_shift_us + 1000),
                           method="bounded", options={"xatol": 5.0}).x
    from align.loop.run import close_loop

    lp = close_loop(setup, pf)
    fl = lp.features
    loop_sd = float(np.sqrt(max(fl.cov[6, 6], 0.0))) * 1000.0
    return {"seed": seed, "loop_error_us": fl.shift_us - truth, "loop_sd": loop_sd, "error_us": s.time_shift_us - truth, "std_us": s.std_us, "std_feat": std_feat,
            "probe_se": se_ind, "rho": rho, "jackknife": jack, "n_probe_est": int(est.size), "a_check": full - truth}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="20-31")
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--scene", default="people")
    ap.add_argument("--probes", type=int, default=24, help="align's probes (default: %(default)s, as align)")
    ap.add_argument("--cache", default="/tmp/depthbench-shift-coverage")
    args = ap.parse_args()
    rows = []
    print("| seed | error (us) | stated std (us) | error/std | std_feat | probe_se | lag-1 rho | jackknife | error/jackknife "
          "| loop: error (us) | loop sd | error/sd |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
    for seed in parse_seeds(args.seeds):
        r = one(seed, args)
        rows.append(r)
        print(f"| {seed} | {r['error_us']:+.0f} | {r['std_us']:.0f} | {r['error_us'] / r['std_us']:+.2f} | "
              f"{r['std_feat']:.0f} | {r['probe_se']:.0f} | {r['rho']:+.2f} | {r['jackknife']:.0f} | "
              f"{r['error_us'] / r['jackknife']:+.2f} | {r['loop_error_us']:+.0f} | {r['loop_sd']:.0f} | "
              f"{r['loop_error_us'] / r['loop_sd']:+.2f} |", flush=True)
    e = np.array([r["error_us"] for r in rows])
    for key, err in (("std_us", e), ("jackknife", e), ("loop_sd", np.array([r["loop_error_us"] for r in rows]))):
        z = err / np.array([r[key] for r in rows])
        print(f"\n{key}: RMS error/std {np.sqrt(np.mean(z ** 2)):.2f} over {z.size} seeds, "
              f"|error| < 1.96 std in {np.mean(np.abs(z) < 1.96) * 100:.0f} % (RMS error {np.sqrt(np.mean(err ** 2)):.0f} us)")


if __name__ == "__main__":
    main()
