"""features.py TAG SESSION [BASE_DIR FMIX_DIR [FPFG_DIR]]: per scored pixel of BASE_DIR (default /tmp/refedge4/al_base_TAG, footprint-fg), every witness tried, for
the learned-combination bound (learn.py). No feature reads the truth; the label (|error| > 0.3 m) and the error are
saved beside them. Features:
 n_other    8-neighbours that are reference holes or > 10 % farther (island.py: corners, peninsulas, bridges)
 sil        distance (px) to the nearest near-side silhouette pixel (photo.silhouette_dist)
 jump       log(max reference depth in the 5x5 / z_ref) (holes ignored)
 holes5     reference holes in the 5x5
 photo_rgb  min |c_lq(p) - c_hq| over the 3x3 HQ colour pixels around X(p)'s projection (RGB)
 photo_y    the same on luminance
 lqedge     a_in - a_out of lqedge.py (LQ colour alone; -442 where p has no 'other' neighbour)
 dropped    footprint-mixed-fg (FMIX_DIR, default /tmp/refedge4/al_fmix_TAG) has no reference here (the HQ mixes align.mixed_pixels distrusts)
 occ        (only with FPFG_DIR, a footprint-fg dataset of the same session, when BASE_DIR is strict-fg) footprint-fg
            masks the pixel (its footprint occluders): the whole 2 % then goes to the learned ranking
Saves /tmp/refedge4/feat_TAG.npz: X (n, 8), y, e (mm), frame index, names."""
import sys, csv
import numpy as np, cv2
from common import frame_errors
from photo import silhouette_dist
from island import n_other
from photo2 import colour_dist
sys.path.insert(0, '/work/wt/refedge4')
from align.dataset import AlignedDataset
from capture.camera import Intrinsics, Transform
from capture.session import open_session

NAMES = ['n_other', 'sil', 'jump', 'holes5', 'photo_rgb', 'photo_y', 'lqedge', 'dropped']
YW = np.array([0.299, 0.587, 0.114], np.float32)


def lq_edge(ref, c):
    H, W = ref.shape
    zp = np.pad(ref, 1, constant_values=np.nan); cp = np.pad(c, ((1, 1), (1, 1), (0, 0)))
    a_in = np.full((H, W), 442.0); a_out = np.full((H, W), np.inf)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                zn = zp[1 + di:1 + di + H, 1 + dj:1 + dj + W]; cn = cp[1 + di:1 + di + H, 1 + dj:1 + dj + W]
                d = np.linalg.norm(cn - c, axis=2)
                with np.errstate(invalid='ignore'):
                    same = np.abs(zn - ref) <= 0.1 * ref
                    other = ~np.isfinite(zn) | (zn > 1.1 * ref)
                a_in = np.where(same, np.minimum(a_in, d), a_in); a_out = np.where(other, np.minimum(a_out, d), a_out)
    return np.where(np.isfinite(a_out), a_in - a_out, -442.0)


def main(tag, sroot, root=None, fmix=None, fpfg=None):
    root = root or f'/tmp/refedge4/al_base_{tag}'
    e, share = frame_errors(root)
    ds, dm = AlignedDataset(root), AlignedDataset(fmix or f'/tmp/refedge4/al_fmix_{tag}')
    dfp = AlignedDataset(fpfg) if fpfg else None
    meta = ds.meta; sess = open_session(sroot)
    rows = list(csv.DictReader(open(f'{root}/frames.csv')))
    Kl = Intrinsics.from_dict(meta['lq_intrinsics']); Khc = sess.intrinsics('hq', 'color')
    T = sess.sensors['hq'].T_depth_color.inverse() @ Transform.from_list(meta['T_lq_hq']).inverse()
    H, W = Kl.height, Kl.width
    jj, ii = np.meshgrid(np.arange(W), np.arange(H))
    Xs, ys, es, fs = [], [], [], []
    for f in range(len(ds)):
        sc = np.isfinite(e[f])
        ref = ds.reference(f); c = ds.lq_color(f).astype(np.float32)
        hqc = sess.read_color('hq', int(rows[f]['hq_frame'])).astype(np.float32)
        fin = np.isfinite(ref)
        mx = cv2.dilate(np.where(fin, ref, 0).astype(np.float32), np.ones((5, 5), np.uint8))
        holes = cv2.boxFilter((~fin).astype(np.float32), -1, (5, 5), normalize=False)
        Xp = T.apply(Kl.unproject(np.stack([jj[sc], ii[sc]], 1).astype(float), ref[sc].astype(float)))
        prgb = colour_dist(c[sc], Xp, Khc, hqc)
        py = colour_dist((c @ YW)[sc][:, None], Xp, Khc, (hqc @ YW)[..., None])
        drop = fin & ~np.isfinite(dm.reference(f))
        cols = [n_other(ref)[sc], silhouette_dist(ref)[sc], np.log(np.maximum(mx[sc], ref[sc]) / ref[sc]), holes[sc],
                np.nan_to_num(prgb, nan=0.0), np.nan_to_num(py, nan=0.0), lq_edge(ref, c)[sc], drop[sc]]
        if dfp is not None:
            cols.append((fin & ~np.isfinite(dfp.reference(f)))[sc])
        Xs.append(np.stack([np.asarray(v, np.float32) for v in cols], 1))
        ys.append(np.abs(e[f][sc]) > 300); es.append(e[f][sc]); fs.append(np.full(sc.sum(), f, np.int16))
    np.savez_compressed(f'/tmp/refedge4/feat_{tag}.npz', X=np.concatenate(Xs), y=np.concatenate(ys), e=np.concatenate(es),
                        f=np.concatenate(fs), names=NAMES, roi_total=meta['reference_edges']['roi_pixels'], share=share,
                        shape=np.array(e.shape))
    print(tag, 'scored', sum(len(v) for v in ys), 'big', int(sum(v.sum() for v in ys)))


if __name__ == '__main__':
    main(*sys.argv[1:])
