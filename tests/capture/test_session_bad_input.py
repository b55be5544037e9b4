"""Bad sessions through ``depthbench capture validate``: one line naming the file and problem, exit 2,
nothing written or changed."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.capture.sessionkit import tree_digest, write_source
from tests.conftest import assert_one_line_error


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _edit_table(root: Path, edit) -> Path:
    """Apply ``edit(list of row lists)`` to lq/frames.csv and keep session.json's checksum of it in step."""
    table = root / "lq" / "frames.csv"
    lines = table.read_text().splitlines()
    rows = [line.split(",") for line in lines[1:]]
    edit(rows)
    table.write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n")
    m = json.loads((root / "session.json").read_text())
    m["checksums"]["lq/frames.csv"] = _sha(table)
    (root / "session.json").write_text(json.dumps(m))
    return table


def _replace_frame(root: Path, rel: str, data: bytes) -> Path:
    """Overwrite a frame file and update its sha256 in the table, so only the content is wrong."""
    path = root / rel
    path.write_bytes(data)
    _edit_table(root, lambda rows: [r.__setitem__(5, hashlib.sha256(data).hexdigest()) for r in rows if r[4] == rel])
    return path


def _png(img) -> bytes:
    return cv2.imencode(".png", img)[1].tobytes()


def truncated_png(root):
    rel = "lq/depth/00000001.png"
    return _replace_frame(root, rel, (root / rel).read_bytes()[:-40]), "truncated PNG"


def eight_bit_depth(root):
    return _replace_frame(root, "lq/depth/00000001.png", _png(np.full((48, 64), 9, np.uint8))), "16-bit"


def wrong_size(root):
    return _replace_frame(root, "lq/depth/00000001.png", _png(np.full((24, 32), 900, np.uint16))), \
        "frame is 32x24, stream is 64x48"


def missing_intrinsic(root):
    m = json.loads((root / "session.json").read_text())
    del m["sensors"]["lq"]["streams"]["depth"]["intrinsics"]["fx"]
    (root / "session.json").write_text(json.dumps(m))
    return root / "session.json", "'fx' is a required property"


def timestamps_backwards(root):
    def edit(rows):
        depth = [r for r in rows if r[0] == "depth"]
        depth[2][3] = str(int(depth[1][3]) - 1)
    return _edit_table(root, edit), "host_timestamp_us goes backwards"


def checksum_mismatch(root):
    path = root / "lq/color/00000002.png"
    path.write_bytes(_png(np.zeros((48, 64, 3), np.uint8)))  # a valid image, but not the one indexed
    return path, "checksum mismatch"


def path_escapes(root):
    (root.parent / "outside.png").write_bytes(_png(np.ones((48, 64), np.uint16)))
    def edit(rows):
        rows[0][4] = "../outside.png"
    return _edit_table(root, edit), "escapes the folder"


def absolute_path(root):
    def edit(rows):
        rows[0][4] = str((root / "lq/depth/00000000.png").resolve())
    return _edit_table(root, edit), "must be relative"


def unknown_version(root):
    m = json.loads((root / "session.json").read_text())
    m["format_version"] = "2.0"
    (root / "session.json").write_text(json.dumps(m))
    return root / "session.json", "unknown format version '2.0'"


def partial_row(root):
    table = root / "lq" / "frames.csv"
    with open(table, "a") as f:
        f.write("depth,77,1,2,lq/de")
    m = json.loads((root / "session.json").read_text())
    m["checksums"]["lq/frames.csv"] = _sha(table)
    (root / "session.json").write_text(json.dumps(m))
    return table, "expected 6 fields"


CASES = [truncated_png, eight_bit_depth, wrong_size, missing_intrinsic, timestamps_backwards, checksum_mismatch,
         path_escapes, absolute_path, unknown_version, partial_row]


@pytest.mark.parametrize("corrupt", CASES, ids=[c.__name__ for c in CASES])
def test_bad_session_is_one_line_error(tmp_path, cli, corrupt):
    root = tmp_path / "s"
    write_source(root, n=3, sensors=("lq",))
    bad_file, problem = corrupt(root)
    before = tree_digest(tmp_path)
    result = cli("capture", "validate", root)
    assert_one_line_error(result, str(bad_file), problem)
    assert tree_digest(tmp_path) == before  # nothing written, nothing changed


def test_missing_folder_and_missing_manifest(tmp_path, cli):
    assert_one_line_error(cli("capture", "validate", tmp_path / "nope"), str(tmp_path / "nope"), "not a session folder")
    (tmp_path / "empty").mkdir()
    assert_one_line_error(cli("capture", "validate", tmp_path / "empty"), "session.json", "missing")
