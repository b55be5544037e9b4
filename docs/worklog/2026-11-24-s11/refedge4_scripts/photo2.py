"""photo2.py DATASET SESSION: two depth hypotheses per candidate pixel (no truth in the scores): the reference's z
(near) and the farthest reference depth in the 7x7 window around p (far). For each, X = ray_lq(p) z projected into
the HQ colour camera; d = min over the 3x3 HQ colour pixels around the projection of |c_lq(p) - c_hq| (RGB L2).
Candidates: scored pixels within 2 px of a reference silhouette (photo.silhouette_dist) whose far depth is > 10 %
beyond z_ref. Saves /tmp/refedge4/photo2_<name>.npz (e, dn, df, cand, D)."""
import sys, csv
from pathlib import Path
import numpy as np, cv2
from common import frame_errors
from photo import silhouette_dist
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset
from capture.camera import Intrinsics, Transform
from capture.session import open_session


def colour_dist(lqc_px, X_hqc, Khc, hqc, win=1):
    uv = Khc.project(X_hqc)
    ok = np.all(np.isfinite(uv), 1) & (X_hqc[:, 2] > 0)
    uv = np.where(ok[:, None], uv, -100)
    cu, cv = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
    inside = (cu >= win) & (cv >= win) & (cu < Khc.width - win) & (cv < Khc.height - win)
    cu, cv = np.clip(cu, win, Khc.width - 1 - win), np.clip(cv, win, Khc.height - 1 - win)
    best = np.full(cu.size, np.inf)
    for a in range(-win, win + 1):
        for b in range(-win, win + 1):
            best = np.minimum(best, np.linalg.norm(hqc[cv + b, cu + a] - lqc_px, axis=1))
    return np.where(inside, best, np.nan)


def main(root, sroot, win=1):
    e, share = frame_errors(root)
    ds = AlignedDataset(root); meta = ds.meta
    sess = open_session(sroot)
    rows = list(csv.DictReader(open(f'{root}/frames.csv')))
    Kl = Intrinsics.from_dict(meta['lq_intrinsics'])
    Khc = sess.intrinsics('hq', 'color')
    T = sess.sensors['hq'].T_depth_color.inverse() @ Transform.from_list(meta['T_lq_hq']).inverse()
    H, W = Kl.height, Kl.width
    jj, ii = np.meshgrid(np.arange(W), np.arange(H))
    DN, DF, C, D = [], [], [], []
    for f in range(len(ds)):
        ref = ds.reference(f)
        lqc = ds.lq_color(f).astype(np.float32)
        hqc = sess.read_color('hq', int(rows[f]['hq_frame'])).astype(np.float32)
        d = silhouette_dist(ref)
        far = cv2.dilate(np.where(np.isfinite(ref), ref, 0).astype(np.float32), np.ones((7, 7), np.uint8))
        cand = np.isfinite(e[f]) & (d <= 2) & (far > 1.1 * np.nan_to_num(ref, nan=np.inf))
        pix = np.stack([jj[cand], ii[cand]], 1).astype(float)
        dn = np.full((H, W), np.nan); df = np.full((H, W), np.nan)
        for z, out in ((ref[cand], dn), (far[cand], df)):
            X = T.apply(Kl.unproject(pix, z.astype(float)))
            out[cand] = colour_dist(lqc[cand], X, Khc, hqc, win)
        DN.append(dn); DF.append(df); C.append(cand); D.append(d)
    DN, DF, C, D = map(np.stack, (DN, DF, C, D))
    name = Path(root).name
    np.savez_compressed(f'/tmp/refedge4/photo2_{name}_w{win}.npz', e=e, dn=DN, df=DF, cand=C, D=D,
                        roi_total=meta['reference_edges']['roi_pixels'], share=share)
    big = np.abs(np.nan_to_num(e)) > 300
    print(f"{name}: candidates {C.sum()} ({100 * C.sum() / meta['reference_edges']['roi_pixels']:.2f} % of ROI), "
          f">0.3 m {big.sum()}, of them candidates {np.sum(big & C)}")
    r = C & ~big
    for lab, m in (('big', big & C), ('rest', r)):
        a, b = DN[m], DF[m]
        print(f"  {lab}: near pcts 10/50/90 {np.round(np.nanpercentile(a, [10, 50, 90]), 1)} far {np.round(np.nanpercentile(b, [10, 50, 90]), 1)}"
              f" near-far>10: {np.mean(a - b > 10):.3f} >20: {np.mean(a - b > 20):.3f}")
    for f, i, j in zip(*np.nonzero(big)):
        print(f"    f{f} ({i},{j}) cand {C[f, i, j]} near {DN[f, i, j]:.1f} far {DF[f, i, j]:.1f} dist {D[f, i, j]:.1f} e {e[f, i, j]:.0f}")


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 1)
