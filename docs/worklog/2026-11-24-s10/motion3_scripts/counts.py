"""Sample counts in SceneFlow's passes over 30 consecutive pairs (what the fill and the expansion work on)."""
import os, sys
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np, cv2
sys.path.insert(0, os.getcwd())
import align._flow_kernel as fk
import align.motion_flow as mf
import perf.reference_motion as rm
from align.motion import MotionReference
from align.pipeline import pair_setup
from align.reference_edges import EdgeRule
from align.warp import DepthWarper
from capture.session import open_session
from capture.truth import read_truth
stats = []
_fill, _exp = fk.fill_untrusted, fk.expand_blocks
def fill(out, trusted, offsets, dl, mj):
    before = out.copy()
    _fill(out, trusted, offsets, dl, mj)
    unt = (~trusted) & (dl > 0)
    filled = unt & (out != 0).any(axis=0)
    stats.append(dict(n=trusted.size, depth=int((dl > 0).sum()), trusted=int(trusted.sum()), untrusted=int(unt.sum()), filled=int(filled.sum())))
def exp(low, trusted, still, shift, dl, d, dx, R, grid, corner, scale, mj, out):
    _exp(low, trusted, still, shift, dl, d, dx, R, grid, corner, scale, mj, out)
    quiet = ~(low != 0).any(axis=0) & ~(trusted & ~still)
    st = stats[-1]
    st.update(still=int(still.sum()), quiet=int(quiet.sum()), pix=out.shape[1] * out.shape[2], moving_px=int((out != 0).any(axis=0).sum()))
    # heavy-path pixels: those not skipped by the still test (with depth), with the quiet test
    g0, h0, s = grid; r0, c0 = corner
    Y = np.arange(out.shape[1]) + r0; X = np.arange(out.shape[2]) + c0
    i = (Y - g0) // s; j = (X - h0) // s
    def allq(q):
        qp = np.pad(q, ((0, 1), (0, 1)), constant_values=True)
        wy = ((Y - g0) % s != 0)[:, None]; wx = ((X - h0) % s != 0)[None, :]
        a = qp[i][:, j]; b = qp[i][:, j + 1]; c = qp[i + 1][:, j]; e = qp[i + 1][:, j + 1]
        return a & (~wx | b) & (~wy | (c & (~wx | e)))
    z = d[r0:r0 + out.shape[1], c0:c0 + out.shape[2]] > 0
    st.update(heavy_still=int((z & ~allq(still)).sum()), heavy_quiet=int((z & ~allq(quiet)).sum()), zpix=int(z.sum()))
fk.fill_untrusted, fk.expand_blocks = fill, exp
sess, tr = open_session(sys.argv[1]), read_truth(sys.argv[1])
setup = pair_setup(sess, lq="lq", hq="hq")
warper = DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=EdgeRule.named("strict").edge_reach)
print("crop", warper.crop)
n = 30
depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
dt = 0.25 * float(np.median(np.diff(setup.t_hq)))
R = MotionReference(lambda i: warper(depth[i]), setup.t_hq, moved=rm._flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i]))
for i in range(n):
    R(i, dt)
keys = stats[0].keys()
print({k: int(np.mean([s[k] for s in stats])) for k in keys})
