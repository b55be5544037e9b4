"""acc.py with the finer-flow threshold FB; the dump's "gain" becomes [gain, fast landed, fast moving]."""
import os, sys, json
import align.motion_flow as mf
mf.FALLBACK_LANDED = float(os.environ.get("FB", "0.75"))
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
