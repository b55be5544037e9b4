"""Dump expand_blocks' / fill's inputs over 30 pairs (DUMP=1), or time kernels on the dump.
PYTHONPATH=checkout python kexp.py dump SESSION  |  python kexp.py time [MODULE_FILE]"""
import os, sys, pickle, time
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
import numpy as np
sys.path.insert(0, os.getcwd())
P = "/tmp/m3/kexp_inputs.pkl"
if sys.argv[1] == "dump":
    import align._flow_kernel as fk
    import perf.reference_motion as rm
    from align.motion import MotionReference
    from align.pipeline import pair_setup
    from align.reference_edges import EdgeRule
    from align.warp import DepthWarper
    from capture.session import open_session
    from capture.truth import read_truth
    rec = {"expand": [], "fill": []}
    _e, _f = fk.expand_blocks, fk.fill_untrusted
    def e(*a):
        rec["expand"].append([x.copy() if isinstance(x, np.ndarray) else x for x in a]); return _e(*a)
    def f(*a):
        rec["fill"].append([x.copy() if isinstance(x, np.ndarray) else x for x in a]); return _f(*a)
    fk.expand_blocks, fk.fill_untrusted = e, f
    sess, tr = open_session(sys.argv[2]), read_truth(sys.argv[2])
    setup = pair_setup(sess, lq="lq", hq="hq")
    warper = DepthWarper(setup.K_hq, setup.K_lq, tr.T_lq_hq, edge_reach=EdgeRule.named("strict").edge_reach)
    n = 30
    depth = [sess.read_depth("hq", int(setup.f_hq[i])) for i in range(n + 1)]
    color = [sess.read_color(setup.hq, int(setup.f_hq_c[setup.hq_color_of_depth[i]])) for i in range(n + 1)]
    dt = 0.25 * float(np.median(np.diff(setup.t_hq)))
    R = MotionReference(lambda i: warper(depth[i]), setup.t_hq, moved=rm._flow_motion(setup, warper, lambda i: depth[i], lambda i: color[i]))
    for i in range(n):
        R(i, dt)
    pickle.dump(rec, open(P, "wb"))
    sys.exit()
import importlib.util
rec = pickle.load(open(P, "rb"))
mods = []
for path in sys.argv[2:]:
    spec = importlib.util.spec_from_file_location(os.path.basename(path)[:-3], path)
    m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); mods.append((path, m))
def run_expand(m):
    outs = []
    for a in rec["expand"]:
        a = list(a); out = a[-1] if os.environ.get("REUSE") else np.empty_like(a[-1]); a[-1] = out
        m.expand_blocks(*a); outs.append(out)
    return outs
def run_fill(m):
    outs = []
    for a in rec["fill"]:
        a = list(a); a[0] = a[0].copy(); m.fill_untrusted(*a); outs.append(a[0])
    return outs
for name, fn in (("expand", run_expand), ("fill", run_fill)):
    ref = None
    res = {}
    for path, m in mods:
        o = fn(m)
        if ref is None: ref = o
        same = all(np.array_equal(x, y, equal_nan=True) for x, y in zip(ref, o))
        nd = sum(int((~((x == y) | (np.isnan(x) & np.isnan(y)))).sum()) for x, y in zip(ref, o))
        res[path] = [same, nd, []]
    for r in range(7):
        for path, m in mods:
            c = time.process_time(); fn(m); res[path][2].append((time.process_time() - c) / len(rec[name]) * 1e3)
    for path, (same, nd, t) in res.items():
        print(f"{name} {os.path.basename(path)}: {min(t):.3f} ms/pair (median {np.median(t):.3f}); same as first: {same} ({nd} values differ)")
