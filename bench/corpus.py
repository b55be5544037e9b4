"""A training corpus from the simulator: several seeds, people and balloons, different time shifts,
each simulated and aligned exactly as a benchmark session, on the benchmark's executors.

``depthbench bench corpus --out C --seeds 101-106 --validation 1 --test 1`` writes::

    C/
      sessions/<name>/     the simulated sessions (with truth/, as 'capture simulate' writes them)
      aligned/<name>/      their aligned datasets (as 'align' writes them; truth attached, the fit never reads it)
      training.json        the training manifest (data_manifests/training.md): every aligned dataset,
                           its checksum and its split; the last ``test`` sequences are test, the ``validation``
                           before them validation, the rest train

One task per sequence (simulate, then align) runs wherever the :class:`bench.executors.ExecutorSpec`
says: this process, local processes, or a Dask cluster (paths must be shared), so a lab can make an
SSDD-size corpus (51 sequences of 30 s) on a cluster. The folder is built aside and published when
every sequence is done: a failure leaves nothing.

The references of an ``lq-hq`` corpus are carried to the LQ instant with the ``flow`` motion model
(:mod:`align.motion_flow`; align's default too since session 13) unless ``motion_model`` says otherwise: they are
what SSDD's eq. 32 trains against, and on moving surfaces the ``edges`` step left them much further from the truth (one people sequence
16 ms apart, reference - truth on moving pixels inside surfaces: +3.18 mm / 41.8 mm2 with ``edges``, +2.01 mm /
14.7 mm2 with ``flow``; session 8's lead measurement, re-measured on corpora in docs/worklog, session 9).

``rig`` ``multiview4`` / ``multiview4-hq`` makes DDD's self-supervision corpus instead: four-view sessions
aligned by the suite's multi-view alignment (``aligned/<name>/rig.json`` plus ``view0`` ... ``view3``),
one manifest entry per view; a static-looking scene leaves the views' time shifts unobservable, which is
flagged (placeholder shift 0, as ``align --allow-unobservable``) rather than refused.
"""
from __future__ import annotations

import dataclasses
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from bench.errors import BenchError
from bench.executors import ExecutorSpec
from depthbench.fsutil import check_output_free, publish_directory, staging_dir_for

MANIFEST = "training.json"
#: the motion model of an lq-hq corpus's references unless the spec names one (see the module docstring)
TRAINING_MOTION_MODEL = "flow"


@dataclass(frozen=True)
class CorpusSpec:
    """What to simulate: one sequence per seed; scenes and time shifts are cycled over the seeds.

    ``time_shifts_ms``: empty = drawn by the simulator within +-55 ms from each seed. ``scale``:
    image size factor (0.5: 320x240 LQ). ``validation`` / ``test``: sequences in those splits.
    ``probes``: HQ frames the alignment fits (None: its default). ``reports``: each sequence's
    alignment report (Markdown and figures, a few CPU-seconds per sequence). ``motion_model``: the
    alignment's motion step for the references (None: ``flow`` for the ``lq-hq`` rig, the training
    corpora of SSDD and DDRNet; the alignment's own default for multi-view rigs). ``reference_edges``:
    the alignment's reference edge rule (None: its default; :mod:`align.reference_edges`).
    """

    seeds: tuple[int, ...] = (101, 102, 103, 104, 105)
    scenes: tuple[str, ...] = ("people", "balloons")
    seconds: float = 3.0
    scale: float = 0.5
    time_shifts_ms: tuple[float, ...] = ()
    validation: int = 1
    test: int = 0
    probes: int | None = None
    name: str = "sim-corpus"
    rig: str = "lq-hq"
    reports: bool = True
    motion_model: str | None = None
    reference_edges: str | None = None

    def check(self) -> "CorpusSpec":
        from align.pair_reference import MOTION_MODELS
        from align.reference_edges import RULES
        from capture.sim import RIGS, SCENES

        if self.rig not in RIGS:
            raise BenchError(f"rig {self.rig!r} unknown (choose from {', '.join(RIGS)})")
        if not self.seeds or len(set(self.seeds)) != len(self.seeds) or min(self.seeds) < 0:
            raise BenchError(f"seeds must be distinct non-negative integers, got {list(self.seeds)}")
        bad = [s for s in self.scenes if s not in SCENES]
        if not self.scenes or bad:
            raise BenchError(f"scene {bad[0] if bad else ''!r} unknown (choose from {', '.join(SCENES)})")
        if self.seconds <= 0 or self.scale <= 0:
            raise BenchError(f"seconds and scale must be positive, got {self.seconds}, {self.scale}")
        if self.motion_model is not None and self.motion_model not in MOTION_MODELS:
            raise BenchError(f"motion model {self.motion_model!r} unknown (choose from {', '.join(MOTION_MODELS)})")
        if self.reference_edges is not None and self.reference_edges not in RULES:
            raise BenchError(f"reference edge rule {self.reference_edges!r} unknown (choose from {', '.join(RULES)})")
        if self.validation < 0 or self.test < 0 or self.validation + self.test >= len(self.seeds):
            raise BenchError(f"{len(self.seeds)} sequences leave none for training with {self.validation} "
                             f"validation and {self.test} test sequences")
        return self

    def splits(self) -> list[str]:
        n = len(self.seeds)
        n_train = n - self.validation - self.test
        return ["train"] * n_train + ["validation"] * self.validation + ["test"] * self.test

    def resolved_motion_model(self) -> str | None:
        """The motion model the alignments use (None: the alignment's default)."""
        if self.motion_model is not None:
            return self.motion_model
        return TRAINING_MOTION_MODEL if self.rig == "lq-hq" else None


