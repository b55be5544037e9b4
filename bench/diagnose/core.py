"""``diagnose()``: the measured error model of each depth sensor of a capture (pure, no I/O).

For every sensor (:class:`bench.diagnose.data.SensorFrames`):

1. a reference per frame: the simulator's truth or a fused reference as given; inside a
   ChArUco board the robust plane fitted to the depth; elsewhere local planes
   (:func:`bench.diagnose.stats.tile_plane_reference`);
2. the residual ``depth - reference`` binned by reference depth: random error ``sigma(z)``
   (robust) and bias; the candidate models of :mod:`bench.diagnose.models` fitted, one chosen
   on held-out frames (or image blocks); for stereo the subpixel value ``c f B`` of Intel's
   ``RMS = z**2 subpixel / (f B)``;
3. fill rate against depth, brightness and texture; spatial correlation of the residual
   (white vs Gaussian-correlated); errors at depth edges; depth steps (quantisation);
   temporal noise between frames of one static view; far outliers;
4. with a board: its plane from the colour image (square units) against the depth's plane,
   per pose: the depth-implied board size, and which depth-error model explains how it
   changes with distance (:func:`board_scale_models`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bench.diagnose import models as M
from bench.diagnose import stats as S
from bench.diagnose.data import SensorFrames
from bench.errors import BenchError

#: residuals beyond this many robust sigmas (and 5 cm) are far outliers, not noise
OUTLIER_SIGMAS = 8.0
#: lags (px) at which the spatial correlation of the residual is measured
LAGS = (1, 2, 3, 4, 6, 8, 12, 16, 24)
#: frames the spatial correlation is measured on (evenly spaced)
CORRELATION_FRAMES = 16
#: bins of brightness (0-1) and of texture (local standard deviation of brightness, 7x7 px) for the fill rate
LUMINANCE_EDGES = np.linspace(0, 1, 11)
TEXTURE_EDGES = np.array([0, 0.005, 0.01, 0.02, 0.04, 0.08, 0.16, 0.5])


@dataclass
class SensorDiagnosis:
    """Everything measured on one sensor (metres unless named otherwise; see ``to_dict``)."""

    sensor: str
    model: str
    technology: str
    reference_kind: str
    frames: int
    shape: tuple[int, int]
    sigma: S.Binned
    sigma_models: M.Selection
    bias: S.Binned | None
    bias_models: M.Selection | None
    fill_depth: tuple[np.ndarray, np.ndarray, np.ndarray]
    fill_luminance: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    fill_texture: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    fill_rate: float
    rho: np.ndarray
    correlation_models: M.Selection
    position_bias: np.ndarray
    edges: S.EdgeErrors
    steps: tuple[np.ndarray, np.ndarray]
    outlier_fraction: float
    temporal: S.Binned | None
    board: dict | None
    derived: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        def arr(a):
            return None if a is None else [None if not np.isfinite(v) else float(v) for v in np.ravel(a)]

        def fill(t):
            return None if t is None else {"centre": arr(t[0]), "fill": arr(t[1]), "count": arr(t[2])}
        return {"sensor": self.sensor, "model": self.model, "technology": self.technology,
                "reference": self.reference_kind, "frames": self.frames, "shape": list(self.shape),
                "sigma_m": self.sigma.to_dict(), "sigma_models": self.sigma_models.to_dict(),
                "bias_m": None if self.bias is None else self.bias.to_dict(),
                "bias_models": None if self.bias_models is None else self.bias_models.to_dict(),
                "fill_rate": self.fill_rate, "fill_vs_depth": fill(self.fill_depth),
                "fill_vs_luminance": fill(self.fill_luminance), "fill_vs_texture": fill(self.fill_texture),
                "autocorrelation": arr(self.rho), "correlation_models": self.correlation_models.to_dict(),
                "position_bias_m": [arr(r) for r in self.position_bias], "edges": self.edges.to_dict(),
                "depth_steps_m": {"centre": arr(self.steps[0]), "step": arr(self.steps[1])},
                "outlier_fraction": self.outlier_fraction,
                "temporal_sigma_m": None if self.temporal is None else self.temporal.to_dict(),
                "board": self.board, "derived": self.derived, "notes": self.notes}


@dataclass
class DiagnoseResult:
    """The diagnosis of every sensor of one capture."""

    source: str
    sensors: dict[str, SensorDiagnosis]

    def to_dict(self) -> dict:
        return {"source": self.source, "sensors": {k: v.to_dict() for k, v in self.sensors.items()}}


# ----------------------------------------------------------------------------- references
def _board_reference(data: SensorFrames, i: int, rays_xy: np.ndarray) -> tuple[np.ndarray, S.Plane | None]:
    b = data.board[i]
    z = data.depth[i]
    m = b.mask & np.isfinite(z)
    if m.sum() < 100:
        return np.full(z.shape, np.nan, np.float32), None
    P = np.c_[rays_xy[m] * z[m][:, None], z[m]]
    plane = S.robust_plane(P)
    ref = np.where(b.mask, S.plane_depth(plane, rays_xy), np.nan).astype(np.float32)
    return ref, plane


def references(data: SensorFrames, rays_xy: np.ndarray, *, tile: int | None = None) -> tuple[list, list]:
    """Reference depth of every frame and, with a board, the depth's plane per frame."""
    tile = tile or max(12, int(round(data.intrinsics.width / 27)))
    refs, planes = [], []
    for i, z in enumerate(data.depth):
        if data.board[i] is not None:
            ref, plane = _board_reference(data, i, rays_xy)
        elif data.reference[i] is not None:
            ref, plane = data.reference[i], None
        else:
            ref, plane = S.tile_plane_reference(z, rays_xy, tile=tile), None
        refs.append(ref)
        planes.append(plane)
    return refs, planes


