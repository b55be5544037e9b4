"""DDRNet (Yan et al. 2018, seed section III-A): a denoising net and a shading-guided refinement net.

Pure modules: :mod:`methods.ddrnet.nets` (the two networks), :mod:`methods.ddrnet.losses` (eq. 12-20).
"""
