"""``depthbench capture validate`` on a session it cannot read: one line naming the file and the
reason, exit 2, nothing changed, never a traceback.

The case users meet is a frame folder without read permission. Permissions do not stop root, and
the tests run as root in CI, so that case runs the command as user ``nobody`` when the tests are
root; the same code path (an ``OSError`` on the way to a frame) is also exercised in-process by
entries that no user can read as files: a file where the frame folder should be, a folder or a
FIFO where a frame file should be, a folder in place of ``frames.csv`` or ``session.json``.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.capture.inproc_cli import run_inproc
from tests.capture.sessionkit import tree_digest, write_source
from tests.conftest import CliResult, assert_one_line_error

def _frame_folder_is_a_file(root: Path) -> tuple[Path, str]:
    shutil.rmtree(root / "lq" / "depth")
    (root / "lq" / "depth").write_text("not a folder")
    return root / "lq" / "depth" / "00000000.png", "cannot be read (Not a directory)"


def _frame_is_a_folder(root: Path) -> tuple[Path, str]:
    path = root / "hq" / "color" / "00000001.png"
    path.unlink()
    path.mkdir()
    return path, "not a regular file"


def _frame_is_a_fifo(root: Path) -> tuple[Path, str]:
    path = root / "lq" / "color" / "00000002.png"
    path.unlink()
    os.mkfifo(path)                    # opening it would block the reader forever
    return path, "not a regular file"


def _table_is_a_folder(root: Path) -> tuple[Path, str]:
    path = root / "hq" / "frames.csv"
    path.unlink()
    path.mkdir()
    return path, "cannot be read (Is a directory)"


def _manifest_is_a_folder(root: Path) -> tuple[Path, str]:
    path = root / "session.json"
    path.unlink()
    path.mkdir()
    return path, "cannot be read (Is a directory)"


CASES = [_frame_folder_is_a_file, _frame_is_a_folder, _frame_is_a_fifo, _table_is_a_folder, _manifest_is_a_folder]


@pytest.mark.parametrize("damage", CASES, ids=[c.__name__.strip("_") for c in CASES])
def test_unreadable_entries_are_one_line_errors(tmp_path, capfd, damage):
    root = tmp_path / "S"
    write_source(root, n=3)
    bad, problem = damage(root)
    before = tree_digest(root)
    r = run_inproc(capfd, "capture", "validate", root)
    assert_one_line_error(r, str(bad), problem)
    assert tree_digest(root) == before and sorted(os.listdir(tmp_path)) == ["S"]


#: Root without the capabilities that let it ignore permissions (util-linux ``setpriv``).
_NO_DAC = ["setpriv", "--inh-caps=-dac_override,-dac_read_search", "--bounding-set=-dac_override,-dac_read_search"]


def test_frame_folder_without_read_permission(tmp_path):
    """The reported case, run as a user whom the permissions stop: when the tests run as root, as
    root without CAP_DAC_OVERRIDE / CAP_DAC_READ_SEARCH (then the folder's mode applies to it too)."""
    prefix = []
    if os.geteuid() == 0:
        if shutil.which("setpriv") is None:
            pytest.skip("running as root and util-linux 'setpriv' is missing: permissions would not stop root "
                        "(the in-process cases above test the same code path)")
        prefix = _NO_DAC
    root = tmp_path / "S"
    write_source(root, n=3)
    folder = root / "lq" / "depth"
    before = tree_digest(root)
    os.chmod(folder, 0)
    try:
        p = subprocess.run([*prefix, sys.executable, "-m", "depthbench", "capture", "validate", str(root)],
                           capture_output=True, text=True, timeout=300)
    finally:
        os.chmod(folder, 0o755)
    assert_one_line_error(CliResult(p.returncode, p.stdout, p.stderr), str(folder), "Permission denied")
    assert tree_digest(root) == before
