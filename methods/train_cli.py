"""``depthbench methods train``: train a learned method into a run folder (thin parser around
:func:`methods.nn.train.train_method`).

    depthbench methods train NAME --dataset MANIFEST --config tiny|paper|FILE.toml --out RUN
                             [--device auto|cpu|cuda] [--resume] [--force] [--no-progress]

Multi-process: ``torchrun --nproc_per_node N -m depthbench methods train ...`` (gloo on CPU,
NCCL on GPU); the global batch is the config's ``batch_size`` whatever N.
"""
from __future__ import annotations


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "train", help="train a learned method (e.g. ssdd_unet, ssdd_lstm) on a training manifest",
        description="Train method NAME on the aligned datasets of a training manifest (data_manifests/training.md) "
                    "with a config (built-in name or TOML file). Writes RUN/<method>.safetensors (weights for "
                    "'--param weights=...'), config.toml, run.json, and per network a checkpoint, history.csv and "
                    "curves.png. Under torchrun the processes train together (DistributedDataParallel).",
        epilog="Example: depthbench methods train ssdd_lstm --dataset corpus/training.json --config tiny --out runs/ssdd")
    p.add_argument("name", help="method to train (ssdd_unet: level 1 only; ssdd_lstm: both levels)")
    p.add_argument("--dataset", required=True, help="training manifest (JSON, data_manifests/training.md)")
    p.add_argument("--config", required=True, help="built-in config name (tiny, paper) or a .toml file")
    p.add_argument("--out", required=True, help="run folder (refused if it exists, unless --resume or --force)")
    p.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda, cuda:N (default: auto)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoints")
    p.add_argument("--force", action="store_true", help="replace an existing run folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run_train)


def run_train(args) -> int:
    from methods.errors import TrainingError
    from methods.nn.train import train_method

    if args.resume and args.force:
        raise TrainingError("give --resume or --force, not both")
    result = train_method(args.name, dataset=args.dataset, config=args.config, out=args.out, device=args.device,
                          resume=args.resume, force=args.force, progress=not args.no_progress)
    import os

    if int(os.environ.get("RANK", "0")) == 0:
        for method, path in result.weights.items():
            print(f"{method}: {path}")
        print(f"trained in {result.seconds:.0f} s; run folder {result.out} (curves: */curves.png)")
    return 0
