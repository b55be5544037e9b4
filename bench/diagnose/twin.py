"""The simulated twin of a capture and the sim-to-real distance per statistic (pure).

The twin films the *measured scene*: each real frame's reference surfaces (the ChArUco board
where the colour image sees it, at the fitted board size; the local planes; the fused
reference; the truth) are the true depth, the real colour image's brightness is the
brightness, and the simulator's own noise functions
(:func:`capture.sim.noise.stereo_depth`, :func:`capture.sim.noise.tof_depth`) make the depth.
:func:`bench.diagnose.core.diagnose` then measures the twin exactly as it measured the capture.

:func:`stages` builds the noise model step by step -- the simulator's default sensor, then each
effect the diagnosis fitted, cumulatively -- so the report shows the distance before and after
each added effect. :func:`noise_from_diagnosis` is the fitted model (what
``capture/sim/sensor_profiles.json`` stores).

The twin is a random draw of the simulated noise, and for a capture of a few frames its spread
is as large as an effect (D415, 2 frames: the sigma distance after the fitted subpixel reads
10.1 / 7.5 / 9.5 % with twin seeds 0 / 1 / 2). So every stage is measured with
:data:`TWIN_SEEDS` twins (seeds ``seed .. seed + n - 1``, the same draws for every stage) and
:func:`sim_to_real` decides on the mean distance over them; the report gives each mean with its
standard error, and each decision the paired change with its standard error.
"""
from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np

from bench.diagnose.core import LUMINANCE_EDGES, TEXTURE_EDGES, DiagnoseResult, SensorDiagnosis, diagnose_sensor, references
from bench.diagnose.data import SensorFrames
from bench.errors import BenchError
from capture.sim.noise import StereoNoise, TofNoise, stereo_depth, tof_depth


def _fit(d: SensorDiagnosis, model: str):
    return next(f for f in d.sigma_models.fits if f.model == model)


def stages(d: SensorDiagnosis, data: SensorFrames) -> list[tuple[str, StereoNoise | TofNoise]]:
    """``[(label, noise model)]``: the default sensor, then each diagnosed effect added in turn."""
    der = d.derived
    corr = _native_px(der.get("correlation_px") or 0.0, data)
    # the random error and its spatial correlation are one effect: a smaller matching noise leaves
    # a larger (white) quantisation share, which lowers the correlation, and the other way round
    if data.technology == "tof":
        out = [("default", TofNoise())]
        lin = _fit(d, "linear")
        a, b = max(lin.params["a"], 0.0), max(lin.params["b"], 0.0)
        out.append(("+ fitted sigma(z), correlation", replace(out[-1][1], sigma0_m=a, sigma_slope=b, z0_m=0.0,
                                                               correlation_px=corr)))
    else:
        step = 1 / 8 if data.technology == "structured_light" else 1 / 32
        base = StereoNoise(baseline_m=data.baseline_m or 0.055, disparity_step_px=step)
        out = [("default", base),
               ("+ fitted subpixel (z^2), correlation",
                replace(base, subpixel_px=matching_subpixel(der["subpixel_px"], step), correlation_px=corr))]
        if der.get("noise_floor_m", 0) > 1e-4:
            out.append(("+ noise floor", replace(out[-1][1], noise_floor_m=der["noise_floor_m"],
                                                 subpixel_px=matching_subpixel(der["floor_quadratic_subpixel_px"], step))))
        thresholds = dropout_thresholds(d)
        if thresholds:
            out.append(("+ dropout thresholds", replace(out[-1][1], **thresholds)))
    if der.get("outlier_fraction", 0) > 0:
        out.append(("+ outliers", replace(out[-1][1], outlier_fraction=der["outlier_fraction"])))
    if der.get("board_model") == "offset" and data.technology != "tof":
        out.append(("+ depth offset", replace(out[-1][1], depth_offset_m=der["board_params"]["offset_m"])))
    if der.get("board_model") == "disparity_offset" and data.technology != "tof":
        out.append(("+ disparity offset", replace(out[-1][1], disparity_offset_px=der["board_params"]["delta_px"])))
    return out


