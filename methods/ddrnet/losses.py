"""DDRNet's loss terms, eq. 12-20 of the seed report, as pure torch functions plus ``nn.Module`` wrappers.

Shapes: depth ``(B, 1, H, W)`` in **metres**, normals ``(B, 3, H, W)`` unit (zero where invalid),
grey image ``(B, 1, H, W)`` in ``[0, 1]``, masks ``(B, 1, H, W)`` bool, intrinsics ``(B, 4)``
``fx, fy, cx, cy`` in pixels. Every term is a mean over the pixels of its mask (sums in the paper;
means keep the weights independent of image size and batch).

* eq. 13 ``L_rec = ||D_dn - D_ref||_1 + ||D_dn - D_ref||_2``: mean absolute error plus the root
  mean square error (the L2 *norm*, as eq. 13 writes it), metres. The released code uses L1 + Huber
  instead (not an option here: the paper's form is unambiguous).
* eq. 12 ``L_dot = sum_i sum_{j in N4(i)} <P^i - P^j, N_ref^i>^2``: ``P`` the back-projected denoised
  depth, ``N_ref`` normals of the reference depth from four neighbours
  (:func:`methods.nn.geometry.normals_from_depth`), square metres. Zero on any plane that agrees
  with the reference normals.
* eq. 17 ``B(l, N, R) = R sum_b l_b H_b(N)`` with the nine second-order spherical-harmonic
  functions ``H = [1, y, z, x, xy, yz, 3z^2 - 1, zx, x^2 - y^2]`` (constant factors fold into ``l``).
* eq. 16 ``l* = argmin_l ||B(l, N_ref, R) - I||^2`` by ridge least squares (``ridge`` added to the
  normal equations, 1e-4 as in the released code), per image, on the **reference** normals.
* eq. 15 ``L_sh = ||B(l*, N_dt, R) - I||_2 + lambda_g ||grad B - grad I||_2``: root mean square of the
  rendered-minus-observed grey, plus ``lambda_g`` times the mean of the root mean squares of their
  forward differences along x and along y.
* eq. 18 ``L_fid = ||D_dt - D_ref||_2`` (root mean square, metres).
* eq. 19 ``L_smo``: anisotropic total variation, mean ``|D(i+1, j) - D(i, j)|`` over vertical pairs
  plus mean ``|D(i, j+1) - D(i, j)|`` over horizontal pairs (a ramp of slopes a, b gives ``|a| + |b|``).
* eq. 14 ``L_dt = lambda_sh L_sh + lambda_fid L_fid + lambda_smo L_smo``; eq. 13 ``L_dn = lambda_rec
  L_rec + lambda_dot L_dot``; eq. 20 ``L_total = L_dn + lambda L_dt``.

**Albedo** (``R`` in eq. 15-17). The paper takes it from Nestmeyer et al.'s CNN + filter intrinsic
decomposition, which needs a trained network we do not have. Choices (``albedo=``):

* ``"ratio"`` (default): ``R = I / B(l0, N_ref, 1)``, clipped to ``[0, 2]``, with ``l0`` the uniform-
  albedo lighting fit; computed without gradient. Texture is thereby explained as albedo, so
  the shading loss compares the shading of the refined normals with that of the reference
  normals under the fitted light instead of copying texture edges into the depth (the classic
  shading-refinement artefact on textured surfaces, which the simulator's mosaic textures would
  provoke). The released code carries this very formula commented out.
* ``"uniform"``: ``R = 1`` inside the mask: what the released code does.

In the released code the normal-dot term and the smoothness term are commented out; the loss here
has all five terms (``released_terms=True`` switches those two off for comparison).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn

from methods.nn.geometry import backproject

EPS = 1e-12


def masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of ``x`` over ``mask`` (broadcast over channels); 0 for an empty mask."""
    m = mask.to(x.dtype).expand_as(x)
    return (x * m).sum() / m.sum().clamp_min(1.0)


