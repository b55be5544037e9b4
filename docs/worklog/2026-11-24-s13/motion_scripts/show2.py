import numpy as np, cv2, sys
z = np.load("/work/notes/motion/diag.npz")
r0, r1, c0, c1 = [int(x) for x in sys.argv[1:5]]
def col(d):
    g = np.clip((d - 1.0) / 5 * 255, 0, 255); g = np.where(np.isfinite(d), g, 0).astype(np.uint8)
    return cv2.applyColorMap(g, cv2.COLORMAP_JET) * np.isfinite(d)[..., None].astype(np.uint8)
pan = [col(z[k][r0:r1, c0:c1]) for k in ("wto", "truth", "wtx", "plain", "ref")]
b = np.zeros_like(pan[0]); b[z["bad"][r0:r1, c0:c1]] = 255
pan.append(b)
pan = [np.pad(p, ((0, 0), (0, 2), (0, 0)), constant_values=255) for p in pan]
img = cv2.resize(np.concatenate(pan, 1), None, fx=3, fy=3, interpolation=cv2.INTER_NEAREST)
cv2.imwrite("/work/notes/motion/show2.png", img)
