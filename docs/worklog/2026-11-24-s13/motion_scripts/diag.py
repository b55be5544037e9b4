"""Which HQ samples land on the sliver pixels of one pair, and what their links / motions are."""
import os, sys
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference, bracket
from align.reference_edges import EdgeRule
from align.roi import background_depth, foreground_mask
from align.motion_flow import flow_image, settle_flow, FALLBACK_LANDED
cv2.setNumThreads(1)
root, k = sys.argv[1], int(sys.argv[2])
rule = EdgeRule.named("strict")
setup, warper, tr, pairs = rm._pairs(root, 10, rule)
sess = setup.session
rd = lambda i: sess.read_depth("hq", int(setup.f_hq[i]))
fm = rm._flow_motion(setup, warper, rd)
i, j, dt = pairs[k]
a, b, alpha = bracket(setup.t_hq, i, dt)
other, frac = (b, alpha) if a == i else (a, 1 - alpha)
print("pair", i, j, dt, "other", other, "frac", frac)
do, dx = rd(i), rd(other)
c = lambda n: sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[n]]))
go, gx = flow_image(c(i), scale=0.25), flow_image(c(other), scale=0.25)
fl = settle_flow(fm._flow(go, gx), go, gx)
finer = (FALLBACK_LANDED, lambda: settle_flow(fm._fallback(go, gx), go, gx))
sf = fm.scene_flow
cm = sf.crop_motion(do, dx, fl, scale=frac, warper=warper, refine=finer)
print("gain", sf.last_gain, "landed", sf.last_landed, "refined", sf.last_refined)
ref = rule.apply(warper.warp(do, motion=cm))[0]
plain = rule.apply(warper.warp(do))[0]
truth = tr.depth("lq", int(setup.f_lq[j]))
u, v, w, valid = warper.forward_map(do, motion=cm)
u0, v0, _, _ = warper.forward_map(do)
r0, r1, c0, c1 = warper.crop
mz = np.full(do.shape, np.nan, np.float32); mz[r0:r1, c0:c1] = cm.dz.reshape(r1 - r0, c1 - c0)
e = (ref - truth) * 1000
bad = np.isfinite(e) & (e < -300)
print("bad px", bad.sum())
ys, xs = np.nonzero(bad)
# source samples landing within 1 px of bad pixels
ok = valid & np.isfinite(u)
U, V = u[ok], v[ok]
src = np.argwhere(ok)
near = np.zeros(bad.shape, bool)
badset = bad
hit = []
for (sy, sx), uu, vv in zip(src, U, V):
    iu, iv = int(round(uu)), int(round(vv))
    if 0 <= iv < bad.shape[0] and 0 <= iu < bad.shape[1] and bad[iv, iu]:
        hit.append((sy, sx))
hit = np.array(hit)
print("source samples landing on bad px:", len(hit))
if len(hit):
    print(" rows", hit[:, 0].min(), hit[:, 0].max(), "cols", hit[:, 1].min(), hit[:, 1].max())
    for sy, sx in hit[:: max(1, len(hit) // 25)]:
        nb = do[sy - 1:sy + 2, sx - 1:sx + 2]
        du = u[sy, sx] - u0[sy, sx]; dv = v[sy, sx] - v0[sy, sx]
        nbm = [(round(float(u[sy + a_, sx + b_] - u0[sy + a_, sx + b_]), 1), round(float(v[sy + a_, sx + b_] - v0[sy + a_, sx + b_]), 1)) for a_, b_ in ((0, -1), (0, 1), (-1, 0), (1, 0))]
        print(f"  src ({sy},{sx}) d {do[sy, sx]:.3f} moved ({du:.1f},{dv:.1f}) dz {mz[sy, sx]*1000:.0f}mm nbrs d {np.round(nb.ravel(), 2)} nb moves {nbm}")
np.savez("/work/notes/motion/diag.npz", ref=ref, plain=plain, truth=truth, u=u, v=v, u0=u0, v0=v0, do=do, dx=dx, bad=bad)
to = tr.depth("hq", int(setup.f_hq[i])); tx = tr.depth("hq", int(setup.f_hq[other]))
wto, wtx = rule.apply(warper.warp(to))[0], rule.apply(warper.warp(tx))[0]
lab_bad = bad
for name, arr in (("truth_lq", truth), ("ref", ref), ("plain", plain), ("warp truth_hq o", wto), ("warp truth_hq x", wtx)):
    a_ = arr[bad]
    print(f"{name:18s} on bad: median {np.nanmedian(a_):.2f} finite {np.isfinite(a_).mean():.2f} fg(<2.5m) {np.mean(a_ < 2.5):.2f}")
np.savez("/work/notes/motion/diag.npz", ref=ref, plain=plain, truth=truth, u=u, v=v, u0=u0, v0=v0, do=do, dx=dx, bad=bad, wto=wto, wtx=wtx)
mot, trusted = sf.motion(do, dx, fl, scale=frac)
cams, grid, low, shift, has = sf._shifts(do, dx, fl, (0, do.shape[0], 0, do.shape[1]))
st = sf.stride
sh = np.repeat(np.repeat(shift, st, 0), st, 1)[:do.shape[0], :do.shape[1]]
if len(hit):
    t = trusted[hit[:, 0], hit[:, 1]]
    print("hit samples trusted share", t.mean(), "n", len(hit))
    rs = sh[hit[:, 0], hit[:, 1]] * frac
    mv = np.stack([u[hit[:, 0], hit[:, 1]] - u0[hit[:, 0], hit[:, 1]], v[hit[:, 0], hit[:, 1]] - v0[hit[:, 0], hit[:, 1]]], 1)
    for q in range(0, len(hit), max(1, len(hit) // 15)):
        print("  ", hit[q], "trusted", t[q], "raw flow*gain*frac (depth px)", np.round(rs[q], 2), "applied (LQ px)", np.round(mv[q], 2), "d", round(float(do[tuple(hit[q])]), 2))
# all arm-ish samples (depth 1.35-1.5) in the hit rows: trusted share