def _rms(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return torch.sqrt(masked_mean(x * x, mask) + EPS)


# ------------------------------------------------------------------------------------ eq. 13, 18
def reconstruction_loss(d: torch.Tensor, ref: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Eq. 13: mean ``|d - ref|`` plus root mean square of ``d - ref`` over ``mask``, metres."""
    r = torch.where(mask, d - ref, torch.zeros_like(d))
    return masked_mean(r.abs(), mask) + _rms(r, mask)


def fidelity_loss(d: torch.Tensor, ref: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Eq. 18: root mean square of ``d - ref`` over ``mask``, metres."""
    return _rms(torch.where(mask, d - ref, torch.zeros_like(d)), mask)


# ----------------------------------------------------------------------------------------- eq. 12
_N4 = ((0, 1), (0, -1), (1, 0), (-1, 0))


def _shift(x: torch.Tensor, dy: int, dx: int) -> torch.Tensor:
    """``x`` moved so that output pixel ``(i, j)`` holds ``x(i + dy, j + dx)`` (zeros outside)."""
    h, w = x.shape[-2:]
    out = torch.zeros_like(x)
    ys, yd = (slice(dy, h), slice(0, h - dy)) if dy >= 0 else (slice(0, h + dy), slice(-dy, h))
    xs, xd = (slice(dx, w), slice(0, w - dx)) if dx >= 0 else (slice(0, w + dx), slice(-dx, w))
    out[..., yd, xd] = x[..., ys, xs]
    return out


def normal_dot_loss(d: torch.Tensor, n_ref: torch.Tensor, K: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Eq. 12: mean over ``mask`` pixels ``i`` of ``sum_j <P^i - P^j, N_ref^i>^2`` over the four
    neighbours ``j`` inside ``mask``; square metres."""
    p = backproject(torch.where(mask, d, torch.zeros_like(d)), K)
    total = torch.zeros_like(d)
    for dy, dx in _N4:
        ok = mask & _shift(mask, dy, dx)
        dot = ((p - _shift(p, dy, dx)) * n_ref).sum(dim=1, keepdim=True)
        total = total + torch.where(ok, dot * dot, torch.zeros_like(dot))
    return masked_mean(total, mask)


# ------------------------------------------------------------------------------------- eq. 15-17
def sh_basis(n: torch.Tensor) -> torch.Tensor:
    """The nine second-order SH functions of unit normals ``(B, 3, H, W)`` -> ``(B, 9, H, W)``."""
    x, y, z = n[:, 0:1], n[:, 1:2], n[:, 2:3]
    return torch.cat([torch.ones_like(x), y, z, x, x * y, y * z, 3 * z * z - 1, z * x, x * x - y * y], dim=1)


def render_shading(light: torch.Tensor, n: torch.Tensor, albedo: torch.Tensor | float = 1.0) -> torch.Tensor:
    """Eq. 17: ``R sum_b l_b H_b(N)``; ``light`` ``(B, 9)``, ``n`` ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    return albedo * (sh_basis(n) * light[:, :, None, None]).sum(dim=1, keepdim=True)


def fit_lighting(n: torch.Tensor, image: torch.Tensor, mask: torch.Tensor, *,
                 albedo: torch.Tensor | float = 1.0, ridge: float = 1e-4) -> torch.Tensor:
    """Eq. 16: per image the ``l`` ``(B, 9)`` minimising ``sum_mask (R l.H(N) - I)^2 + ridge |l|^2``."""
    a = (sh_basis(n) * albedo * mask.to(n.dtype)).flatten(2)  # (B, 9, N)
    i = (image * mask.to(image.dtype)).flatten(2)  # (B, 1, N)
    ata = a @ a.transpose(1, 2) + ridge * torch.eye(9, dtype=n.dtype, device=n.device)
    return torch.linalg.solve(ata, (a @ i.transpose(1, 2)))[..., 0]


ALBEDOS = ("ratio", "uniform")


def estimate_albedo(n_ref: torch.Tensor, image: torch.Tensor, mask: torch.Tensor, *, kind: str = "ratio",
                    ridge: float = 1e-4) -> torch.Tensor:
    """The albedo ``R`` ``(B, 1, H, W)`` of the documented choice ``kind`` (no gradient)."""
    if kind not in ALBEDOS:
        raise ValueError(f"albedo must be one of {ALBEDOS}, got {kind!r}")
    m = mask.to(image.dtype)
    if kind == "uniform":
        return m
    with torch.no_grad():
        shade = render_shading(fit_lighting(n_ref, image, mask, ridge=ridge), n_ref)
        r = torch.where(shade > 1e-3, image / shade.clamp_min(1e-3), torch.ones_like(image))
        return r.clamp(0.0, 2.0) * m


def _grad_pairs(x: torch.Tensor, mask: torch.Tensor):
    """Forward differences along x and y with the masks of pairs inside ``mask``."""
    gx, gy = x[..., :, 1:] - x[..., :, :-1], x[..., 1:, :] - x[..., :-1, :]
    return (gx, mask[..., :, 1:] & mask[..., :, :-1]), (gy, mask[..., 1:, :] & mask[..., :-1, :])


def shading_loss(n_dt: torch.Tensor, n_ref: torch.Tensor, image: torch.Tensor, mask: torch.Tensor, *,
                 albedo: str = "ratio", lambda_g: float = 1.0, ridge: float = 1e-4) -> torch.Tensor:
    """Eq. 15 with ``l*`` from eq. 16 on the reference normals; ``mask`` where both normals are valid."""
    r = estimate_albedo(n_ref, image, mask, kind=albedo, ridge=ridge)
    light = fit_lighting(n_ref, image, mask, albedo=r, ridge=ridge).detach()
    b = render_shading(light, n_dt, r)
    loss = _rms(b - image, mask)
    for (gb, m), (gi, _) in zip(_grad_pairs(b, mask), _grad_pairs(image, mask)):
        loss = loss + lambda_g * _rms(gb - gi, m) / 2.0
    return loss


# ----------------------------------------------------------------------------------------- eq. 19
def tv_loss(d: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Eq. 19: mean ``|dD/dx|`` over horizontal pairs in ``mask`` plus mean ``|dD/dy|`` over vertical ones."""
    return sum(masked_mean(g.abs(), m) for g, m in _grad_pairs(d, mask))


# ------------------------------------------------------------------------------------- eq. 13-20
@dataclass
class DDRNetWeights:
    """The lambdas of eq. 13, 14, 15 and 20 (``lam`` is eq. 20's lambda)."""

    rec: float = 1.0
    dot: float = 30.0
    sh: float = 0.1
    grad: float = 1.0
    fid: float = 1.0
    smo: float = 0.01
    lam: float = 1.0


class DDRNetLoss(nn.Module):
    """Eq. 20 over a batch; ``forward`` returns ``(total, {term: value})`` (detached values in the dict).

    Args (keyword-only): ``weights`` (:class:`DDRNetWeights`), ``albedo`` (``"ratio"``/``"uniform"``),
    ``released_terms`` (drop eq. 12 and 19 as the released code does).
    """

    def __init__(self, *, weights: DDRNetWeights | None = None, albedo: str = "ratio", released_terms: bool = False) -> None:
        super().__init__()
        if albedo not in ALBEDOS:
            raise ValueError(f"albedo must be one of {ALBEDOS}, got {albedo!r}")
        self.w = weights or DDRNetWeights()
        self.albedo = albedo
        self.released_terms = released_terms

    def forward(self, *, d_dn: torch.Tensor, d_dt: torch.Tensor | None, ref: torch.Tensor, mask: torch.Tensor,
                K: torch.Tensor, grey: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
        from methods.nn.geometry import normals_from_depth

        w = self.w
        n_ref, n_ok = normals_from_depth(ref, K, mask)
        terms = {"rec": reconstruction_loss(d_dn, ref, mask)}
        terms["dot"] = normal_dot_loss(d_dn, n_ref, K, n_ok) if not self.released_terms else d_dn.new_zeros(())
        total = w.rec * terms["rec"] + w.dot * terms["dot"]
        if d_dt is not None:
            n_dt, dt_ok = normals_from_depth(d_dt, K, mask)
            terms["sh"] = shading_loss(n_dt, n_ref, grey, n_ok & dt_ok, albedo=self.albedo, lambda_g=w.grad)
            terms["fid"] = fidelity_loss(d_dt, ref, mask)
            terms["smo"] = tv_loss(d_dt, mask) if not self.released_terms else d_dt.new_zeros(())
            total = total + w.lam * (w.sh * terms["sh"] + w.fid * terms["fid"] + w.smo * terms["smo"])
        return total, {k: float(v.detach()) for k, v in terms.items()}
