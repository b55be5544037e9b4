"""Timestamp association between the HQ and LQ streams (seed report eq. 28 and TUM's ``associate.py``).

Pure numpy, no I/O. Timestamps are ``int64`` microseconds on the session's time base. The time
shift follows the suite's convention (``truth.json``, ``aligned.json``): an instant the HQ sensor
stamps ``t`` is stamped ``t + time_shift_us`` by the LQ sensor, so HQ frame ``i`` belongs with the
LQ frame whose stamp is nearest to ``t_hq[i] + time_shift_us``.

Two associations are offered:

* :func:`nearest_mapping` -- eq. 28, ``Phi(i) = argmin_j |t_LQ^j - (t_HQ^i + Delta)|`` for every HQ
  frame, vectorised with ``searchsorted`` (O(N log M)); several HQ frames may map to one LQ frame.
* :func:`associate_greedy` -- the greedy one-to-one matching of the TUM RGB-D benchmark's
  ``associate.py``: all pairs closer than ``max_difference`` sorted by difference, taken in that order
  unless one of their frames is already taken. Same pairs as TUM's script on the same lists
  (TUM adds ``offset`` to the *second* list: ``|a - (b + offset)|``; here ``a`` = LQ, ``b`` = HQ,
  ``offset`` = ``time_shift_us``).

:func:`associate` wraps both, applies the maximum difference, logs "N of M matched" and raises
:class:`~align.errors.AssociationError` naming both streams when nothing matches.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from align.errors import AlignError, AssociationError

log = logging.getLogger(__name__)

ASSOCIATIONS = ("nearest", "greedy")


def _as_stamps(t, name: str) -> np.ndarray:
    t = np.asarray(t)
    if t.ndim != 1:
        raise AlignError(f"{name}: timestamps must be a 1-D array, got shape {t.shape}")
    if t.size and not np.issubdtype(t.dtype, np.integer):
        raise AlignError(f"{name}: timestamps must be integer microseconds, got {t.dtype}")
    t = t.astype(np.int64, copy=False)
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise AlignError(f"{name}: timestamps must not decrease")
    return t


def _shift_per_frame(time_shift_us, n: int) -> np.ndarray:
    """A scalar or per-HQ-frame shift (drift model) as ``int64 (n,)``, rounded to whole µs."""
    s = np.asarray(time_shift_us, dtype=np.float64)
    s = np.broadcast_to(s, (n,)) if s.ndim == 0 else s
    if s.shape != (n,):
        raise AlignError(f"time shift must be a scalar or one value per HQ frame ({n}), got shape {s.shape}")
    return np.rint(s).astype(np.int64)


def nearest_mapping(t_hq_us, t_lq_us, time_shift_us=0) -> np.ndarray:
    """Eq. 28: for every HQ frame the index of the LQ frame nearest to ``t_hq + time_shift_us``.

    Args:
        t_hq_us: ``(N,)`` int64 HQ timestamps, non-decreasing.
        t_lq_us: ``(M,)`` int64 LQ timestamps, non-decreasing, ``M >= 1``.
        time_shift_us: scalar, or ``(N,)`` per HQ frame (``Delta(t) = a + b t``); rounded to µs.

    Returns:
        ``(N,)`` int64 indices into ``t_lq_us``. On a tie the earlier LQ frame wins (argmin's rule).
    """
    t_hq = _as_stamps(t_hq_us, "HQ")
    t_lq = _as_stamps(t_lq_us, "LQ")
    if t_lq.size == 0:
        raise AssociationError("LQ stream has no frames")
    target = t_hq + _shift_per_frame(time_shift_us, t_hq.size)
    k = np.searchsorted(t_lq, target, side="left")
    hi = np.clip(k, 0, t_lq.size - 1)
    lo = np.clip(k - 1, 0, t_lq.size - 1)
    # earlier frame wins ties: choose hi only if strictly closer
    take_hi = np.abs(t_lq[hi] - target) < np.abs(t_lq[lo] - target)
    return np.where(take_hi, hi, lo).astype(np.int64)


def associate_greedy(t_hq_us, t_lq_us, *, time_shift_us=0, max_difference_us: int) -> tuple[np.ndarray, np.ndarray]:
    """TUM ``associate.py``: greedy one-to-one pairs with ``|t_lq - (t_hq + shift)| < max_difference_us``.

    Candidates are ordered by (difference, LQ stamp, HQ stamp) -- the order in which TUM's script
    sorts its ``(diff, a, b)`` tuples -- and accepted unless either frame is already taken. Only the
    candidates inside the window are formed (searchsorted), so the cost is O((N + M) log M + C log C)
    for C candidates instead of TUM's O(N M).

    Returns:
        ``(hq_index, lq_index)``, int64 arrays sorted by LQ stamp (TUM sorts its matches by ``a``).
    """
    t_hq = _as_stamps(t_hq_us, "HQ")
    t_lq = _as_stamps(t_lq_us, "LQ")
    if max_difference_us <= 0:
        raise AlignError(f"max_difference_us must be positive, got {max_difference_us}")
    target = t_hq + _shift_per_frame(time_shift_us, t_hq.size)
    lo = np.searchsorted(t_lq, target - max_difference_us, side="right")  # strict: diff < max
    hi = np.searchsorted(t_lq, target + max_difference_us, side="left")
    counts = np.maximum(hi - lo, 0)
    if counts.sum() == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    hq = np.repeat(np.arange(t_hq.size), counts)
    first = np.repeat(lo - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    lq = first + np.arange(hq.size)
    diff = np.abs(t_lq[lq] - target[hq])
    order = np.lexsort((t_hq[hq], t_lq[lq], diff))  # last key is primary: (diff, a, b)
    hq_taken = np.zeros(t_hq.size, bool)
    lq_taken = np.zeros(t_lq.size, bool)
    out_hq, out_lq = [], []
    for c in order:  # sequential by nature; C is a few per frame
        a, b = lq[c], hq[c]
        if not lq_taken[a] and not hq_taken[b]:
            lq_taken[a] = hq_taken[b] = True
            out_hq.append(b)
            out_lq.append(a)
    out_hq, out_lq = np.asarray(out_hq, np.int64), np.asarray(out_lq, np.int64)
    order = np.lexsort((t_hq[out_hq], t_lq[out_lq]))
    return out_hq[order], out_lq[order]


@dataclass(frozen=True)
class Association:
    """Index pairs between the HQ and LQ streams.

    Attributes:
        hq_index, lq_index: ``(P,)`` int64 frame indices (positions in the timestamp arrays).
        dt_us: ``(P,)`` int64 residual time difference ``t_lq - (t_hq + shift)`` in µs.
        n_hq, n_lq: lengths of the two streams.
        method: ``"nearest"`` or ``"greedy"``.
    """

    hq_index: np.ndarray
    lq_index: np.ndarray
    dt_us: np.ndarray
    n_hq: int
    n_lq: int
    method: str

    def __len__(self) -> int:
        return int(self.hq_index.size)


def associate(t_hq_us, t_lq_us, *, time_shift_us=0, method: str = "nearest", max_difference_us: int | None = None,
              hq_name: str = "HQ", lq_name: str = "LQ") -> Association:
    """Pair HQ and LQ frames; log "N of M matched"; raise when nothing matches.

    ``method="nearest"`` is eq. 28 for every HQ frame, then pairs with ``|dt| >= max_difference_us``
    are removed (``None`` keeps all). ``method="greedy"`` is TUM's one-to-one association
    (``max_difference_us`` required; TUM's default is 20 ms).

    Raises:
        AssociationError: no pair at all; the message names both streams and their time ranges.
    """
    if method not in ASSOCIATIONS:
        raise AlignError(f"association must be one of {', '.join(ASSOCIATIONS)}, got {method!r}")
    t_hq = _as_stamps(t_hq_us, hq_name)
    t_lq = _as_stamps(t_lq_us, lq_name)
    shift = _shift_per_frame(time_shift_us, t_hq.size)
    if t_hq.size == 0 or t_lq.size == 0:
        empty = hq_name if t_hq.size == 0 else lq_name
        raise AssociationError(f"{hq_name} / {lq_name}: stream {empty} has no frames to associate")
    if method == "nearest":
        lq = nearest_mapping(t_hq, t_lq, shift)
        hq = np.arange(t_hq.size, dtype=np.int64)
        if max_difference_us is not None:
            keep = np.abs(t_lq[lq] - (t_hq + shift)) < max_difference_us
            hq, lq = hq[keep], lq[keep]
    else:
        if max_difference_us is None:
            raise AlignError("greedy association needs max_difference_us")
        hq, lq = associate_greedy(t_hq, t_lq, time_shift_us=shift, max_difference_us=max_difference_us)
    dt = t_lq[lq] - (t_hq[hq] + shift[hq])
    log.info("%s association %s -> %s: %d of %d HQ frames matched", method, hq_name, lq_name, hq.size, t_hq.size)
    if hq.size == 0:
        raise AssociationError(
            f"{hq_name} / {lq_name}: no frame pairs within {max_difference_us} us "
            f"({hq_name} {t_hq[0]}..{t_hq[-1]} us shifted by {int(shift[0])} us, {lq_name} {t_lq[0]}..{t_lq[-1]} us): "
            "the time ranges do not overlap")
    return Association(hq, lq, dt.astype(np.int64), int(t_hq.size), int(t_lq.size), method)


def overlap_us(t_hq_us, t_lq_us, time_shift_us=0) -> int:
    """Length of the overlap of the two streams' time ranges after shifting HQ (0 if none)."""
    t_hq, t_lq = np.asarray(t_hq_us, np.int64), np.asarray(t_lq_us, np.int64)
    if t_hq.size == 0 or t_lq.size == 0:
        return 0
    s = int(np.rint(time_shift_us))
    return int(max(0, min(t_hq[-1] + s, t_lq[-1]) - max(t_hq[0] + s, t_lq[0])))
