"""An ``--out`` inside the input (or holding it) is refused before anything is read or written:
one line, exit 2, the input byte-identical, no output created. One shared check
(``depthbench.fsutil.check_output_outside``) behind ``capture import``, ``align``, ``methods run``
and ``bench run``."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from depthbench.errors import OutputInsideInputError
from depthbench.fsutil import check_output_outside
from tests.bench.helpers import make_dataset
from tests.capture.inproc_cli import run_inproc
from tests.capture.sessionkit import tree_digest, write_source
from tests.conftest import assert_one_line_error


def test_the_check_by_itself(tmp_path):
    inp = tmp_path / "in"
    inp.mkdir()
    (tmp_path / "link").symlink_to(inp)
    for out in (inp, inp / "out", inp / "a" / "b", tmp_path / "link" / "out", tmp_path):
        with pytest.raises(OutputInsideInputError, match="input"):
            check_output_outside(out, [tmp_path / "elsewhere", inp])
    for out in (tmp_path / "out", tmp_path / "in2", tmp_path / "in.out"):
        check_output_outside(out, [inp])                  # siblings are fine


@pytest.fixture(scope="module")
def tum(tmp_path_factory):
    root = tmp_path_factory.mktemp("tum") / "fr1"
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    rng = np.random.default_rng(0)
    for i, t in enumerate(("1.000000", "1.033333")):
        cv2.imwrite(str(root / "depth" / f"{t}.png"), rng.integers(4000, 9000, (48, 64)).astype(np.uint16))
        cv2.imwrite(str(root / "rgb" / f"{t}.png"), rng.integers(0, 255, (48, 64, 3)).astype(np.uint8))
    for kind, folder in (("depth", "depth"), ("rgb", "rgb")):
        (root / f"{kind}.txt").write_text("# timestamp filename\n1.000000 {0}/1.000000.png\n1.033333 {0}/1.033333.png\n"
                                          .format(folder))
    return root


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp("sess") / "S"
    write_source(root, n=3)
    return root


@pytest.fixture(scope="module")
def aligned(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("al") / "A", frames=2)


def _refused(capfd, inp, out, *argv):
    before = tree_digest(inp)
    r = run_inproc(capfd, *argv)
    assert_one_line_error(r, str(out), "inside the input" if str(out).startswith(str(inp)) else "contain the input")
    assert tree_digest(inp) == before
    assert not out.exists() or out == inp.parent


def test_capture_import_tum(tum, tmp_path, capfd):
    ok = run_inproc(capfd, "capture", "import", "tum", tum, "--out", tmp_path / "ok", "--quiet",
                    "--size", "64x48")
    assert ok.returncode == 0, ok.stderr                         # the folder itself imports
    _refused(capfd, tum, tum / "session", "capture", "import", "tum", tum, "--out", tum / "session", "--quiet")
    _refused(capfd, tum, tum.parent, "capture", "import", "tum", tum, "--out", tum.parent, "--force", "--quiet")


def test_align(session, capfd):
    _refused(capfd, session, session / "aligned", "align", session, "--out", session / "aligned", "--no-progress")
    _refused(capfd, session, session.parent, "align", session, "--out", session.parent, "--force", "--no-progress")


def test_methods_run(aligned, capfd):
    _refused(capfd, aligned, aligned / "d", "methods", "run", "raw", "--data", aligned, "--out", aligned / "d",
             "--no-progress")


def test_bench_run(aligned, tmp_path, capfd):
    other = make_dataset(tmp_path / "B", frames=1, seed=3)
    _refused(capfd, aligned, aligned / "r", "bench", "run", "--data", other, "--data", aligned, "--methods", "raw",
             "--out", aligned / "r")
