import sys; sys.path.insert(0, "/work/notes/simtof")
sys.argv = [sys.argv[0], sys.argv[1]]
exec(open("/work/notes/simtof/sim_stat.py").read().split("for lo, hi in")[0])
for lo, hi in ((0.1, 0.2), (0.2, None)):
    run(f"recorded {S} {lo}-{hi}", rec, lo, hi, True)
