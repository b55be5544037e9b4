"""photo.py DATASET SESSION (env LUMA=1: luminance only; WIN=k: (2k+1)^2 window): per scored pixel, the photo-consistency of the reference with the two colour images
(no truth in the score). X = ray_lq(p) * z_ref(p) is projected into the HQ *colour* camera (T_lq_hq, the HQ
sensor's T_depth_color); score = min over the 3x3 HQ colour pixels around the projection of |c_lq(p) - c_hq|
(RGB L2, 0-255). 'occluded': the HQ depth warped onto the HQ colour image is nearer than X by > 5 % there (X not
seen by the HQ colour camera: no verdict, score NaN). Also 'edge': distance (px) to the nearest reference
silhouette (a 3x3 neighbour farther by > 10 % or a hole). Saves /tmp/refedge4/photo_<name>.npz with e (error, mm,
NaN unscored), score, edge_dist, and prints the score distribution of > 0.3 m pixels vs the rest."""
import sys, csv
from pathlib import Path
import os
import numpy as np, cv2
LUMA = os.environ.get('LUMA') == '1'
WIN = int(os.environ.get('WIN', '1'))
YW = np.array([0.299, 0.587, 0.114], np.float32)
from common import frame_errors
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset
from align.warp import DepthWarper
from capture.camera import Intrinsics, Transform
from capture.session import open_session


def silhouette_dist(ref):
    """distance (px, L2) to the nearest pixel that is a hole or whose 3x3 has a pixel > 10 % farther / a hole,
    measured from pixels on the near side."""
    fin = np.isfinite(ref)
    z = np.where(fin, ref, np.inf).astype(np.float32)
    far = cv2.dilate(np.where(fin, ref, 1e6).astype(np.float32), np.ones((3, 3), np.uint8))
    edge = fin & (far > 1.1 * z)  # near side pixels at a silhouette (holes count as far)
    return cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 3)


def frame_scores(ds, sess, rows, f, Kl, Khc, Kh, T_hq_lq, T_hqc_hq, warp_col):
    ref = ds.reference(f)
    lqc = ds.lq_color(f).astype(np.float32)
    hqf = int(rows[f]['hq_frame'])
    hqc = sess.read_color('hq', hqf).astype(np.float32)
    hqd = sess.read_depth('hq', hqf)
    dcol = warp_col(hqd)
    H, W = ref.shape
    jj, ii = np.meshgrid(np.arange(W), np.arange(H))
    has = np.isfinite(ref)
    X = T_hq_lq.apply(Kl.unproject(np.stack([jj[has], ii[has]], 1).astype(float), ref[has].astype(float)))
    Xc = T_hqc_hq.apply(X)
    uv = Khc.project(Xc)
    cu, cv = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
    inside = (cu >= WIN) & (cv >= WIN) & (cu < Khc.width - WIN) & (cv < Khc.height - WIN)
    cu, cv = np.clip(cu, WIN, Khc.width - 1 - WIN), np.clip(cv, WIN, Khc.height - 1 - WIN)
    c = lqc[has]
    best = np.full(cu.size, np.inf)
    if LUMA:
        c = c @ YW; hqc = hqc @ YW
    for a in range(-WIN, WIN + 1):
        for b in range(-WIN, WIN + 1):
            q = hqc[cv + b, cu + a]
            best = np.minimum(best, np.abs(q - c) if LUMA else np.linalg.norm(q - c, axis=1))
    dz = dcol[cv, cu]
    occl = np.isfinite(dz) & (dz < Xc[:, 2] / 1.05)
    s = np.full((H, W), np.nan); s[has] = np.where(inside & ~occl, best, np.nan)
    oc = np.zeros((H, W), bool); oc[has] = occl
    return s, oc, silhouette_dist(ref)


def main(root, sroot):
    e, share = frame_errors(root)
    ds = AlignedDataset(root); meta = ds.meta
    sess = open_session(sroot)
    rows = list(csv.DictReader(open(f'{root}/frames.csv')))
    Kl, Kh = Intrinsics.from_dict(meta['lq_intrinsics']), Intrinsics.from_dict(meta['hq_intrinsics'])
    Khc = sess.intrinsics('hq', 'color')
    T_hq_lq = Transform.from_list(meta['T_lq_hq']).inverse()
    T_hqc_hq = sess.sensors['hq'].T_depth_color.inverse()
    warp_col = DepthWarper(Kh, Khc, T_hqc_hq, edge_reach=0.0)
    S, O, D = [], [], []
    for f in range(len(ds)):
        s, oc, d = frame_scores(ds, sess, rows, f, Kl, Khc, Kh, T_hq_lq, T_hqc_hq, warp_col)
        S.append(s); O.append(oc); D.append(d)
    S, O, D = np.stack(S), np.stack(O), np.stack(D)
    name = Path(root).name
    np.savez_compressed(f'/tmp/refedge4/photo_{name}_l{int(LUMA)}w{WIN}.npz', e=e, score=S, occl=O, edge_dist=D,
                        roi_total=ds.meta['reference_edges']['roi_pixels'], share=share)
    sc = np.isfinite(e)
    big = sc & (np.abs(np.nan_to_num(e)) > 300)
    print(f"{name}: scored {sc.sum()}, >0.3 m {big.sum()}; occluded among scored {np.sum(O & sc)}, among big {np.sum(O & big)}")
    for lab, m in (('big', big), ('near-sil<=3 rest', sc & ~big & (D <= 3)), ('all rest', sc & ~big)):
        v = S[m]; v = v[np.isfinite(v)]
        q = np.percentile(v, [10, 50, 90, 99]) if v.size else []
        print(f"  {lab}: n {m.sum()} (finite {v.size}) score pcts 10/50/90/99 {np.round(q, 1)}")
    print("  big pixels: score, edge_dist, err_mm:")
    for f, i, j in zip(*np.nonzero(big)):
        print(f"    f{f} ({i},{j}) score {S[f, i, j]:.1f} dist {D[f, i, j]:.1f} occl {O[f, i, j]} e {e[f, i, j]:.0f}")


if __name__ == '__main__':
    main(sys.argv[1], sys.argv[2])
