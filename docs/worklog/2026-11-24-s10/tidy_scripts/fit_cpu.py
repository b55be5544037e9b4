"""CPU seconds of fit_pair with the code on PYTHONPATH: python fit_cpu.py SESSION..."""
import sys, time
import align.pipeline as P
from capture.session import open_session
for root in sys.argv[1:]:
    sess = open_session(root)
    setup = P.pair_setup(sess, lq=sess.sensors_with_role("lq")[0], hq=sess.sensors_with_role("hq")[0])
    t = time.process_time()
    P.fit_pair(setup, P.AlignOptions(progress=False, workers=1))
    print(root, f"{time.process_time() - t:.2f}")
