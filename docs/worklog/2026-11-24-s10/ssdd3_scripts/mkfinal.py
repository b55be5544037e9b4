"""mkfinal.py SRC DST: SRC's ssdd_lstm weights with level2.level1_input = "final" (the final level 1 feeds level 2)
and without the fold models. Level 2's training does not depend on level1_input (its validation loss only; the
trainer keeps the last epoch), so these are the weights a run with "final" would have written."""
import sys
from pathlib import Path
from methods.nn.checkpoint import load_tensors, save_tensors
src, dst = sys.argv[1:3]
f = load_tensors(Path(src) / "ssdd_lstm.safetensors", kind="weights")
meta = dict(f.meta)
meta["config"]["level2"]["level1_input"] = "final"
tensors = {k: v for k, v in f.tensors.items() if not k.startswith("level1_fold")}
Path(dst).mkdir(parents=True, exist_ok=True)
save_tensors(Path(dst) / "ssdd_lstm.safetensors", tensors, kind="weights", meta={k: v for k, v in meta.items() if k not in ("format", "format_version", "kind")})
print(dst, len(f.tensors), "->", len(tensors))