def matching_subpixel(measured_px: float, step_px: float) -> float:
    """The simulator's matching noise (px) whose sum with the quantisation of the disparity to
    ``step_px`` (variance ``step**2 / 12``) has the measured spread ``measured_px``.

    >>> round(matching_subpixel(float(np.hypot(0.06, 0.125 / np.sqrt(12))), 0.125), 6)
    0.06
    """
    return float(np.sqrt(max(measured_px ** 2 - step_px ** 2 / 12, 0.0)))


def dropout_thresholds(d: SensorDiagnosis) -> dict:
    """``min_luminance`` / ``min_contrast`` of the stereo model read off the measured fill rate
    against brightness and texture: the upper edge of the highest bin (from the bottom, in a
    row) where fewer than half the pixels are measured; 0 when even the darkest / flattest bin
    is mostly measured (an active sensor with its own pattern). Empty without a colour image."""
    out = {}
    for key, table, edges in (("min_luminance", d.fill_luminance, LUMINANCE_EDGES),
                              ("min_contrast", d.fill_texture, TEXTURE_EDGES)):
        if table is None:
            continue
        fill = table[1]
        k = 0
        while k < len(fill) and np.isfinite(fill[k]) and fill[k] < 0.5:
            k += 1
        if np.isfinite(fill[0]) or k > 0:
            out[key] = float(edges[k]) if k > 0 else 0.0
    return out


def _native_px(px_in_image: float, data: SensorFrames) -> float:
    """Correlation length in the matcher's pixels (the D435's depth is resampled to 1920x1080)."""
    if data.stereo_focal_px:
        return float(px_in_image * data.stereo_focal_px / data.intrinsics.fx)
    return float(px_in_image)


def noise_from_diagnosis(d: SensorDiagnosis, data: SensorFrames) -> StereoNoise | TofNoise:
    """The fitted noise model (the last stage), parameters in the sensor's native pixels."""
    return stages(d, data)[-1][1]


def twin(data: SensorFrames, noise: StereoNoise | TofNoise, *, seed: int = 0,
         square_m: float | None = None) -> SensorFrames:
    """The capture re-filmed by the simulator with ``noise`` (see the module docstring).

    ``square_m``: with a ChArUco board, the board's square length (metres, as the diagnosis
    fitted it): the true surface is then the board where the colour camera sees it (its pose
    scaled to metres), not the plane fitted to the real depth, which carries the real bias."""
    K = data.intrinsics
    rays = K.ray_grid()
    refs, _ = references(data, rays[..., :2].astype(np.float32))
    if square_m:
        from bench.diagnose.stats import Plane, plane_depth

        for i, b in enumerate(data.board):
            if b is not None:
                refs[i] = np.where(b.mask, plane_depth(Plane(b.n, square_m * b.d_units, 0.0, 1.0),
                                                       rays[..., :2]), np.nan).astype(np.float32)
    depth = []
    for i, ref in enumerate(refs):
        rng = np.random.default_rng([seed, i])
        # without a colour image: a textured surface (no dropouts for lack of texture)
        lum = data.luminance[i] if data.luminance[i] is not None else \
            rng.uniform(0.3, 0.7, K.shape).astype(np.float32)
        z_true = _fill_nearest(ref)
        if isinstance(noise, TofNoise):
            # no mixed pixels: the reference surfaces are planes separated by the filled holes,
            # whose artificial depth jumps would mix inside the planes the statistics use
            nd = tof_depth(z_true, lum, noise=replace(noise, flying_fraction=0.0), rng=rng)
        else:
            # the matcher's focal length sets the disparity; the correlation is given in its pixels
            scale = K.fx / data.stereo_focal_px if data.stereo_focal_px else 1.0
            nz = replace(noise, correlation_px=noise.correlation_px * scale,
                         noise_floor_m=noise.noise_floor_m)
            fx = data.stereo_focal_px or K.fx
            nd = stereo_depth(z_true, rays[..., 0].astype(np.float32), lum, noise=nz, fx=fx, cx=K.cx * fx / K.fx,
                              rng=rng)
        depth.append(np.where(np.isfinite(ref), nd.depth, np.nan).astype(np.float32))
    reference = [r if data.reference[i] is not None else None for i, r in enumerate(data.reference)]
    return replace(data, depth=depth, reference=reference, notes=[])


