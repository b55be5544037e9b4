"""The simulated twin of a capture and the sim-to-real distance per statistic (pure).

The twin films the *measured scene*: each real frame's reference surfaces (the board plane,
the local planes, the fused reference or the truth) are the true depth, the real colour image's
brightness is the brightness, and the simulator's own noise functions
(:func:`capture.sim.noise.stereo_depth`, :func:`capture.sim.noise.tof_depth`) make the depth.
:func:`bench.diagnose.core.diagnose` then measures the twin exactly as it measured the capture.

:func:`stages` builds the noise model step by step -- the simulator's default sensor, then each
effect the diagnosis fitted, cumulatively -- so the report shows the distance before and after
each added effect. :func:`noise_from_diagnosis` is the fitted model (what
``capture/sim/sensor_profiles.json`` stores).
"""
from __future__ import annotations

from dataclasses import asdict, replace

import numpy as np

from bench.diagnose.core import DiagnoseResult, SensorDiagnosis, diagnose_sensor, references
from bench.diagnose.data import SensorFrames
from capture.sim.noise import StereoNoise, TofNoise, stereo_depth, tof_depth


def _fit(d: SensorDiagnosis, model: str):
    return next(f for f in d.sigma_models.fits if f.model == model)


def stages(d: SensorDiagnosis, data: SensorFrames) -> list[tuple[str, StereoNoise | TofNoise]]:
    """``[(label, noise model)]``: the default sensor, then each diagnosed effect added in turn."""
    der = d.derived
    corr = _native_px(der.get("correlation_px") or 0.0, data)
    if data.technology == "tof":
        out = [("default", TofNoise())]
        out.append(("+ correlation", replace(out[-1][1], correlation_px=corr)))
        lin = _fit(d, "linear")
        a, b = max(lin.params["a"], 0.0), max(lin.params["b"], 0.0)
        out.append(("+ fitted sigma(z)", replace(out[-1][1], sigma0_m=a, sigma_slope=b, z0_m=0.0)))
    else:
        step = 1 / 8 if data.technology == "structured_light" else 1 / 32
        base = StereoNoise(baseline_m=data.baseline_m or 0.055, disparity_step_px=step)
        out = [("default", base), ("+ correlation", replace(base, correlation_px=corr))]
        out.append(("+ fitted subpixel (z^2)", replace(out[-1][1], subpixel_px=der["subpixel_px"])))
        if der.get("noise_floor_m", 0) > 1e-4:
            out.append(("+ noise floor", replace(out[-1][1], subpixel_px=der["floor_quadratic_subpixel_px"],
                                                 noise_floor_m=der["noise_floor_m"])))
    if der.get("outlier_fraction", 0) > 0:
        out.append(("+ outliers", replace(out[-1][1], outlier_fraction=der["outlier_fraction"])))
    if der.get("board_model") == "offset" and data.technology != "tof":
        out.append(("+ depth offset", replace(out[-1][1], depth_offset_m=der["board_params"]["offset_m"])))
    if der.get("board_model") == "disparity_offset" and data.technology != "tof":
        out.append(("+ disparity offset", replace(out[-1][1], disparity_offset_px=der["board_params"]["delta_px"])))
    return out


def _native_px(px_in_image: float, data: SensorFrames) -> float:
    """Correlation length in the matcher's pixels (the D435's depth is resampled to 1920x1080)."""
    if data.stereo_focal_px:
        return float(px_in_image * data.stereo_focal_px / data.intrinsics.fx)
    return float(px_in_image)


def noise_from_diagnosis(d: SensorDiagnosis, data: SensorFrames) -> StereoNoise | TofNoise:
    """The fitted noise model (the last stage), parameters in the sensor's native pixels."""
    return stages(d, data)[-1][1]


def twin(data: SensorFrames, noise: StereoNoise | TofNoise, *, seed: int = 0) -> SensorFrames:
    """The capture re-filmed by the simulator with ``noise`` (see the module docstring)."""
    K = data.intrinsics
    rays = K.ray_grid()
    refs, _ = references(data, rays[..., :2].astype(np.float32))
    depth = []
    for i, ref in enumerate(refs):
        rng = np.random.default_rng([seed, i])
        # without a colour image: a textured surface (no dropouts for lack of texture)
        lum = data.luminance[i] if data.luminance[i] is not None else \
            rng.uniform(0.3, 0.7, K.shape).astype(np.float32)
        z_true = _fill_nearest(ref)
        if isinstance(noise, TofNoise):
            nd = tof_depth(z_true, lum, noise=noise, rng=rng)
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