def _depth_edges(z: np.ndarray, *, bins: int = 12) -> np.ndarray:
    z = z[np.isfinite(z)]
    if z.size == 0:
        raise BenchError("no pixel has both a measurement and a reference")
    lo, hi = np.quantile(z, [0.005, 0.995])
    width = max((hi - lo) / bins, 0.02)
    return np.arange(lo, hi + width, width)


def _texture(lum: np.ndarray, window: int = 7) -> np.ndarray:
    import cv2

    m = cv2.blur(lum, (window, window))
    return np.sqrt(np.maximum(cv2.blur(lum * lum, (window, window)) - m * m, 0.0))


# ----------------------------------------------------------------------------- the diagnosis
def diagnose(sensors: list[SensorFrames], *, source: str = "") -> DiagnoseResult:
    """Diagnose every sensor (see the module docstring). Raises :class:`BenchError` when a
    sensor has no pixel with both a measurement and a reference."""
    return DiagnoseResult(source, {d.sensor: diagnose_sensor(d) for d in sensors})


def _halves(n: int, shape: tuple[int, int], block: int = 32) -> list[np.ndarray]:
    """Two disjoint halves as masks ``(n, H, W)``: frames by parity when there are 2+ frames,
    else alternate columns of ``block``-pixel blocks of the one frame."""
    if n >= 2:
        return [np.broadcast_to((np.arange(n) % 2 == k)[:, None, None], (n,) + shape) for k in (0, 1)]
    cols = (np.arange(shape[1]) // block) % 2 == 0
    return [np.broadcast_to(cols[None, None, :] == k, (n,) + shape) for k in (True, False)]


def _masked(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    return np.where(m, a, np.nan)


def diagnose_sensor(data: SensorFrames, *, depth_edges: np.ndarray | None = None) -> SensorDiagnosis:
    """Diagnose one sensor (see the module docstring); ``depth_edges``: the depth bins (metres;
    None: 12 bins over the 0.5-99.5 % range of the reference depths)."""
    K = data.intrinsics
    rays_xy = K.ray_grid()[..., :2].astype(np.float32)
    refs, planes = references(data, rays_xy)
    resid = [(z - r) for z, r in zip(data.depth, refs)]
    zref = np.stack(refs)
    res = np.stack(resid)
    edges = _depth_edges(np.where(np.isfinite(res), zref, np.nan)) if depth_edges is None else depth_edges
    # far outliers (e.g. the D435's 46 m pixels) are reported, then kept out of the noise statistics
    sig0 = S.robust_sigma(res[np.isfinite(res)])
    outlier = np.isfinite(res) & (np.abs(res) > max(OUTLIER_SIGMAS * sig0, 0.05))
    outlier_fraction = float(outlier.sum() / max(np.isfinite(res).sum(), 1))
    res_c = np.where(outlier, np.nan, res)
    # spatial correlation first: it sets the effective number of samples per pixel
    halves = _halves(len(res_c), res_c.shape[1:])
    # the correlation from at most CORRELATION_FRAMES evenly spaced frames (it is a property of the sensor)
    corr_idx = np.unique(np.linspace(0, len(res_c) - 1, min(len(res_c), CORRELATION_FRAMES)).round().astype(int))
    rho_frames = [S.autocorrelation(res_c[i], LAGS) for i in corr_idx]
    rho, pairs = _pool_rho(rho_frames)
    if len(rho_frames) >= 2:  # halves are frame subsets: reuse the per-frame correlations
        half_rho = [[rho_frames[i] for i in range(len(rho_frames)) if i % 2 == k] for k in (0, 1)]
    else:
        half_rho = [[S.autocorrelation(r, LAGS) for r in _masked(res_c, h)] for h in halves]
    corr = _correlation_selection(rho, pairs, half_rho)
    s_px = corr.best.params.get("s_px", 0.0) if corr.chosen == "gaussian" else 0.0
    area = max(1.0, 4 * np.pi * s_px ** 2)
    sigma = S.binned(zref, res_c, edges, area_px=area)
    half_bins = [S.binned(_masked(zref, h), _masked(res_c, h), edges, area_px=area) for h in halves]
    split = tuple(_bin_triplet(b, "sigma") for b in half_bins)
    sigma_sel = M.select("sigma", M.SIGMA_MODELS, _bin_triplet(sigma, "sigma"), split)
    bias = bias_sel = None
    if data.independent_reference:
        bias = sigma
        bsplit = tuple(_bin_triplet(b, "mean") for b in half_bins)
        bias_sel = M.select("bias", M.bias_models(data.fB), _bin_triplet(sigma, "mean"), bsplit)
    valid = np.isfinite(np.stack(data.depth))
    has_ref = np.isfinite(zref)
    fill_depth = (0.5 * (edges[1:] + edges[:-1]),) + S.fill_by(zref[has_ref], valid[has_ref], edges)
    fill_lum = fill_tex = None
    if all(lum is not None for lum in data.luminance):
        lum = np.stack(data.luminance)
        tex = np.stack([_texture(v) for v in data.luminance])
        le, te = LUMINANCE_EDGES, TEXTURE_EDGES
        fill_lum = (0.5 * (le[1:] + le[:-1]),) + S.fill_by(lum[has_ref], valid[has_ref], le)
        fill_tex = (0.5 * (te[1:] + te[:-1]),) + S.fill_by(tex[has_ref], valid[has_ref], te)
    edge = _edge_errors(data, refs)
    steps = (0.5 * (edges[1:] + edges[:-1]), S.depth_steps(np.stack(data.depth), edges))
    temporal = _temporal(data, zref, edges)
    diag = SensorDiagnosis(
        data.sensor, data.model, data.technology, data.reference_kind, len(data.depth), K.shape, sigma, sigma_sel,
        bias, bias_sel, fill_depth, fill_lum, fill_tex, float(valid[has_ref].mean()) if has_ref.any() else float("nan"),
        rho, corr, S.position_bias(_nanmean0(res_c)
                                   if data.independent_reference else res_c[0]),
        edge, steps, outlier_fraction, temporal, None, notes=list(data.notes))
    if any(b is not None for b in data.board):
        diag.board = board_analysis(data, planes)
    diag.derived = derived_parameters(diag, data)
    return diag


def _bin_triplet(b: S.Binned, what: str) -> tuple:
    y = b.sigma if what == "sigma" else b.mean
    return b.centre, y, b.sigma_se if what == "sigma" else b.sigma * np.sqrt(2) * b.sigma_se / np.maximum(b.sigma, 1e-12)


def _pool_rho(rho_frames) -> tuple[np.ndarray, np.ndarray]:
    R = np.array([r for r, _ in rho_frames])
    N = np.array([n for _, n in rho_frames], np.float64)
    w = np.where(np.isfinite(R), N, 0.0)
    with np.errstate(invalid="ignore"):
        rho = np.nansum(np.nan_to_num(R) * w, axis=0) / w.sum(axis=0)
    return rho, N.sum(axis=0)


def _correlation_selection(rho, pairs, half_frames) -> M.Selection:
    lags = np.asarray(LAGS, np.float64)

    def trip(r, n):
        return lags, r, np.maximum(0.02, 1 / np.sqrt(np.maximum(n, 1)))
    split = tuple(trip(*_pool_rho(h)) for h in half_frames)
    return M.select("correlation", M.CORRELATION_MODELS, trip(rho, pairs), split)


def _edge_errors(data: SensorFrames, refs) -> S.EdgeErrors:
    if not data.independent_reference:
        return S.EdgeErrors(0, float("nan"), float("nan"), float("nan"), float("nan"))
    per = [S.edge_errors(z, r) for z, r in zip(data.depth, refs)]
    n = sum(e.pixels for e in per)
    if n == 0:
        return per[0]

    def avg(k):
        vals = [(getattr(e, k), e.pixels) for e in per if e.pixels and np.isfinite(getattr(e, k))]
        return float(sum(v * w for v, w in vals) / max(sum(w for _, w in vals), 1))
    return S.EdgeErrors(n, avg("flying_fraction"), avg("fattened_fraction"), avg("missing_fraction"), avg("fattening_px"))


def _temporal(data: SensorFrames, zref: np.ndarray, edges: np.ndarray) -> S.Binned | None:
    """Pixel-wise standard deviation over frames of one static view (groups of 2+ frames)."""
    groups = np.asarray(data.group)
    dev, zs = [], []
    for g in np.unique(groups):
        idx = np.flatnonzero(groups == g)
        if len(idx) < 2:
            continue
        Z = np.stack([data.depth[i] for i in idx])
        ok = np.all(np.isfinite(Z), axis=0) & np.any(np.isfinite(zref[idx]), axis=0)
        mean = Z.mean(axis=0)
        # deviations from the per-pixel mean, scaled so that their spread is the per-frame sigma
        d = (Z - mean) * np.sqrt(len(idx) / (len(idx) - 1))
        dev.append(np.where(ok, d, np.nan))
        zs.append(np.broadcast_to(np.where(ok, mean, np.nan), d.shape))
    if not dev:
        return None
    return S.binned(np.concatenate([z.ravel() for z in zs]), np.concatenate([d.ravel() for d in dev]), edges)


# ----------------------------------------------------------------------------- board
def board_analysis(data: SensorFrames, planes) -> dict:
    """Per frame: the depth plane vs the colour-image board plane; per pose: the square length
    the depth implies (metres per square), and the depth-error models fitted across poses."""
    rows = []
    for i, (b, p) in enumerate(zip(data.board, planes)):
        if b is None or p is None:
            continue
        angle = float(np.degrees(np.arccos(min(1.0, abs(float(p.n @ b.n))))))
        rows.append({"frame": i, "pose": int(data.group[i]), "depth_plane_m": p.d, "board_plane_units": b.d_units,
                     "square_m": p.d / b.d_units, "angle_deg": angle, "plane_rms_m": p.rms_m,
                     "pose_rms_px": b.rms_px, "corners": b.n_corners,
                     "z_centre_m": float(np.nanmedian(np.where(b.mask, data.depth[i], np.nan)))})
    out = {"frames": rows}
    lens = lens_check(data)
    if lens:
        out["lens"] = lens
    if len({r["pose"] for r in rows}) >= 2:
        out["models"] = board_scale_models(np.array([r["board_plane_units"] for r in rows]),
                                           np.array([r["depth_plane_m"] for r in rows]),
                                           np.array([r["pose"] for r in rows]), fB=data.fB)
    return out


def lens_check(data: SensorFrames) -> dict | None:
    """Does the colour camera's undeclared lens distortion explain the board sizes? Fits the
    radial ``k1`` (focal length and principal point held) to the board corners of every pose and
    reports the reprojection RMS and the board distances (square units) with and without it."""
    import cv2

    views = {}
    for i, b in enumerate(data.board):
        if b is not None and b.corners_px is not None and data.group[i] not in views:
            views[data.group[i]] = b
    if len(views) < 1:
        return None
    K = data.intrinsics
    obj = [v.corners_board.astype(np.float32) for v in views.values()]
    img = [v.corners_px.astype(np.float32) for v in views.values()]
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_FOCAL_LENGTH | cv2.CALIB_FIX_PRINCIPAL_POINT
             | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    rms, _, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, (K.width, K.height), K.K.copy(), np.zeros(5), flags=flags)
    d_with = {}
    for g, rv, tv in zip(views, rvecs, tvecs):
        R = cv2.Rodrigues(rv)[0]
        d_with[int(g)] = float(abs(np.asarray(tv).ravel() @ R[:, 2]))
    d_without = {int(g): v.d_units for g, v in views.items()}
    poses = sorted(d_with)
    ratio = (d_with[poses[0]] / d_without[poses[0]]) / (d_with[poses[-1]] / d_without[poses[-1]])
    return {"k1": float(dist.ravel()[0]), "rms_px_with_k1": float(rms),
            "rms_px_without": float(np.mean([v.rms_px for v in views.values()])),
            "board_units_with_k1": d_with, "board_units_without": d_without,
            "near_far_size_change_from_k1": float(1 / ratio - 1)}


def board_scale_models(d_units: np.ndarray, d_depth: np.ndarray, pose: np.ndarray, *, fB: float | None) -> dict:
    """Which depth error explains the depth-implied board size across poses.

    ``d_units``: distance of the board plane from the colour pose in square units; ``d_depth``:
    of the depth's plane in metres. With the square length ``s`` unknown, the true distance is
    ``s * d_units`` and the candidates are: ``scale`` (``d = k s d_units``: a wrong depth unit,
    depth scale or focal length -- indistinguishable from ``s`` itself, so the size is the same in
    every pose), ``offset`` (``d = s d_units + b``), ``disparity_offset`` (stereo:
    ``1/d = 1/(s d_units) + delta / (f B)``). Fitted by least squares on frames, chosen by
    leave-one-frame-out prediction error (mm), then AICc.
    """
    def f_scale(p, u):
        return p[0] * u

    def f_off(p, u):
        return p[0] * u + p[1]

    def f_disp(p, u):
        return 1.0 / (1.0 / (p[0] * u) + p[1] / fB)

    cands = {"scale": (f_scale, [np.median(d_depth / d_units)]),
             "offset": (f_off, [np.median(d_depth / d_units), 0.0])}
    if fB:
        cands["disparity_offset"] = (f_disp, [np.median(d_depth / d_units), 0.0])
    from scipy.optimize import least_squares

    out = {}
    n = len(d_units)
    for name, (f, p0) in cands.items():
        r = least_squares(lambda p: f(p, d_units) - d_depth, p0)
        rss = float(np.sum(r.fun ** 2))
        k = len(p0)
        sigma2 = max(rss / n, 1e-12)
        aicc = n * np.log(sigma2) + 2 * k + (2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else np.inf)
        lopo, lofo = [], []
        for held, groups in ((lopo, pose), (lofo, np.arange(n))):
            for g in np.unique(groups):
                tr = groups != g
                rr = least_squares(lambda p: f(p, d_units[tr]) - d_depth[tr], p0)
                held.extend((f(rr.x, d_units[~tr]) - d_depth[~tr]).tolist())
        params = {"square_m": float(r.x[0])}
        if name == "offset":
            params["offset_m"] = float(r.x[1])
        if name == "disparity_offset":
            params["delta_px"] = float(r.x[1])
        out[name] = {"params": params, "rms_mm": float(np.sqrt(rss / n) * 1000), "aicc": float(aicc),
                     "leave_one_frame_out_rms_mm": float(np.sqrt(np.mean(np.square(lofo))) * 1000),
                     "leave_one_pose_out_rms_mm": float(np.sqrt(np.mean(np.square(lopo))) * 1000)}
    # held out frame by frame (with three poses, leaving a whole pose out extrapolates a 2-parameter
    # model from two distances: reported, not used); AICc breaks near-ties (within 10 %)
    best = min(out[k]["leave_one_frame_out_rms_mm"] for k in cands)
    out["chosen"] = min((k for k in cands if out[k]["leave_one_frame_out_rms_mm"] <= 1.1 * best),
                        key=lambda k: out[k]["aicc"])
    return out


# ----------------------------------------------------------------------------- derived parameters
def derived_parameters(d: SensorDiagnosis, data: SensorFrames) -> dict:
    """The numbers the simulator's noise model takes, read off the chosen/fitted models."""
    out: dict = {}
    quad = next(f for f in d.sigma_models.fits if f.model == "quadratic")
    fq = next(f for f in d.sigma_models.fits if f.model == "floor_quadratic")
    lin = next(f for f in d.sigma_models.fits if f.model == "linear")
    if data.fB:
        out["subpixel_px"] = quad.params["c"] * data.fB
        out["subpixel_px_error"] = quad.errors.get("c", float("nan")) * data.fB
        out["floor_quadratic_subpixel_px"] = fq.params["c"] * data.fB
        out["noise_floor_m"] = fq.params["a"]
        out["fB_px_m"] = data.fB
    out["sigma_linear_a_m"], out["sigma_linear_b"] = lin.params.get("a"), lin.params.get("b")
    cg = next(f for f in d.correlation_models.fits if f.model == "gaussian")
    out["correlation_px"] = cg.params.get("s_px") if d.correlation_models.chosen == "gaussian" else 0.0
    out["correlation_px_fit"] = cg.params.get("s_px")
    out["outlier_fraction"] = d.outlier_fraction
    out["fill_rate"] = d.fill_rate
    # the pixels the simulator parameters are given in: the matcher's for stereo, else the image's
    out["native_focal_px"] = float(data.stereo_focal_px or data.intrinsics.fx)
    if d.bias_models is not None:
        out["bias_model"] = d.bias_models.chosen
        out["bias_params"] = d.bias_models.best.params
    if d.board and "models" in d.board:
        m = d.board["models"]
        out["board_model"] = m["chosen"]
        out["board_params"] = m[m["chosen"]]["params"]
    return out


def _nanmean0(a: np.ndarray) -> np.ndarray:
    """Mean over frames ignoring NaN (NaN where no frame has a value, without a warning)."""
    n = np.isfinite(a).sum(axis=0)
    s = np.where(np.isfinite(a), a, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)
