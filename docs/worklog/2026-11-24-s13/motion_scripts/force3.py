"""acc.py with the primary flow FLOWCFG="preset,finest,refinement" (preset: uf/fast/med; refinement -1 = preset's)
and the finer-flow threshold FB; dump's gain = [gain, landed, moving] of the primary flow."""
import os, sys, json, cv2
import align.motion_flow as mf
mf.FALLBACK_LANDED = float(os.environ.get("FB", "0.75"))
P = {"uf": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST, "med": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}
cfg = os.environ.get("FLOWCFG")
if cfg:
    _CFG = tuple(cfg.split(","))
    _init = mf.FlowMotion.__init__
    def __init__(self, *a, **k):
        _init(self, *a, **k)
        self._flow = mf.ColorFlow(P[_CFG[0]], finest=int(_CFG[1]), refinement=None if int(_CFG[2]) < 0 else int(_CFG[2]))
        if len(_CFG) > 3:
            _c = self._flow.__class__.__call__
            st = int(_CFG[3]); fl = self._flow
            def call(a, b, _fl=fl):
                dis = getattr(_fl._local, "dis", None)
                if dis is None:
                    _c(_fl, a, b); _fl._local.dis.setPatchStride(st)
                return _c(_fl, a, b)
            self._flow = call
    mf.FlowMotion.__init__ = __init__
_sh, _pl = mf.SceneFlow._shifts, mf.SceneFlow._planar
def _shifts(self, *a, **k):
    r = _sh(self, *a, **k)
    if self._first is None:
        self._first = self.last_landed
    return r
def _planar(self, *a, **k):
    self._first = None
    r = _pl(self, *a, **k)
    self.last_gain_rec = [self.last_gain, *self._first]
    return r
mf.SceneFlow._shifts, mf.SceneFlow._planar = _shifts, _planar
src = open("docs/worklog/2026-11-24-s12/recheck_scripts/acc.py").read().replace("flow._moved.scene_flow.last_gain", "flow._moved.scene_flow.last_gain_rec")
exec(src)