def _fill_nearest(ref: np.ndarray) -> np.ndarray:
    """The reference with its holes filled by the nearest reference pixel (so that the
    simulator sees no artificial depth edges at the borders of the reference surfaces)."""
    from scipy.ndimage import distance_transform_edt

    hole = ~np.isfinite(ref)
    if not hole.any() or hole.all():
        return ref.astype(np.float32)
    idx = distance_transform_edt(hole, return_distances=False, return_indices=True)
    return ref[idx[0], idx[1]].astype(np.float32)


# ----------------------------------------------------------------------------- distances
def statistics(d: SensorDiagnosis) -> dict[str, float | np.ndarray]:
    """The statistics compared between a capture and its twin."""
    out = {"sigma_m": d.sigma.sigma, "fill_rate": d.fill_rate, "rho_lag1": float(d.rho[0]),
           "rho_lag4": float(d.rho[3]), "outlier_fraction": d.outlier_fraction}
    if d.bias is not None:
        out["bias_m"] = d.bias.mean
    if d.board and d.board.get("frames"):
        rows = d.board["frames"]
        by = {}
        for r in rows:
            by.setdefault(r["pose"], []).append(r["square_m"])
        poses = sorted(by)
        out["board_near_far_ratio"] = float(np.mean(by[poses[0]]) / np.mean(by[poses[-1]]))
    return out


def distance(real, sim, *, relative: bool = False) -> float:
    """Per statistic: arrays -> median over the bins both have of ``|sim/real - 1|`` (``relative``,
    sigma) or ``|sim - real|`` (bias, metres); scalars -> ``|sim - real|``."""
    if isinstance(real, np.ndarray):
        ok = np.isfinite(real) & np.isfinite(sim)
        if not ok.any():
            return float("nan")
        d = np.abs(sim[ok] - real[ok])
        return float(np.median(d / np.abs(real[ok]) if relative else d))
    return float(abs(sim - real))


#: twins (random draws of the simulated noise) each stage is measured with; the stage rule uses their mean
TWIN_SEEDS = 3

#: how much a statistic may move before it counts as worse (simulation noise of the twin)
TOLERANCE = {"sigma_m": 0.01, "fill_rate": 0.005, "rho_lag1": 0.02, "rho_lag4": 0.02, "outlier_fraction": 0.002,
             "bias_m": 0.1, "board_near_far_ratio": 0.003}


def _scale_amplitude(noise, k: float):
    """The noise model with its random-error amplitude multiplied by ``k``."""
    if isinstance(noise, TofNoise):
        return replace(noise, sigma0_m=noise.sigma0_m * k, sigma_slope=noise.sigma_slope * k)
    return replace(noise, subpixel_px=noise.subpixel_px * k)


def worse_statistics(before: dict, after: dict) -> list[str]:
    """Statistics whose distance grew by more than 5 % plus :data:`TOLERANCE`."""
    return [k for k in before if not k.startswith("_") and np.isfinite(before[k]) and
            (not np.isfinite(after[k]) or after[k] > 1.05 * before[k] + TOLERANCE.get(k, 0.0))]


