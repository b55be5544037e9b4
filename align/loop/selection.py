"""Model selection that cannot fool itself: held-out error, a noise-calibrated threshold, a second guard.

Pure numpy. Works on a *linearised* problem around the current fit: residual rows ``r0`` (``(n,)``),
a Jacobian ``J`` (``(n, C)``) holding the columns of every parameter (the base model's and every
candidate's), and a group per row (a probe of the feature fit, a frame pair of the depth fit),
groups numbered in time order. A model is a set of columns.

Held-out error (:class:`HeldOut`): the groups are cut into ``folds`` contiguous time
blocks; for each block, the model's parameters are fitted (robust, Cauchy IRLS weights; every
column of the model re-fitted, base columns included) on the groups outside the block and a
``gap`` of groups on each side of it, and the block's rows are scored with the robust loss
``rho(r) = c^2 log(1 + (r / c)^2)``. Every group is held out exactly once: one loss per group.

Accepting a candidate (:func:`compare`): the per-group loss differences ``d_g = L_base(g) -
L_with(g)`` give the improvement ``sum d / sum L_base`` and its noise, ``z = mean(d) / (sd(d) /
sqrt(G))``. A candidate is accepted when ``z`` exceeds the threshold **and** the information
criterion agrees (:meth:`HeldOut.bic`: ``sum rho / sigma^2 + k ln n`` falls).

Threshold (:func:`null_threshold`), a parametric bootstrap: data are simulated from the fitted
model with no effect added -- residual rows replaced by noise drawn from the fit's own residuals
(group means resampled across groups with random signs, within-group deviations permuted
across rows of the same coordinate, which keeps their size and the correlation within a group
and destroys any relation to an effect's signature) -- and the largest ``z`` over all
candidates is recorded per replicate; the threshold is its ``1 - alpha`` quantile (never below
``z_floor``). The false-alarm rate of one stage is then about ``alpha`` by construction, and
the clean-session study (``scripts/loop_study.py``) measures it end to end.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def rho(r: np.ndarray, c: float) -> np.ndarray:
    """Cauchy loss ``c^2 log(1 + (r/c)^2)``."""
    return c * c * np.log1p((r / c) ** 2)


def weights(r: np.ndarray, c: float) -> np.ndarray:
    """IRLS weights of the Cauchy loss."""
    return 1.0 / (1.0 + (r / c) ** 2)


@dataclass
class LinearProblem:
    """Residual rows ``r0`` ``(n,)``, Jacobian ``J`` ``(n, C)``, row groups ``group`` ``(n,)`` (0..G-1, time
    order, rows sorted by group), Cauchy scale ``c``, the column names, and the noise sigma of one
    row (default ``c / 2.5``: the loop sets ``c`` to 2.5 robust sigmas)."""

    r0: np.ndarray
    J: np.ndarray
    group: np.ndarray
    c: float
    names: list[str]
    sigma: float | None = None

    def __post_init__(self) -> None:
        self.n_groups = int(self.group.max()) + 1 if self.group.size else 0
        self.sigma = self.c / 2.5 if self.sigma is None else self.sigma
        norm = np.sqrt(np.mean(self.J ** 2, axis=0))
        self.col_scale = np.where(norm > 0, norm, 1.0)
        self.Jn = self.J / self.col_scale
        self.starts = np.searchsorted(self.group, np.arange(self.n_groups))

    def with_r0(self, r0: np.ndarray) -> "LinearProblem":
        out = object.__new__(LinearProblem)
        out.__dict__.update(self.__dict__)
        out.r0 = r0
        return out

    def cols(self, names) -> np.ndarray:
        return np.array([self.names.index(n) for n in names], np.int64)


def folds_of(n_groups: int, *, folds: int = 5, gap: int = 1) -> list[tuple[np.ndarray, np.ndarray]]:
    """Contiguous time blocks: ``[(test groups, excluded groups = test + gap either side), ...]``."""
    k = max(2, min(folds, n_groups))
    blocks = np.array_split(np.arange(n_groups), k)
    out = []
    for b in blocks:
        if b.size == 0:
            continue
        ex = np.arange(max(0, b[0] - gap), min(n_groups, b[-1] + gap + 1))
        out.append((b, ex))
    return out


def _solve(G: np.ndarray, h: np.ndarray) -> np.ndarray:
    if G.shape[0] == 0:
        return np.zeros(0)
    G = G.copy()
    G.flat[:: G.shape[0] + 1] += 1e-9 * max(float(np.trace(G)), 1e-12)
    return -np.linalg.solve(G, h)


def full_fit(p: LinearProblem, cols: np.ndarray, *, irls: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Robust fit of the columns ``cols`` on all rows: ``(delta in parameter units, fitted residual rows)``."""
    J = p.Jn[:, cols]
    r = p.r0
    delta = np.zeros(cols.size)
    for _ in range(irls):
        w = weights(r, p.c)
        delta = _solve((J * w[:, None]).T @ J, (J * w[:, None]).T @ p.r0)
        r = p.r0 + J @ delta
    return delta / p.col_scale[cols], r


