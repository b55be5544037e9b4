"""Prototype: masks of uncertain-motion samples on the flow reference (strict rule), scored like acc.py.
DUMP=out.json python proto.py SESSION..."""
import os, sys, json
os.environ.setdefault("OMP_NUM_THREADS", "1"); os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import perf.reference_motion as rm
from align.motion import MotionReference, bracket
from align.reference_edges import EdgeRule
from align.roi import background_depth, foreground_mask
from align.motion_flow import flow_image, settle_flow, FALLBACK_LANDED
from align.warp import CropMotion
cv2.setNumThreads(1)

def dest_mask(sel, u, v, w, ref, shape):
    m = np.zeros(shape, bool)
    ys, xs = np.nonzero(sel)
    if not ys.size: return m
    fu, fv, ww = np.floor(u[ys, xs]).astype(int), np.floor(v[ys, xs]).astype(int), w[ys, xs]
    for a in (0, 1):
        for b in (0, 1):
            x, y = fu + a, fv + b
            ok = (x >= 0) & (x < shape[1]) & (y >= 0) & (y < shape[0])
            x, y, wq = x[ok], y[ok], ww[ok]
            r = ref[y, x]
            same = np.isfinite(r) & (np.abs(r * wq - 1) <= 0.03)
            m[y[same], x[same]] = True
    return m

def trailing(sel, do, du, dv, c, maxj=0.08):
    """samples of sel with a farther/no sample within c*|disp| (+1) source px behind them (against the motion)."""
    ys, xs = np.nonzero(sel)
    out = np.zeros(sel.shape, bool)
    if not ys.size: return out
    mag = np.hypot(du[ys, xs], dv[ys, xs])
    ux, uy = -du[ys, xs] / np.maximum(mag, 1e-6), -dv[ys, xs] / np.maximum(mag, 1e-6)
    J = np.maximum(np.ceil(c * mag).astype(int), 1)
    d0 = do[ys, xs]; H, W = do.shape
    hit = np.zeros(ys.size, bool)
    for j in range(1, J.max() + 1):
        act = J >= j
        yy = np.clip(np.round(ys + uy * j).astype(int), 0, H - 1); xx = np.clip(np.round(xs + ux * j).astype(int), 0, W - 1)
        dn = do[yy, xx]
        far = ~(dn <= d0 + maxj)  # NaN or farther
        hit |= act & far
    out[ys[hit], xs[hit]] = True
    return out

VARIANTS = ["none", "T1c05", "T1c1", "T15c05", "T2c1", "CT1c05", "CT15c1"]
out = {}
for root in sys.argv[1:]:
    rule = EdgeRule.named("strict")
    setup, warper, tr, pairs = rm._pairs(root, 10, rule)
    sess = setup.session
    rd = lambda i: sess.read_depth("hq", int(setup.f_hq[i]))
    fm = rm._flow_motion(setup, warper, rd)
    sf = fm.scene_flow
    col = lambda n: sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[n]]))
    rows = []
    for i, j, dt in pairs:
        lq = sess.read_depth("lq", int(setup.f_lq[j]))
        do = rd(i)
        plain = rule.apply(warper.warp(do))[0]
        br = bracket(setup.t_hq, i, dt) if abs(dt) >= 1000 else None
        masks = {}
        if br is None:
            ref = plain
            for k in VARIANTS: masks[k] = np.zeros(ref.shape, bool)
        else:
            a, b, alpha = br
            other, frac = (b, alpha) if a == i else (a, 1 - alpha)
            dx = rd(other)
            go, gx = flow_image(col(i), scale=0.25), flow_image(col(other), scale=0.25)
            fl = settle_flow(fm._flow(go, gx), go, gx)
            finer = (FALLBACK_LANDED, lambda: settle_flow(fm._fallback(go, gx), go, gx))
            o, trl = sf._planar(do, dx, fl, frac, warper.T.R.astype(np.float32), tuple(int(c) for c in warper.crop), 4, finer)
            cm = CropMotion(dst=o[:3].reshape(3, -1), dz=o[3].reshape(-1))
            raw, fmap = warper.warp_with_map(do, motion=cm)
            ref = rule.apply(raw)[0]
            u, v, w, valid = fmap
            u0, v0, _, _ = warper.forward_map(do)
            du, dv = u - u0, v - v0
            st = sf.stride; r0, r1, c0, c1 = warper.crop; g0, h0 = r0 - r0 % st, c0 - c0 % st
            tfull = np.ones(do.shape, bool)
            tt = np.repeat(np.repeat(trl, st, 0), st, 1)
            tfull[g0:g0 + tt.shape[0], h0:h0 + tt.shape[1]] = tt[:do.shape[0] - g0, :do.shape[1] - h0]
            moving = valid & (np.hypot(du, dv) >= 0.5)
            unt = moving & ~tfull & np.isfinite(do)
            masks["none"] = np.zeros(ref.shape, bool)
            masks["A"] = dest_mask(unt, u, v, w, ref, ref.shape)
            ratio = sf.K_depth.fx / warper.K_dst.fx
            ys, xs = np.nonzero(unt)
            yy = np.clip(np.round(ys + dv[ys, xs] * ratio).astype(int), 0, do.shape[0] - 1)
            xx = np.clip(np.round(xs + du[ys, xs] * ratio).astype(int), 0, do.shape[1] - 1)
            left = np.zeros(do.shape, bool)
            left[ys, xs] = ~(dx[yy, xx] <= do[ys, xs] + 0.08)
            mag = np.hypot(du, dv)
            for name, T, c, base in (("T1c05", 1, .5, unt), ("T1c1", 1, 1, unt), ("T15c05", 1.5, .5, unt), ("T2c1", 2, 1, unt),
                                     ("CT1c05", 1, .5, left), ("CT15c1", 1.5, 1, left)):
                masks[name] = dest_mask(trailing(base & (mag >= T), do, du, dv, c), u, v, w, ref, ref.shape)
        rows.append((plain, ref, masks, tr.depth("lq", int(setup.f_lq[j])), lq))
    bg = background_depth(np.stack([np.where(np.isfinite(r[0]), r[0], r[4]) for r in rows]))
    recs = []
    for (p, f, masks, truth, lq), (i, j, dt) in zip(rows, pairs):
        roi = foreground_mask(np.where(np.isfinite(p), p, lq), bg) & np.isfinite(truth)
        rec = dict(hq=i, lq=j, dt_ms=dt / 1000, plain_n=int((roi & np.isfinite(p)).sum()))
        for k, m in masks.items():
            ok = roi & np.isfinite(f) & ~m
            e = np.abs(f - truth)[ok] * 1000
            rec[f"{k}_sum"], rec[f"{k}_n"] = float(e.sum()), int(e.size)
            rec[f"{k}_masked"] = int((roi & np.isfinite(f) & m).sum())
        recs.append(rec)
    out[root] = recs
    line = f"{root}:"
    for k in VARIANTS:
        s, n, mk = (sum(r[f"{k}_{x}"] for r in recs) for x in ("sum", "n", "masked"))
        line += f" {k} {s / n:.2f} ({100 * mk / sum(r['plain_n'] for r in recs):.2f}%)"
    print(line, flush=True)
if os.environ.get("DUMP"):
    json.dump(out, open(os.environ["DUMP"], "w"))
