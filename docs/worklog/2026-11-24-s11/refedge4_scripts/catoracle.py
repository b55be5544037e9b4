"""catoracle.py: ratio after removing exactly the pixels of some categories of categories.py (an oracle: truth-chosen)."""
import re, sys
import numpy as np
from common import frame_errors, per_frame, ratio
for s in ('demo', 'p1', 'p2', 'p4'):
    e, _ = frame_errors(f'/tmp/refedge4/al_base_{s}')
    px = [(int(f), int(r), int(c), cat) for f, r, c, cat in
          re.findall(r"f(\d+) \((\d+),(\d+)\) err \S+ (\w+)", open(f'/tmp/refedge4/cat_{s}.txt').read())]
    out = []
    for name, cats in (('none', ()), ('cut', ('cut',)), ('cut+full', ('cut', 'full')), ('mix', ('mix',)), ('all', ('mix', 'cut', 'full', 'other'))):
        e2 = e.copy()
        for f, r, c, cat in px:
            if cat in cats:
                e2[f, r, c] = np.nan
        out.append(f"{name} {ratio(*per_frame(e2)):.2f}")
    print(s, " | ".join(out))
