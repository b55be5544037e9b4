import sys, json
import align.loop.run as R
sys.argv = [sys.argv[0]] + sys.argv[1:]
exec(open('/work/notes/loopref/measure.py').read().replace('for refine in (False, True):', 'for refine in (False, True, "rr"):').replace(
 'lr = close_loop(setup, pf, refine=refine)', 'R.REREFINE_LENS = refine == "rr"; lr = close_loop(setup, pf, refine=bool(refine))').replace(
 'rec["refine" if refine else "sift"]', 'rec[{False: "sift", True: "refine", "rr": "rerefine"}[refine]]'))