#: how much a statistic may move before it counts as worse (simulation noise of the twin)
TOLERANCE = {"sigma_m": 0.01, "fill_rate": 0.005, "rho_lag1": 0.02, "rho_lag4": 0.02, "outlier_fraction": 0.002,
             "bias_m": 0.1, "board_near_far_ratio": 0.003}


def worse_statistics(before: dict, after: dict) -> list[str]:
    """Statistics whose distance grew by more than 5 % plus :data:`TOLERANCE`."""
    return [k for k in before if np.isfinite(before[k]) and
            (not np.isfinite(after[k]) or after[k] > 1.05 * before[k] + TOLERANCE.get(k, 0.0))]


def sim_to_real(data: SensorFrames, d: SensorDiagnosis, *, seed: int = 0) -> dict:
    """Distances per statistic for every stage of :func:`stages`.

    Each stage's change is applied on top of the last *kept* model; a stage that makes any
    statistic worse (:func:`worse_statistics`) is reported and rejected. ``final`` is the kept model.
    """
    real = statistics(d)
    c = d.sigma.centre
    w = np.diff(c).mean() if len(c) > 1 else 0.05
    edges = np.r_[c - w / 2, c[-1] + w / 2]

    def measure(noise) -> dict:
        st = statistics(diagnose_sensor(twin(data, noise, seed=seed), depth_edges=edges))
        out = {k: distance(v, st.get(k, np.nan), relative=k == "sigma_m") for k, v in real.items()}
        if "bias_m" in real:  # bias in units of the measured random error (its bins' spread scales with it)
            out["bias_m"] = distance(real["bias_m"] / real["sigma_m"], st["bias_m"] / real["sigma_m"])
        return out

    st = stages(d, data)
    kept_label, kept = st[0]
    values = {kept_label: measure(kept)}
    labels, notes = [kept_label], [f"{kept_label}: {_describe(kept)}"]
    prev = kept
    for label, target in st[1:]:
        changes = {k: v for k, v in asdict(target).items() if v != getattr(prev, k)}
        prev = target
        noise = replace(kept, **changes)
        v = measure(noise)
        worse = worse_statistics(values[kept_label], v)
        if worse:
            label = f"{label} (rejected)"
            notes.append(f"{label}: makes {', '.join(worse)} worse; not kept ({_describe(noise)})")
        else:
            kept_label, kept = label, noise
            notes.append(f"{label}: kept ({_describe(noise)})")
        values[label] = v
        labels.append(label)

    def fmt(k, v):
        if not np.isfinite(v):
            return "-"
        return f"{100 * v:.1f} %" if k in ("sigma_m", "fill_rate", "outlier_fraction", "board_near_far_ratio") \
            else f"{v:.2f} sigma" if k == "bias_m" else f"{v:.3f}"

    def fmt_real(k, v):
        if isinstance(v, np.ndarray):
            return ", ".join(f"{1000 * x:.1f}" for x in v if np.isfinite(x)) + " mm"
        return f"{v:.4f}"
    table = {k: {"real": fmt_real(k, v), "distance": {s: fmt(k, values[s][k]) for s in labels}} for k, v in real.items()}
    return {"stages": labels, "statistics": table, "values": values, "notes": notes, "final_stage": kept_label,
            "final": kept.to_dict()}


def _describe(noise) -> str:
    keys = ("subpixel_px", "noise_floor_m", "correlation_px", "outlier_fraction", "depth_offset_m",
            "disparity_offset_px", "sigma0_m", "sigma_slope", "z0_m")
    d = noise.to_dict()
    return ", ".join(f"{k} = {d[k]:.4g}" for k in keys if k in d)


def sim_to_real_tables(frames: list[SensorFrames], result: DiagnoseResult, *, seed: int = 0) -> dict:
    """:func:`sim_to_real` for every sensor of a diagnosis."""
    return {f.sensor: sim_to_real(f, result.sensors[f.sensor], seed=seed) for f in frames}
