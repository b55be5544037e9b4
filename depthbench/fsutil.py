"""Crash-safe file output shared by every stage.

* Files are written to a temporary name in the same folder and renamed into place, so a
  reader never sees half a file.
* Output folders are built under a temporary sibling name and renamed when complete; an
  existing output is only replaced with ``force=True``.
* Paths read from files are resolved with :func:`safe_join`, which refuses to leave the folder.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import secrets
import shutil
from pathlib import Path
from typing import Iterator

from depthbench.errors import OutputExistsError, OutputInsideInputError, UnsafePathError


_OPEN_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)


def _new_sibling(path: Path, *, prefix: str, suffix: str, directory: bool = False) -> tuple[int | None, Path]:
    """Create a new hidden file (or folder) ``PREFIX<random>SUFFIX`` beside ``path``.

    Created with mode 0666 (folders 0777) so the kernel applies the user's umask: published
    outputs get the permissions a plain ``open``/``mkdir`` would give (``tempfile`` makes them
    private), without reading the umask, which is not thread-safe. Returns ``(fd or None, path)``."""
    for _ in range(100):
        tmp = path.parent / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            if directory:
                os.mkdir(tmp, 0o777)
                return None, tmp
            return os.open(tmp, _OPEN_FLAGS, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(path))  # pragma: no cover


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
    fd, tmp = _new_sibling(path, prefix=f".{path.name}.", suffix=".tmp")
    try:
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
    fd, tmp = _new_sibling(path, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield tmp
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
    except OSError as exc:   # no permission, a folder, a folder on the way that is a file...
        raise error(f"{path}: cannot be read ({exc.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not valid JSON ({exc}){invalid_note}") from None


def check_output_free(path: str | os.PathLike, *, force: bool, what: str = "output") -> None:
    """Raise :class:`OutputExistsError` if ``path`` exists (a non-empty folder or a file) and not ``force``
    (the command line adds how to replace it)."""
    path = Path(path)
    if force or not path.exists():
        return
    if path.is_dir() and not any(path.iterdir()):
        return
    raise OutputExistsError(f"{path}: {what} exists")


def check_output_outside(path: str | os.PathLike, inputs, *, what: str = "output") -> None:
    """Raise :class:`OutputInsideInputError` if the output ``path`` is one of ``inputs`` (files or
    folders), lies inside one (writing into the input), or contains one (replacing it would delete
    the input). Paths are compared resolved (symbolic links followed); nothing needs to exist."""
    out = Path(path).resolve()
    for given in inputs:
        inp = Path(given).resolve()
        if out == inp or inp in out.parents:
            raise OutputInsideInputError(f"{path}: the {what} would be inside the input {given}; choose a folder "
                                         "outside it")
        if out in inp.parents:
            raise OutputInsideInputError(f"{path}: the {what} would contain the input {given}; choose a folder "
                                         "that does not hold the input")


def free_bytes(path: str | os.PathLike) -> int:
    """Bytes free for this user on the file system that holds ``path`` (or would: the nearest
    existing folder above it is asked)."""
    p = Path(path).resolve()
    while not p.exists() and p != p.parent:
        p = p.parent
    return shutil.disk_usage(p).free


def human_bytes(n: float) -> str:
    """``n`` bytes as a short decimal figure: ``"4.2 GB"``."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1000
    raise AssertionError  # pragma: no cover


def staging_dir_for(path: str | os.PathLike) -> Path:
    """A new hidden sibling folder ``.NAME.XXXX.partial`` to build ``path`` in (umask permissions)."""
    return _new_sibling(Path(path), prefix=f".{Path(path).name}.", suffix=".partial", directory=True)[1]


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


def safe_join(root: str | os.PathLike, relative: str, *, source: str | os.PathLike | None = None,
              error: type[Exception] = UnsafePathError) -> Path:
    """Resolve ``relative`` (read from a file) inside ``root``; refuse absolute paths and escapes.

    ``source`` names the file the path came from, for the error message; ``error`` is the
    exception type raised (default :class:`UnsafePathError`; readers pass their format error).
    """
    where = f"{source}: " if source is not None else ""
    rel = str(relative)
    if not rel or os.path.isabs(rel) or rel.startswith(("/", "\\")) or "\x00" in rel:
        raise error(f"{where}path {rel!r} must be relative to {root}")
    root_resolved = Path(root).resolve()
    target = (root_resolved / rel).resolve()
    if target != root_resolved and root_resolved not in target.parents:
        raise error(f"{where}path {rel!r} escapes the folder {root}")
    return target
