"""Coverage of the extrinsic fit's reported sd against the simulator's truth (task 3, session 10).

python extr_cov.py OUT.jsonl SEED...   (run with PYTHONPATH=<tree with the cluster-robust covariance>)
Per seed: simulate lq-hq people 2 s, scale 0.5, shift and phase drawn by the simulator; fit_pair with the
defaults (photometric refinement on); the final fit's rows are captured and the pose covariance computed
several ways; the error of fit.T against truth (T_lqcolor_hqdepth) is recorded in the fit's parameters.
"""
import json, os, sys, time
from pathlib import Path
import numpy as np
import align.pipeline as P
from align.extrinsics import cluster_covariance, _pose_params
from capture.sim import simulate
from capture.session import open_session
from capture.truth import read_truth

calls = []
orig = P.fit_extrinsics
def rec(points, pixels, K, **kw):
    fit = orig(points, pixels, K, **kw)
    naive = orig(points, pixels, K, **{k: v for k, v in kw.items() if k != "clusters"})
    assert np.array_equal(naive.T.matrix, fit.T.matrix)   # the point estimate does not depend on the clusters
    calls.append((np.asarray(points), np.asarray(pixels), K, kw.get("clusters"), fit, naive.covariance))
    return fit
P.fit_extrinsics = rec

out = open(sys.argv[1], "a")
for seed in map(int, sys.argv[2:]):
    sync = os.environ.get("SYNC") == "1"   # shift 0 and frame phase 0 (extr's 2001-2006 condition)
    root = Path(f"/tmp/tidy_extr/s{seed}{'_sync' if sync else ''}")
    t = time.process_time()
    if not (root / "session.json").exists():
        simulate(root, rig="lq-hq", scene="people", seconds=2.0, seed=seed, scale=0.5, progress=False, workers=1,
                 **({"time_shift_us": 0, "frame_phase_us": 0.0} if sync else {}))
    sess = open_session(root)
    setup = P.pair_setup(sess, lq=sess.sensors_with_role("lq")[0], hq=sess.sensors_with_role("hq")[0])
    calls.clear()
    pf = P.fit_pair(setup, P.AlignOptions(progress=False, workers=1))
    pts, px, K, cl, fit, naive_cov = [c for c in calls if np.array_equal(c[4].T.matrix, pf.fit.T.matrix)][-1]
    shift_term = pf.fit.covariance - (pf.fit.covariance_fit if pf.fit.covariance_fit is not None else pf.fit.covariance)
    truth = read_truth(root).T_lq_hq
    T_true = setup.T_lqdepth_lqcolor.inverse() @ truth
    # error in the fit's parameters: left perturbation D = T_true T_fit^-1 -> (rotvec, translation of T_true - T_fit)
    d = np.concatenate([T_true.rotvec() - fit.T.rotvec(), T_true.t - fit.T.t])   # in the fit's own parameters
    good = np.all(np.isfinite(pts), 1) & np.all(np.isfinite(px), 1)
    inl = fit.inliers[good] if fit.inliers.shape[0] == good.shape[0] else fit.inliers
    Pg, pg, cg = pts[good][inl], px[good][inl], np.asarray(cl)[good][inl]
    uv = setup.K_hq.project(Pg)
    cells = (np.clip(uv[:, 1] * 8 // setup.K_hq.height, 0, 7) * 8 + np.clip(uv[:, 0] * 8 // setup.K_hq.width, 0, 7)).astype(int)
    covs = {"naive": naive_cov, "product": fit.covariance,
            "probe": cluster_covariance(Pg, pg, K, fit.T, cg[:, 0]),
            "keypoint": cluster_covariance(Pg, pg, K, fit.T, cg[:, 1]),
            "cell": cluster_covariance(Pg, pg, K, fit.T, cells),
            "probe x keypoint": cluster_covariance(Pg, pg, K, fit.T, cg),
            "probe x cell": cluster_covariance(Pg, pg, K, fit.T, np.stack([cg[:, 0], cells], 1)),
            "pair (iid)": cluster_covariance(Pg, pg, K, fit.T, np.arange(len(Pg))), "shift term": shift_term, "reported": pf.fit.covariance}
    rec_ = {"seed": seed, "sync": sync, "err": d.tolist(), "n": int(len(Pg)), "keypoints": int(np.unique(cg[:, 1]).size),
            "probes": int(np.unique(cg[:, 0]).size), "shift_us": float(pf.shift.time_shift_us),
            "shift_true_us": float(read_truth(root).time_shift_us), "shift_std_us": float(pf.shift.std_us),
            "covs": {k: (None if v is None else np.asarray(v).tolist()) for k, v in covs.items()},
            "cpu_s": time.process_time() - t, "T": pf.fit.T.matrix.tolist()}
    out.write(json.dumps(rec_) + "\n"); out.flush()
    sd = {k: np.sqrt(np.diag(v))[3:] * 1e3 for k, v in covs.items() if v is not None}
    print(seed, "err mm", np.round(d[3:] * 1e3, 2), {k: np.round(v, 2).tolist() for k, v in sd.items()},
          f"n={len(Pg)} kp={rec_['keypoints']} cpu {rec_['cpu_s']:.0f}s", flush=True)