class HeldOut:
    """Held-out losses of any model within the columns ``all_cols`` of a problem (see the module docstring).

    One set of IRLS weights serves every model: those of the robust fit of *all* the columns on
    all rows (weights only decide which training rows count, so a candidate is trained on the
    rows it would win back; every test row is scored by ``rho`` of its held-out residual). The
    per-group normal equations are formed once; a model is a sub-block of them.
    """

    def __init__(self, p: LinearProblem, all_cols: np.ndarray, folds, *, irls: int = 3) -> None:
        self.p, self.folds = p, folds
        self.all_cols = np.asarray(all_cols, np.int64)
        self.local = {int(c): k for k, c in enumerate(self.all_cols)}
        _, r = full_fit(p, self.all_cols, irls=irls)
        w = weights(r, p.c)
        J = p.Jn[:, self.all_cols]
        Jw = J * w[:, None]
        self.J = J
        self.Gr = np.add.reduceat(Jw[:, :, None] * J[:, None, :], p.starts, axis=0)
        self.hr = np.add.reduceat(Jw * p.r0[:, None], p.starts, axis=0)
        self.G_all, self.h_all = self.Gr.sum(axis=0), self.hr.sum(axis=0)
        ends = np.append(p.starts[1:], p.r0.size)
        # per fold: the training normal equations (all columns) and the test rows (a contiguous slice)
        self.train = [(self.G_all - self.Gr[ex].sum(axis=0), self.h_all - self.hr[ex].sum(axis=0)) for _, ex in folds]
        self.test_rows = [slice(int(p.starts[t[0]]), int(ends[t[-1]])) for t, _ in folds]

    def _sub(self, cols) -> np.ndarray:
        return np.array([self.local[int(c)] for c in cols], np.int64)

    def losses(self, cols, *, rows_out: np.ndarray | None = None) -> np.ndarray:
        """Held-out robust loss per group ``(G,)``; ``rows_out`` ``(n,)`` receives the held-out residual rows."""
        p, k = self.p, self._sub(cols)
        loss = np.zeros(p.n_groups)
        full = np.zeros(self.all_cols.size)
        for (test, _), (G, h), sl in zip(self.folds, self.train, self.test_rows):
            full[:] = 0.0
            if k.size:
                full[k] = _solve(G[k][:, k], h[k])
            r = p.r0[sl] + self.J[sl] @ full
            if rows_out is not None:
                rows_out[sl] = r
            loss[test] = np.add.reduceat(rho(r, p.c), p.starts[test] - p.starts[test[0]])
        return loss

    def bic(self, cols) -> float:
        """``sum rho / sigma^2 + k ln n`` of the model fitted on all rows: the Gaussian deviance of the
        inliers (``rho ~ r^2`` for ``|r| << c``), outliers capped by the robust loss."""
        p, k = self.p, self._sub(cols)
        delta = _solve(self.G_all[np.ix_(k, k)], self.h_all[k])
        r = p.r0 + (self.J[:, k] @ delta if k.size else 0.0)
        return float(np.sum(rho(r, p.c)) / p.sigma ** 2 + k.size * np.log(max(r.size, 2)))