@dataclass(frozen=True)
class SequenceTask:
    """Simulate one session and align it (module-level data: travels to worker processes)."""

    seed: int
    scene: str
    seconds: float
    scale: float
    time_shift_us: int | None
    session: str
    aligned: str
    probes: int | None = None
    rig: str = "lq-hq"
    report: bool = True
    motion_model: str | None = None
    reference_edges: str | None = None


def build_sequence(task: SequenceTask) -> dict:
    """The task function: simulate + align; returns what the manifest records about the sequence."""
    from align.pipeline import align_session
    from capture.sim import simulate

    sim = simulate(task.session, rig=task.rig, scene=task.scene, seconds=task.seconds, seed=task.seed,
                   time_shift_us=task.time_shift_us, scale=task.scale, progress=False, workers=1)
    opts = {"progress": False, "workers": 1, "report": task.report,
            **({} if task.rig == "lq-hq" else {"on_unobservable": "flag"})}
    if task.probes is not None:
        opts["probes"] = task.probes
    if task.motion_model is not None:
        opts["motion_model"] = task.motion_model
    if task.reference_edges is not None:
        opts["reference_edges"] = task.reference_edges
    align_session(task.session, task.aligned, **opts)
    return {"scene": task.scene, "seed": task.seed, "time_shift_us": int(sim.time_shift_us)}


def _tasks(spec: CorpusSpec, work: Path) -> list[SequenceTask]:
    out = []
    for i, seed in enumerate(spec.seeds):
        scene = spec.scenes[i % len(spec.scenes)]
        shift = round(spec.time_shifts_ms[i % len(spec.time_shifts_ms)] * 1000) if spec.time_shifts_ms else None
        name = f"{scene}-seed{seed}"
        out.append(SequenceTask(seed=seed, scene=scene, seconds=spec.seconds, scale=spec.scale, time_shift_us=shift,
                                session=str(work / "sessions" / name), aligned=str(work / "aligned" / name),
                                probes=spec.probes, rig=spec.rig, report=spec.reports,
                                motion_model=spec.resolved_motion_model(), reference_edges=spec.reference_edges))
    return out


def _datasets(aligned: Path) -> list[Path]:
    """The aligned datasets of one sequence: itself, or a multi-view alignment's per-view folders."""
    if (aligned / "aligned.json").is_file():
        return [aligned]
    return sorted(p for p in aligned.iterdir() if (p / "aligned.json").is_file())


@dataclass
class CorpusResult:
    out: Path
    manifest: Path
    sequences: int


def make_corpus(out: str | Path, spec: CorpusSpec = CorpusSpec(), *, executor: ExecutorSpec = ExecutorSpec(jobs=1),
                force: bool = False, progress: bool | None = None) -> CorpusResult:
    """Simulate and align ``spec``'s sequences into ``out`` with a training manifest; see the module docstring."""
    from align.dataset import AlignedDataset
    from methods.nn.manifest import manifest_entry, write_manifest

    spec.check()
    executor.check()
    out = Path(out)
    check_output_free(out, force=force, what="corpus folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    work = staging_dir_for(out)
    try:
        tasks = _tasks(spec, work)
        (work / "sessions").mkdir()
        (work / "aligned").mkdir()
        info: dict[int, dict] = {}
        bar = tqdm(total=len(tasks), desc="corpus", unit="sequence", file=sys.stderr,
                   disable=(None if progress is None else not progress))

        def done(task: SequenceTask, result: dict) -> None:
            info[task.seed] = result
            bar.update(1)

        try:
            executor.make(len(tasks)).run(tasks, done, fn=build_sequence, key=lambda t: f"corpus-seed{t.seed}")
        finally:
            bar.close()
        entries = [manifest_entry(AlignedDataset(root), root=work, split=split, **info[t.seed])
                   for t, split in zip(tasks, spec.splits()) for root in _datasets(Path(t.aligned))]
        write_manifest(work / MANIFEST, name=spec.name, entries=entries,
                       created={"program": "depthbench bench corpus", "options": dataclasses.asdict(spec)})
        publish_directory(work, out)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    return CorpusResult(out, out / MANIFEST, len(tasks))