def sim_to_real(data: SensorFrames, d: SensorDiagnosis, *, seed: int = 0, twin_seeds: int | None = None) -> dict:
    """Distances per statistic for every stage of :func:`stages`, each the mean over ``twin_seeds``
    twins (None: :data:`TWIN_SEEDS`) with seeds ``seed, seed + 1, ...``.

    Each stage's change is applied on top of the last *kept* model; the fitted random error is
    re-scaled once so that the twin reads the measured sigma (plane fits absorb part of correlated
    noise); a stage that makes any statistic worse on the mean over the twins
    (:func:`worse_statistics`) is reported and rejected. ``final`` is the kept model;
    ``values[stage]`` the mean distances, ``standard_errors[stage]`` their standard errors over the
    twins, ``per_seed[stage]`` each twin's.
    """
    n = TWIN_SEEDS if twin_seeds is None else twin_seeds
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise BenchError(f"twin seeds: {n!r} must be a positive integer")
    real = statistics(d)
    dropped = []
    if data.reference_kind == "planes":
        # local planes are kept only where the sensor measured most pixels: their fill is biased
        real.pop("fill_rate")
        dropped.append("fill_rate not compared: local-plane references are chosen where the sensor measured")
    c = d.sigma.centre
    w = np.diff(c).mean() if len(c) > 1 else 0.05
    edges = np.r_[c - w / 2, c[-1] + w / 2]

    square = (d.derived.get("board_params") or {}).get("square_m")

    def measure(noise) -> dict:
        """Mean distances over the twins; ``_runs``: each twin's."""
        runs = [measure_one(noise, s) for s in range(seed, seed + n)]
        out = {k: float(np.mean([r[k] for r in runs])) for k in runs[0]}
        return out | {"_runs": runs}

    def measure_one(noise, twin_seed: int) -> dict:
        st = statistics(diagnose_sensor(twin(data, noise, seed=twin_seed, square_m=square), depth_edges=edges))
        out = {k: distance(v, st.get(k, np.nan), relative=k == "sigma_m") for k, v in real.items()}
        if "bias_m" in real:  # bias in units of the measured random error (its bins' spread scales with it)
            out["bias_m"] = distance(real["bias_m"] / real["sigma_m"], st["bias_m"] / real["sigma_m"])
        ok = np.isfinite(real["sigma_m"]) & np.isfinite(st["sigma_m"])
        out["_sigma_ratio"] = float(np.median(real["sigma_m"][ok] / st["sigma_m"][ok])) if ok.any() else 1.0
        return out

    def calibrated(noise, v: dict):
        """A fitted noise amplitude re-scaled once so that the twin's measured sigma matches
        (correlated noise is partly absorbed by the plane fits, so it reads lower than it is)."""
        k = v["_sigma_ratio"]
        if abs(k - 1) < 0.03:
            return noise, v
        scaled = _scale_amplitude(noise, k)
        v2 = measure(scaled)
        return (scaled, v2) if v2["sigma_m"] < v["sigma_m"] else (noise, v)

    st = stages(d, data)
    kept_label, kept = st[0]
    values = {kept_label: measure(kept)}
    labels, notes = [kept_label], dropped + [f"{kept_label}: {_describe(kept)}"]
    prev = kept
    for label, target in st[1:]:
        changes = {k: v for k, v in asdict(target).items() if v != getattr(prev, k)}
        prev = target
        noise = replace(kept, **changes)
        v = measure(noise)
        if label.startswith("+ fitted"):
            noise, v = calibrated(noise, v)
        worse = worse_statistics(values[kept_label], v)
        change = _paired_changes(values[kept_label], v, worse or list(real))
        if worse:
            label = f"{label} (rejected)"
            notes.append(f"{label}: makes {', '.join(worse)} worse ({change}); not kept ({_describe(noise)})")
        else:
            kept_label, kept = label, noise
            notes.append(f"{label}: kept ({_describe(noise)}); {change}")
        values[label] = v
        labels.append(label)

    return _tables(real, values, labels, seeds=list(range(seed, seed + n))) | {
        "notes": notes, "final_stage": kept_label, "final": kept.to_dict()}