@dataclass
class Comparison:
    """Held-out comparison of a model with and without a candidate."""

    z: float
    improvement: float  # relative drop of the held-out loss
    loss_before: float  # held-out loss per row
    loss_after: float
    delta_bic: float

    def to_dict(self) -> dict:
        return {"z": float(self.z), "heldout_improvement": float(self.improvement),
                "heldout_loss_before": float(self.loss_before), "heldout_loss_after": float(self.loss_after),
                "delta_bic": float(self.delta_bic)}


def z_of(d: np.ndarray) -> float:
    sd = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    if sd <= 0:
        return float("inf") if d.mean() > 0 else 0.0
    return float(d.mean() / (sd / np.sqrt(d.size)))


def compare(h: HeldOut, base: np.ndarray, extra: np.ndarray, *, base_loss: np.ndarray | None = None,
            base_bic: float | None = None) -> Comparison:
    """Held-out comparison of ``base`` and ``base + extra`` columns, with the BIC difference."""
    lb = h.losses(base) if base_loss is None else base_loss
    both = np.concatenate([base, extra])
    la = h.losses(both)
    d = lb - la
    n = max(h.p.r0.size, 1)
    bb = h.bic(base) if base_bic is None else base_bic
    return Comparison(z_of(d), float(d.sum() / max(lb.sum(), 1e-300)), float(lb.sum() / n), float(la.sum() / n),
                      h.bic(both) - bb)


def bootstrap_noise(p: LinearProblem, r: np.ndarray, rng: np.random.Generator, *, parity: int = 2) -> np.ndarray:
    """One draw of residual rows under the fitted model (see the module docstring); ``parity``: rows
    alternate over that many coordinates (2 for x, y pixel rows)."""
    coord = np.arange(r.size) % parity
    means = np.zeros((p.n_groups, parity))
    for c in range(parity):
        sel = coord == c
        sums = np.add.reduceat(np.where(sel, r, 0.0), p.starts)
        cnt = np.add.reduceat(sel.astype(float), p.starts)
        means[:, c] = sums / np.maximum(cnt, 1)
    dev = r - means[p.group, coord]
    pick = rng.integers(0, p.n_groups, p.n_groups)
    sign = rng.choice([-1.0, 1.0], p.n_groups)
    new_means = means[pick] * sign[:, None]
    out = np.empty_like(r)
    for c in range(parity):
        sel = np.flatnonzero(coord == c)
        out[sel] = rng.permutation(dev[sel])
    return out + new_means[p.group, coord]


def null_threshold(p: LinearProblem, base: np.ndarray, candidates: list[np.ndarray], folds, *, replicates: int = 100,
                   alpha: float = 0.01, z_floor: float = 3.0, seed: int = 0, parity: int = 2) -> tuple[float, np.ndarray]:
    """``(threshold on z, the replicates' largest z)`` from the parametric bootstrap of the module docstring."""
    if not candidates:
        return z_floor, np.zeros(0)
    rng = np.random.default_rng(seed)
    _, r_fit = full_fit(p, base)
    all_cols = np.concatenate([base] + list(candidates))
    zmax = np.empty(replicates)
    for b in range(replicates):
        h = HeldOut(p.with_r0(bootstrap_noise(p, r_fit, rng, parity=parity)), all_cols, folds, irls=1)
        lb = h.losses(base)
        zmax[b] = max(z_of(lb - h.losses(np.concatenate([base, c]))) for c in candidates)
    return max(z_floor, float(np.quantile(zmax, 1 - alpha))), zmax
