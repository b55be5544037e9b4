"""bench_demo.py ALIGNED OUT: the demo's bench run (all methods, the demo's trained weights) on ALIGNED."""
import sys, time
from bench.runner import run_benchmark
from bench.metrics import MetricConfig
R = "/tmp/fp/demo/runs"
params = {"ddrnet": {"weights": f"{R}/ddrnet/ddrnet.safetensors"}, "ddrnet_refine": {"weights": f"{R}/ddrnet/ddrnet_refine.safetensors"},
          "ddd": {"weights": f"{R}/ddd/ddd.safetensors"}, "ssdd_unet": {"weights": f"{R}/ssdd/ssdd_unet.safetensors"},
          "ssdd_lstm": {"weights": f"{R}/ssdd/ssdd_lstm.safetensors"}}
t = time.process_time(); w = time.time()
run_benchmark([sys.argv[1]], "all", sys.argv[2], params=params, config=MetricConfig(radius_m=0.01), jobs=1, progress=False, force=True)
print(f"cpu {time.process_time() - t:.1f} s, wall {time.time() - w:.1f} s")
