"""trueflow.py SEED ALIGNED OUT.npz: for every aligned LQ frame t, the true position in frame t-k (k=1..K) of the
surface point each pixel of frame t sees (the simulator's scene at the two frames' instants, same LQ depth camera),
and that point's camera depth at t-k. Diagnosis only (uses the simulator's geometry)."""
import sys
import csv
import numpy as np
from capture.sim.simulator import make_plan
from capture.sim.pipeline import FrameWorker

seed, root, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
K_BACK = 3
plan = make_plan(rig="lq-hq", scene="people", seconds=3, seed=seed, effects=None, undeclared=False,
                 time_shift_us=25000, static=False, scale=0.5, lq_fps=30.0, hq_fps=30.0)
w = FrameWorker(plan, nthreads=1)
sid = plan.rig.target
cam = w.cams[sid].depth
Kd = plan.rig.sensor(sid).depth
T = cam.T_world_cam
sched = plan.schedules[sid]
fn2t = dict(zip(sched.frame_number.tolist(), sched.scene_time_us.tolist()))
rows = list(csv.DictReader(open(f"{root}/frames.csv")))
times = np.array([fn2t[int(r["lq_frame"])] for r in rows]) * 1e-6
scene = w.renderer.scene
H, W = Kd.shape
n = len(rows)
uv = np.full((n, K_BACK, H, W, 2), np.nan, np.float32)
zb = np.full((n, K_BACK, H, W), np.nan, np.float32)
zt = np.full((n, H, W), np.nan, np.float32)
for t in range(n):
    ans = w.renderer.cast_raw(cam, times[t])
    hit = np.isfinite(ans["t_hit"])
    zt[t] = np.where(hit, ans["t_hit"], np.nan)
    prim = ans["primitive_ids"][hit].astype(np.int64)
    u, v = ans["primitive_uvs"][hit][:, 0], ans["primitive_uvs"][hit][:, 1]
    tri = scene.triangles[prim]
    for k in range(1, K_BACK + 1):
        if t - k < 0:
            continue
        V = scene.vertices_at(times[t - k])
        p = (1 - u - v)[:, None] * V[tri[:, 0]] + u[:, None] * V[tri[:, 1]] + v[:, None] * V[tri[:, 2]]
        pc = T.inverse().apply(p)
        pix = Kd.project(pc)
        a = uv[t, k - 1]; a[hit] = pix
        b = zb[t, k - 1]; b[hit] = pc[:, 2]
np.savez_compressed(out, uv=uv, zb=zb, zt=zt, times=times)
print(out, n, H, W)
