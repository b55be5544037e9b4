"""The diagnosis as people read it: ``report.md`` with tables, one PNG of plots per sensor,
and ``diagnosis.json`` (every number). Written into a staged folder (nothing half-written)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench.diagnose import models as M  # noqa: E402
from bench.diagnose.core import DiagnoseResult, SensorDiagnosis  # noqa: E402
from depthbench.fsutil import staged_directory  # noqa: E402

INTEL_TYPICAL_SUBPIXEL = 0.08


def _mm(v) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{1000 * v:.2f}"


def _f(v, fmt="{:.3f}") -> str:
    return "-" if v is None or not np.isfinite(v) else fmt.format(v)


def figure(d: SensorDiagnosis) -> plt.Figure:
    """Six panels: sigma/bias vs depth with the models, fill vs depth/brightness/texture,
    autocorrelation, bias vs image position, depth steps."""
    fig, ax = plt.subplots(2, 3, figsize=(15, 8.5))
    z = d.sigma.centre
    a = ax[0, 0]
    a.errorbar(z, 1000 * d.sigma.sigma, 1000 * d.sigma.sigma_se, fmt="o", label="measured (robust)")
    if d.temporal is not None:
        a.plot(d.temporal.centre, 1000 * d.temporal.sigma, "s", mfc="none", label="temporal (same view)")
    zz = np.linspace(max(np.nanmin(z) * 0.8, 0.05), np.nanmax(z) * 1.1, 100)
    for c, f in zip(M.SIGMA_MODELS, d.sigma_models.fits):
        if f.params and all(np.isfinite(list(f.params.values()))):
            p = np.array([f.params[k] for k in c.params])
            a.plot(zz, 1000 * c.f(zz, p), "-" if f.model == d.sigma_models.chosen else ":",
                   label=f"{f.model}{' (chosen)' if f.model == d.sigma_models.chosen else ''}")
    a.set(xlabel="depth (m)", ylabel="random error sigma (mm)", title="random error vs depth")
    a.legend(fontsize=7)
    a = ax[0, 1]
    for t, lab in ((d.fill_depth, "depth (m)"),):
        a.plot(t[0], t[1], "o-", label="vs depth")
    a.set(xlabel="depth (m)", ylabel="fill rate", ylim=(0, 1.05), title="fill rate")
    if d.fill_luminance is not None:
        b = a.twiny()
        b.plot(d.fill_luminance[0], d.fill_luminance[1], "s-", color="C1", label="vs brightness")
        b.set_xlabel("brightness (0-1), orange")
    a = ax[0, 2]
    if d.bias is not None:
        a.plot(z, 1000 * d.bias.mean, "o", label="mean residual")
        a.set(title=f"bias vs depth (model: {d.bias_models.chosen})")
    elif d.board and "frames" in d.board:
        rows = d.board["frames"]
        a.plot([r["z_centre_m"] for r in rows], [1000 * r["square_m"] for r in rows], "o")
        a.set(title="depth-implied board square (mm) per frame", ylabel="square (mm)")
    a.set(xlabel="depth (m)")
    a = ax[1, 0]
    from bench.diagnose.core import LAGS

    a.plot(LAGS, d.rho, "o", label="measured")
    s = d.derived.get("correlation_px_fit")
    if s:
        ll = np.linspace(0, max(LAGS), 100)
        a.plot(ll, np.exp(-ll ** 2 / (4 * s ** 2)), "-", label=f"gaussian s = {s:.2f} px")
    a.axhline(0, color="k", lw=0.5)
    a.set(xlabel="lag (px)", ylabel="correlation", title=f"spatial correlation (chosen: {d.correlation_models.chosen})")
    a.legend(fontsize=7)
    a = ax[1, 1]
    im = a.imshow(1000 * d.position_bias, cmap="coolwarm")
    fig.colorbar(im, ax=a, label="mean residual (mm)")
    a.set(title="residual vs image position", xticks=[], yticks=[])
    a = ax[1, 2]
    a.plot(d.steps[0], 1000 * d.steps[1], "o", label="median gap between distinct depths")
    if d.fill_texture is not None:  # its own axes: local contrast on top, fill on the right
        b = a.twinx().twiny()
        b.plot(d.fill_texture[0], d.fill_texture[1], "s-", color="C2")
        b.set_xlabel("local contrast (7x7 std of brightness), green: fill")
        b.set_ylim(0, 1.05)
    a.set(xlabel="depth (m)", ylabel="depth step (mm)", title="quantisation")
    fig.suptitle(f"{d.sensor}: {d.model} ({d.technology}), reference: {d.reference_kind}, {d.frames} frames")
    fig.tight_layout()
    return fig


def markdown(result: DiagnoseResult, *, sim_to_real: dict | None = None) -> str:
    """The report: per sensor the measured statistics, the model comparison, derived parameters."""
    lines = [f"# Sensor diagnosis: {result.source}", ""]
    for name, d in result.sensors.items():
        lines += _sensor_section(name, d)
    if sim_to_real:
        lines += sim_to_real_section(sim_to_real)
    return "\n".join(lines) + "\n"


def _sensor_section(name: str, d: SensorDiagnosis) -> list[str]:
    L = [f"## {name}: {d.model}", "", f"![{name}]({name}.png)", "",
         f"Technology {d.technology}; reference: {d.reference_kind}; {d.frames} frames of {d.shape[1]}x{d.shape[0]}; "
         f"fill rate on the reference {_f(d.fill_rate)}; far outliers {_f(100 * d.outlier_fraction, '{:.2f}')} %.", "",
         "| depth (m) | pixels | sigma (mm) | +- | bias (mm) | fill | temporal sigma (mm) | depth step (mm) |",
         "|---|---|---|---|---|---|---|---|"]
    for i, z in enumerate(d.sigma.centre):
        if d.sigma.count[i] == 0 and not np.isfinite(d.fill_depth[1][i]):
            continue
        temporal = d.temporal.sigma[i] if d.temporal is not None else None
        bias = d.bias.mean[i] if d.bias is not None else None
        L.append(f"| {z:.3f} | {d.sigma.count[i]} | {_mm(d.sigma.sigma[i])} | {_mm(d.sigma.sigma_se[i])} | {_mm(bias)} | "
                 f"{_f(d.fill_depth[1][i], '{:.2f}')} | {_mm(temporal)} | {_mm(d.steps[1][i])} |")
    L += ["", "Models (held-out chi2 per bin: fitted on one half of the frames, scored on the other; AICc on all):", "",
          "| quantity | model | parameters | AICc | held-out chi2 | chosen |", "|---|---|---|---|---|---|"]
    for sel in (d.sigma_models, d.bias_models, d.correlation_models):
        if sel is None:
            continue
        for f in sel.fits:
            ps = ", ".join(f"{k} = {v:.4g} +- {f.errors.get(k, float('nan')):.2g}" for k, v in f.params.items())
            L.append(f"| {sel.quantity} | {f.model} | {ps or '-'} | {_f(f.aicc, '{:.1f}')} | "
                     f"{_f(f.heldout_chi2, '{:.2f}')} | {'**yes**' if f.model == sel.chosen else ''} |")
    der = d.derived
    L.append("")
    if "subpixel_px" in der:
        L.append(f"Stereo subpixel value (Intel's RMS = z^2 subpixel / (f B), f B = {der['fB_px_m']:.2f} px m): "
                 f"**{der['subpixel_px']:.3f} +- {der['subpixel_px_error']:.3f} px** with the pure z^2 model; "
                 f"{der['floor_quadratic_subpixel_px']:.3f} px above a floor of {_mm(der['noise_floor_m'])} mm "
                 f"(floor_quadratic); Intel's typical value: {INTEL_TYPICAL_SUBPIXEL}.")
    if "quantisation_step_px" in der:
        L.append(f"Disparity step implied by the depth steps: {_f(der['quantisation_step_px'], '{:.3f}')} px.")
    if np.isfinite(d.edges.flying_fraction):
        e = d.edges
        L.append(f"Depth edges ({e.pixels} pixels within 2 px of a jump > 10 cm): flying {100 * e.flying_fraction:.1f} %, "
                 f"fattened background {100 * e.fattened_fraction:.1f} % ({e.fattening_px:.2f} px per edge pixel), "
                 f"missing {100 * e.missing_fraction:.1f} %.")
    if d.board:
        L += _board_lines(d.board)
    L += [f"- {n}" for n in d.notes] + [""]
    return L


def _board_lines(board: dict) -> list[str]:
    L = ["", "ChArUco board (plane from the colour image, in square units, against the depth's plane):", "",
         "| frame | pose | depth plane (m) | board plane (squares) | implied square (mm) | angle (deg) | plane RMS (mm) |",
         "|---|---|---|---|---|---|---|"]
    for r in board["frames"]:
        L.append(f"| {r['frame']} | {r['pose']} | {r['depth_plane_m']:.4f} | {r['board_plane_units']:.3f} | "
                 f"{1000 * r['square_m']:.2f} | {r['angle_deg']:.2f} | {1000 * r['plane_rms_m']:.2f} |")
    lens = board.get("lens")
    if lens:
        L += ["", f"Colour lens check: a radial k1 = {lens['k1']:.3f} (the capture declares no distortion) lowers the "
              f"corners' reprojection RMS from {lens['rms_px_without']:.2f} to {lens['rms_px_with_k1']:.2f} px; it changes "
              f"the near/far depth-implied board size by {100 * lens['near_far_size_change_from_k1']:+.1f} %."]
    m = board.get("models")
    if m:
        L += ["", "| depth-error model across poses | parameters | RMS (mm) | leave-one-frame-out (mm) | "
              "leave-one-pose-out (mm) | AICc |", "|---|---|---|---|---|---|"]
        for k, v in m.items():
            if k == "chosen":
                continue
            ps = ", ".join(f"{a} = {b:.4g}" for a, b in v["params"].items())
            L.append(f"| {k}{' (chosen)' if k == m['chosen'] else ''} | {ps} | {v['rms_mm']:.1f} | "
                     f"{v['leave_one_frame_out_rms_mm']:.1f} | {v['leave_one_pose_out_rms_mm']:.1f} | {v['aicc']:.1f} |")
    return L


def sim_to_real_section(s2r: dict) -> list[str]:
    """Table: per sensor and statistic, |sim - real| for each simulator stage (cumulative effects)."""
    L = ["## Sim-to-real distance", "",
         "The same diagnosis on a simulated twin of each capture (the measured reference surfaces, "
         "rendered through the simulator's noise model at each stage; effects added cumulatively).", ""]
    for sensor, table in s2r.items():
        stages = table["stages"]
        L += [f"### {sensor}", "", "| statistic | real | " + " | ".join(stages) + " |",
              "|---|---|" + "---|" * len(stages)]
        for stat, row in table["statistics"].items():
            L.append(f"| {stat} | {row['real']} | " + " | ".join(row["distance"][s] for s in stages) + " |")
        L += ["", *[f"- {n}" for n in table.get("notes", [])], ""]
    return L


def write_report(result: DiagnoseResult, out: str | os.PathLike, *, force: bool = False,
                 sim_to_real: dict | None = None) -> Path:
    """Write ``report.md``, ``<sensor>.png`` and ``diagnosis.json`` into folder ``out``."""
    with staged_directory(out, force=force, what="diagnosis report") as stage:
        stage = Path(stage)
        for name, d in result.sensors.items():
            fig = figure(d)
            fig.savefig(stage / f"{name}.png", dpi=80)
            plt.close(fig)
        (stage / "report.md").write_text(markdown(result, sim_to_real=sim_to_real))
        payload = result.to_dict()
        if sim_to_real:
            payload["sim_to_real"] = sim_to_real
        (stage / "diagnosis.json").write_text(json.dumps(payload, indent=1, default=_json_default))
    return Path(out)


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(type(o).__name__)
