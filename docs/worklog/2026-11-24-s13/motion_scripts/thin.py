import cv2, numpy as np
cv2.setNumThreads(1)
rng = np.random.default_rng(0)
H, W = 135, 240
def tex(h, w, seed):
    r = np.random.default_rng(seed).random((h // 4 + 2, w // 4 + 2))
    return cv2.resize((r * 200 + 30).astype(np.float32), (w + 8, h + 8), interpolation=cv2.INTER_CUBIC)[:h, :w]
bg = tex(H, W, 1)
def frame(x0, width, ang=0):
    img = bg.copy()
    bar = tex(H, 400, 2)
    img[20:115, x0:x0 + width] = bar[20:115, 100:100 + width]  # texture moves with the bar
    return np.clip(img, 0, 255).astype(np.uint8)
for width in (8, 10, 12, 16):
  for shift in (3, 4, 5, 6):
    a, b = frame(100, width), frame(100 + shift, width)
    res = []
    for name, (p, f, st) in {"uf f1": (0, 1, None), "uf f0 s5": (0, 0, 5), "uf f0 s4": (0, 0, 4)}.items():
        d = cv2.DISOpticalFlow_create(p); d.setFinestScale(f)
        if st: d.setPatchStride(st)
        fl = d.calc(a, b, None)
        res.append(f"{name} {np.median(fl[25:110, 100:100 + width, 0]) / shift:.2f}")
    print(f"width {width} shift {shift}: " + ", ".join(res))
