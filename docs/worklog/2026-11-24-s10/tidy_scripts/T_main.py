"""fit_pair's T_ex with the code on PYTHONPATH (to compare the point estimate before/after): python T_main.py OUT.json SESSION..."""
import json, sys
import align.pipeline as P
from capture.session import open_session
out = {}
for root in sys.argv[2:]:
    sess = open_session(root)
    setup = P.pair_setup(sess, lq=sess.sensors_with_role("lq")[0], hq=sess.sensors_with_role("hq")[0])
    out[root] = P.fit_pair(setup, P.AlignOptions(progress=False, workers=1)).fit.T.matrix.tolist()
json.dump(out, open(sys.argv[1], "w"))
