"""Crash-safe file output shared by every stage.

* Files are written to a temporary name in the same folder and renamed into place, so a
  reader never sees half a file.
* Output folders are built under a temporary sibling name and renamed when complete; an
  existing output is only replaced with ``force=True``.
* Paths read from files are resolved with :func:`safe_join`, which refuses to leave the folder.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from depthbench.errors import OutputExistsError, UnsafePathError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _publishable(path: Path, *, directory: bool) -> None:
    """Give a temporary file/folder the permissions a plain ``open``/``mkdir`` would have.

    ``mkstemp``/``mkdtemp`` create 0600/0700 entries; renamed into place they would make every
    output private to its writer. Outputs follow the user's umask instead."""
    os.chmod(path, (0o777 if directory else 0o666) & ~_umask())


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, fsync: bool = False) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        _publishable(Path(tmp), directory=False)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str, *, fsync: bool = False) -> None:
    atomic_write_bytes(path, text.encode("utf-8"), fsync=fsync)


def atomic_write_json(path: str | os.PathLike, obj, *, fsync: bool = False) -> None:
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n", fsync=fsync)


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds.

    For writers that want a file name (``cv2.imwrite``, ``DataFrame.to_parquet``)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        _publishable(Path(tmp), directory=False)
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def read_json(path: str | os.PathLike, *, error: type[Exception], missing: str, invalid_note: str = ""):
    """Parse the JSON file ``path``; raise ``error`` with one line naming it when it is missing
    (``"PATH: missing ..."`` with the ``missing`` explanation) or not JSON (plus ``invalid_note``)."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise error(f"{path}: missing{missing}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not valid JSON ({exc}){invalid_note}") from None


def check_output_free(path: str | os.PathLike, *, force: bool, what: str = "output") -> None:
    """Raise :class:`OutputExistsError` if ``path`` exists (a non-empty folder or a file) and not ``force``."""
    path = Path(path)
    if force or not path.exists():
        return
    if path.is_dir() and not any(path.iterdir()):
        return
    raise OutputExistsError(f"{path}: {what} exists; pass --force to replace it")


def staging_dir_for(path: str | os.PathLike) -> Path:
    """A new hidden sibling folder ``.NAME.XXXX.partial`` to build ``path`` in (umask permissions)."""
    path = Path(path)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent))
    _publishable(tmp, directory=True)
    return tmp


@contextlib.contextmanager
def staged_directory(path: str | os.PathLike, *, force: bool = False, what: str = "output") -> Iterator[Path]:
    """Build a folder under a temporary sibling name and publish it as ``path`` on success.

    On an exception the temporary folder is removed and ``path`` is left as it was. With
    ``force`` an existing ``path`` is replaced only after the new one is complete.
    """
    path = Path(path)
    check_output_free(path, force=force, what=what)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = staging_dir_for(path)
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    publish_directory(tmp, path)


def publish_directory(tmp: str | os.PathLike, path: str | os.PathLike) -> Path:
    """Rename a completed staging folder onto ``path``, replacing what is there only now.

    The old ``path`` is moved aside first and removed after the rename, so ``path`` is at every
    moment either the old complete output or the new one."""
    tmp, path = Path(tmp), Path(path)
    old = None
    if path.exists():
        old = path.parent / f".{path.name}.old-{os.getpid()}"
        os.replace(path, old)
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True) if old.is_dir() else old.unlink()
    return path


def safe_join(root: str | os.PathLike, relative: str, *, source: str | os.PathLike | None = None) -> Path:
    """Resolve ``relative`` (read from a file) inside ``root``; refuse absolute paths and escapes.

    ``source`` names the file the path came from, for the error message.
    """
    where = f"{source}: " if source is not None else ""
    rel = str(relative)
    if not rel or os.path.isabs(rel) or rel.startswith(("/", "\\")) or "\x00" in rel:
        raise UnsafePathError(f"{where}path {rel!r} must be relative to {root}")
    root_resolved = Path(root).resolve()
    target = (root_resolved / rel).resolve()
    if target != root_resolved and root_resolved not in target.parents:
        raise UnsafePathError(f"{where}path {rel!r} escapes the folder {root}")
    return target
