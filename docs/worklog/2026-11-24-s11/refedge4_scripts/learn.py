"""learn.py TRAIN_TAGS TEST_TAGS: the learned-combination bound. A logistic model of 'pixel > 0.3 m off' on every
witness of features.py (expanded: one-hot n_other, dropped, dropped x n_other, photo scores and lqedge in bins, sil,
jump, holes5), fitted on the TRAIN sessions' truth labels (class-balanced, L2), then on every session: the scored
pixels ranked by the model, the top B masked, B = the budget left under 2 % of the ROI (aligned.json's masked share
+ B <= 2 %). Prints the ratio (frame bootstrap 1000) and the > 0.3 m pixels caught. This uses the truth to *choose*
the combination (an upper bound on what these witnesses can do at this budget, not a rule)."""
import sys
import numpy as np
from scipy.optimize import minimize


def expand(X):
    n, sil, jump, holes, prgb, py, lqe, drop = X.T[:8]
    cols = [np.eye(9)[np.clip(n, 0, 8).astype(int)], drop[:, None], (drop[:, None] * np.eye(9)[np.clip(n, 0, 8).astype(int)])]
    for v, edges in ((prgb, [10, 20, 30, 40, 60]), (py, [2, 5, 10, 20]), (lqe, [-40, 0, 20, 40, 80]),
                     (sil, [0.5, 1.5, 2.5, 4]), (jump, [0.05, 0.1, 0.3, 0.6]), (holes, [1, 4, 8, 12])):
        cols.append(np.eye(len(edges) + 1)[np.digitize(v, edges)][:, 1:])
    if X.shape[1] > 8:  # occ (features.py with FPFG_DIR)
        occ = X[:, 8]
        cols += [occ[:, None], occ[:, None] * drop[:, None]]
    return np.concatenate(cols, 1).astype(np.float64)


def fit(Z, y, lam=1.0):
    w_pos = 0.5 / max(y.mean(), 1e-9); w_neg = 0.5 / (1 - y.mean())
    sw = np.where(y, w_pos, w_neg) / len(y)
    Z1 = np.hstack([Z, np.ones((len(Z), 1))])

    def loss(b):
        s = Z1 @ b
        l = np.logaddexp(0, s) - y * s
        g = Z1.T @ (sw * (1 / (1 + np.exp(-s)) - y))
        return np.sum(sw * l) + lam * 1e-3 * b[:-1] @ b[:-1], g + np.r_[2 * lam * 1e-3 * b[:-1], 0]
    return minimize(loss, np.zeros(Z1.shape[1]), jac=True, method='L-BFGS-B').x


def ratio_of(e, f, nf, m):
    ok = ~m
    a = np.abs(e[ok]); ff = f[ok]
    n = np.bincount(ff, minlength=nf); mae = np.bincount(ff, a, nf) / n; rmse = np.sqrt(np.bincount(ff, a * a, nf) / n)
    r = rmse.mean() / mae.mean()
    rng = np.random.default_rng(0)
    bs = [rmse[i].mean() / mae[i].mean() for i in (rng.integers(0, nf, nf) for _ in range(1000))]
    return r, np.percentile(bs, [2.5, 97.5])


def load(t):
    z = np.load(f'/tmp/refedge4/feat_{t}.npz')
    return z


if __name__ == '__main__':
    train, test = sys.argv[1].split(','), sys.argv[2].split(',')
    Z = [load(t) for t in train]
    b = fit(np.concatenate([expand(z['X']) for z in Z]), np.concatenate([z['y'] for z in Z]).astype(float))
    for t in train + test:
        z = load(t); X, y, e, f = z['X'], z['y'], z['e'], z['f'].astype(int)
        nf = int(z['shape'][0]); B = int((0.02 - float(z['share'])) * float(z['roi_total']))
        s = np.hstack([expand(X), np.ones((len(X), 1))]) @ b
        m = np.zeros(len(s), bool); m[np.argsort(-s)[:B]] = True
        r0, _ = ratio_of(e, f, nf, np.zeros(len(s), bool)); r, (lo, hi) = ratio_of(e, f, nf, m)
        rank = np.argsort(np.argsort(-s))[y]
        print(f"{t}{' (train)' if t in train else ''}: budget {B} px; caught {int((m & y).sum())}/{int(y.sum())}; ratio {r0:.2f} -> {r:.2f} "
              f"[{lo:.2f}, {hi:.2f}] at 2.00 %; ranks of the > 0.3 m pixels: {sorted(rank.tolist())}")