def _tables(real: dict, values: dict, labels: list[str], *, seeds: list[int]) -> dict:
    """The result's tables: the mean distance per stage and statistic (``values``), its standard
    error over the twins, each twin's, and the report's formatted table."""
    per_seed = {s: [{k: r[k] for k in real} for r in vals["_runs"]] for s, vals in values.items()}
    errors = {s: {k: _standard_error([r[k] for r in runs]) for k in real} for s, runs in per_seed.items()}
    means = {s: {k: v for k, v in vals.items() if not k.startswith("_")} for s, vals in values.items()}
    table = {k: {"real": _fmt_real(v), "distance": {s: _fmt(k, means[s][k], errors[s][k]) for s in labels}}
             for k, v in real.items()}
    return {"stages": labels, "statistics": table, "values": means, "standard_errors": errors, "per_seed": per_seed,
            "twin_seeds": seeds}


def _fmt(k: str, v: float, se: float) -> str:
    """A distance for the report (with ``± standard error`` when there were several twins)."""
    if not np.isfinite(v):
        return "-"
    pm = np.isfinite(se)
    if k in ("sigma_m", "fill_rate", "outlier_fraction", "board_near_far_ratio"):
        return f"{100 * v:.1f} ± {100 * se:.1f} %" if pm else f"{100 * v:.1f} %"
    digits = 2 if k == "bias_m" else 3
    text = f"{v:.{digits}f}" + (f" ± {se:.{digits}f}" if pm else "")
    return text + " sigma" if k == "bias_m" else text


def _fmt_real(v) -> str:
    if isinstance(v, np.ndarray):
        return ", ".join(f"{1000 * x:.1f}" for x in v if np.isfinite(x)) + " mm"
    return f"{v:.4f}"


def _standard_error(x: list[float]) -> float:
    """Standard error of the mean of ``x`` (NaN for fewer than two finite values)."""
    x = np.asarray(x, dtype=float)
    return float(np.std(x, ddof=1) / np.sqrt(len(x))) if len(x) > 1 and np.isfinite(x).all() else float("nan")


def _paired_changes(before: dict, after: dict, keys: list[str]) -> str:
    """``key +change ± standard error`` over the twins (the same seeds before and after: paired)
    against the allowance of :func:`worse_statistics`, for ``keys``."""
    parts = []
    for k in keys:
        if k not in before or not np.isfinite(before[k]):
            continue
        delta = [a[k] - b[k] for a, b in zip(after["_runs"], before["_runs"])]
        allow = 0.05 * before[k] + TOLERANCE.get(k, 0.0)
        se = _standard_error(delta)
        pm = f" ± {se:.2g}" if np.isfinite(se) else ""
        parts.append(f"{k} {np.mean(delta):+.4g}{pm} (allowed {allow:.3g})")
    return "change of the mean over the twins: " + ", ".join(parts)


def _describe(noise) -> str:
    keys = ("subpixel_px", "noise_floor_m", "correlation_px", "outlier_fraction", "depth_offset_m",
            "disparity_offset_px", "min_luminance", "min_contrast", "sigma0_m", "sigma_slope", "z0_m")
    d = noise.to_dict()
    return ", ".join(f"{k} = {d[k]:.4g}" for k in keys if k in d)


def sim_to_real_tables(frames: list[SensorFrames], result: DiagnoseResult, *, seed: int = 0,
                       twin_seeds: int | None = None) -> dict:
    """:func:`sim_to_real` for every sensor of a diagnosis."""
    out = {}
    for f in frames:
        if f.technology != "tof" and not f.fB:
            out[f.sensor] = {"stages": [], "statistics": {}, "values": {}, "final_stage": None, "final": None,
                             "notes": ["no stereo geometry (focal length x baseline) known: no simulated twin"]}
            continue
        out[f.sensor] = sim_to_real(f, result.sensors[f.sensor], seed=seed, twin_seeds=twin_seeds)
    return out
