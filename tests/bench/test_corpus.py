"""bench corpus: simulated sequences aligned on a local process pool, with a training manifest that reads back."""
import json

import pytest

from bench.corpus import CorpusSpec, make_corpus
from bench.errors import BenchError
from bench.executors import ExecutorSpec
from methods.nn.manifest import read_manifest


def test_corpus_of_two_sequences_on_two_processes(tmp_path):
    spec = CorpusSpec(seeds=(401, 402), scenes=("people", "balloons"), seconds=0.8, scale=0.5,
                      time_shifts_ms=(-20.0, 35.0), validation=1, probes=6, name="t", reports=False)
    res = make_corpus(tmp_path / "c", spec, executor=ExecutorSpec(jobs=2), progress=False)
    m = read_manifest(res.manifest)                      # every dataset present, checksums equal
    assert [e.split for e in m.entries] == ["train", "validation"]
    assert [e.info["scene"] for e in m.entries] == ["people", "balloons"]
    assert [e.info["time_shift_us"] for e in m.entries] == [-20000, 35000]
    for e in m.entries:
        truth = json.loads((e.dataset.root.parent.parent / "sessions" / e.dataset.root.name / "truth" /
                            "truth.json").read_text())
        assert truth["seed"] == e.info["seed"] and e.dataset.simulated
        # aligned by the alignment pipeline (its fit and report fields), not copied from the truth
        assert e.dataset.meta["alignment"]["program"] == "depthbench align" and len(e.dataset) > 10
        assert not (e.dataset.root / "report.md").exists()      # reports=False reaches the alignment
    assert not any(p.name.endswith(".partial") for p in tmp_path.iterdir())


def test_corpus_refuses_bad_specs_before_work(tmp_path):
    with pytest.raises(BenchError, match="none for training"):
        make_corpus(tmp_path / "c", CorpusSpec(seeds=(1, 2), validation=1, test=1))
    with pytest.raises(BenchError, match="unknown"):
        make_corpus(tmp_path / "c", CorpusSpec(scenes=("nope",)))
    with pytest.raises(BenchError, match="rig 'nope' unknown"):
        make_corpus(tmp_path / "c", CorpusSpec(rig="nope"))
    assert not (tmp_path / "c").exists()


def test_a_multiview_sequence_gives_one_manifest_dataset_per_view(tmp_path):
    from bench.corpus import _datasets

    single, multi = tmp_path / "single", tmp_path / "multi"
    single.mkdir()
    (single / "aligned.json").write_text("{}")
    for v in ("view1", "view0", "figures"):
        (multi / v).mkdir(parents=True)
    for v in ("view1", "view0"):
        (multi / v / "aligned.json").write_text("{}")
    (multi / "rig.json").write_text("{}")
    assert _datasets(single) == [single]
    assert _datasets(multi) == [multi / "view0", multi / "view1"]
