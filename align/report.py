"""The alignment report a person reads: ``report.md`` + ``report.html`` + ``figures/*.png``.

Figures (matplotlib, Agg): the eq. 31 loss against the time shift (coarse scan and a zoom on the
minimum), residual histograms (feature reprojection, per-pair depth, pair time difference), the
per-pair depth residual and local shift estimates over time, and one frame: LQ colour, LQ depth,
the warped HQ depth, their difference and the region of interest.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from align.pair_reference import ReferenceOptions  # noqa: E402
from align.time_shift import ShiftLoss  # noqa: E402
from depthbench.markdown_html import html_page, markdown_to_html  # noqa: E402

_CSS = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:2px 8px}img{max-width:100%}blockquote{background:#fee;"
        "padding:.5em;border-left:4px solid #c00}figure{margin:1em 0}figcaption{font-size:.85em;color:#555}")


def _html(md: str, title: str, *, links: dict[str, str] | None = None) -> str:
    """The report page: the Markdown rendered by markdown-it-py (figures link the PNGs beside it;
    ``links``: link targets to replace, e.g. a view's ``report.md`` by its ``report.html``)."""
    return html_page(markdown_to_html(md, links=links), title=title, css=_CSS)


def _save(fig, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)


def _loss_figure(path: Path, pf) -> None:
    sh = pf.shift
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    ax = axes[0]
    ax.plot(sh.grid_us / 1000, sh.grid_loss, ".-", lw=1, ms=3, label="coarse scan")
    ax.axvline(sh.time_shift_us / 1000, color="C3", lw=1, label=f"Delta = {sh.time_shift_us / 1000:.3f} ms")
    ax.set_xlabel("time shift Delta (ms)")
    ax.set_ylabel("robust eq. 31 loss (px$^2$)")
    ax.set_title("loss against the time shift")
    ax.legend(fontsize=8)
    ax = axes[1]
    try:
        loss = ShiftLoss(pf.probes, sh.T_init, pf.setup.K_lq_color, t0_us=sh.t0_us)
        half = 2.0 * float(np.diff(sh.grid_us[:2])[0]) if sh.grid_us.size > 1 else 4000.0
        xs = np.linspace(sh.time_shift_us - half, sh.time_shift_us + half, 161)
        ys = [loss(x, sh.drift_ppm * 1e-6) for x in xs]
        ax.plot(xs / 1000, ys, lw=1)
        ax.axvline(sh.time_shift_us / 1000, color="C3", lw=1)
        if np.isfinite(sh.std_us):
            ax.axvspan((sh.time_shift_us - sh.std_us) / 1000, (sh.time_shift_us + sh.std_us) / 1000, color="C3",
                       alpha=0.15, label=f"+-1 sigma = {sh.std_us:.0f} us")
            ax.legend(fontsize=8)
    except Exception as exc:  # the report must not fail the alignment
        ax.text(0.5, 0.5, f"zoom unavailable: {exc}", ha="center", transform=ax.transAxes, fontsize=8)
    ax.set_xlabel("time shift Delta (ms)")
    ax.set_title("zoom on the minimum (interpolated tracks)")
    _save(fig, path)


def _residual_figure(path: Path, pf, table) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.3))
    r = pf.fit.residuals_px
    r = r[np.isfinite(r)]
    axes[0].hist(np.clip(r, 0, 5), bins=60, color="C0")
    axes[0].set_xlabel("feature reprojection residual (px, clipped at 5)")
    axes[0].set_title(f"eq. 31 residuals: {pf.fit.n_inliers}/{pf.fit.n_pairs} inliers, RMS {pf.fit.rms_px:.2f} px",
                      fontsize=9)
    dr = table.residual[np.isfinite(table.residual)]
    kept = table.kept & np.isfinite(table.residual)
    axes[1].hist(100 * table.residual[kept], bins=40, color="C2", label="kept")
    drop = ~table.kept & np.isfinite(table.residual)
    if drop.any():
        axes[1].hist(100 * table.residual[drop], bins=40, color="C3", alpha=0.7, label="dropped")
    axes[1].set_xlabel("per-pair depth residual, median |D_LQ - D_ref| / D_ref (%)")
    axes[1].set_title(f"{dr.size} pairs", fontsize=9)
    axes[1].legend(fontsize=8)
    dt = np.abs(table.dt_us[table.lq_index >= 0]) / 1000
    axes[2].hist(dt, bins=40, color="C1")
    axes[2].set_xlabel("|t_LQ - (t_HQ + Delta)| (ms)")
    axes[2].set_title("pair time differences", fontsize=9)
    _save(fig, path)


def _timeline_figure(path: Path, pf, table) -> None:
    s = pf.setup
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.2))
    t = (s.t_hq - s.t_hq[0]) / 1e6
    ok = np.isfinite(table.residual)
    axes[0].plot(t[ok & table.kept], 100 * table.residual[ok & table.kept], ".", ms=3, label="kept")
    bad = ok & ~table.kept
    if bad.any():
        axes[0].plot(t[bad], 100 * table.residual[bad], "x", color="C3", ms=5, label="dropped")
    axes[0].set_xlabel("HQ time (s)")
    axes[0].set_ylabel("depth residual (%)")
    axes[0].legend(fontsize=8)
    axes[0].set_title("per-pair depth residual over time", fontsize=9)
    seg = pf.shift.segments
    if seg:
        ts = (np.array([x[0] for x in seg]) - s.t_hq[0]) / 1e6
        axes[1].plot(ts, [x[1] / 1000 for x in seg], "o-", label="local estimate")
    axes[1].plot(t, pf.shift.shift_at(s.t_hq) / 1000, color="C3", lw=1, label=f"model ({pf.shift.model})")
    axes[1].set_xlabel("HQ time (s)")
    axes[1].set_ylabel("Delta (ms)")
    axes[1].set_title("time shift over the session (a slope means drift)", fontsize=9)
    axes[1].legend(fontsize=8)
    _save(fig, path)


def _example_figure(path: Path, example: dict) -> None:
    lq, ref = example["lq"], example["ref"]
    both = np.concatenate([lq[np.isfinite(lq)], ref[np.isfinite(ref)]])
    vmin, vmax = (np.percentile(both, [2, 98]) if both.size else (0, 1))
    n = 5 if example.get("color") is not None else 4
    fig, axes = plt.subplots(1, n, figsize=(4 * n, 3.4))
    k = 0
    if example.get("color") is not None:
        axes[k].imshow(example["color"])
        axes[k].set_title(f"LQ colour (frame {example['lq_frame']})", fontsize=9)
        k += 1
    for img, title in ((lq, "LQ depth (m)"), (ref, f"warped HQ depth (HQ frame {example['hq_frame']})")):
        im = axes[k].imshow(np.where(np.isfinite(img), img, np.nan), vmin=vmin, vmax=vmax, cmap="turbo")
        axes[k].set_title(title, fontsize=9)
        fig.colorbar(im, ax=axes[k], fraction=0.046)
        k += 1
    diff = (lq - ref) * 1000
    lim = np.nanpercentile(np.abs(diff), 95) if np.isfinite(diff).any() else 1
    im = axes[k].imshow(diff, cmap="coolwarm", vmin=-lim, vmax=lim)
    axes[k].set_title("LQ - warped HQ (mm); white: no reference", fontsize=9)
    fig.colorbar(im, ax=axes[k], fraction=0.046)
    k += 1
    roi = example.get("roi")
    axes[k].imshow(np.isfinite(ref), cmap="gray", vmin=0, vmax=1)
    if roi is not None:
        axes[k].imshow(np.ma.masked_where(~roi, roi), cmap="autumn", alpha=0.6)
    axes[k].set_title("valid reference (white), ROI M_r (orange)", fontsize=9)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    _save(fig, path)


def _fmt_T(T) -> str:
    rows = ["| R col 1 | R col 2 | R col 3 | t (m) |", "|--:|--:|--:|--:|"]
    for r in T.matrix:
        rows.append("| " + " | ".join(f"{x:+.6f}" for x in r) + " |")
    return "\n".join(rows)


def _motion_section(m: dict | None) -> list[str]:
    """The reference at the LQ instant (``aligned.json``'s ``motion``): how many pairs, how far apart, what was masked."""
    if not m:
        return []
    lines = ["## Motion between the paired frames", ""]
    if not m["enabled"]:
        return lines + ["Off: each reference is the plain warp of its pair's HQ frame, whatever the time apart.", ""]
    dt = np.array([abs(p["dt_ms"]) for p in m["per_pair"]], float)
    q = np.percentile(dt, [0, 50, 90, 100]) if dt.size else [float("nan")] * 4
    why = ", ".join(f"{n} x {r}" for r, n in m["not_compensated"].items()) or "none"
    roi = m.get("roi_masked_share")
    lines += ["| quantity | value |", "|---|---|",
              f"| pairs carried to the LQ instant | {m['compensated']} of {m['pairs']} (kept as plain warp: {why}) |",
              f"| time apart, abs(t_LQ - (t_HQ + Delta)) | min {q[0]:.2f}, median {q[1]:.2f}, p90 {q[2]:.2f}, "
              f"max {q[3]:.2f} ms |",
              f"| masked (undecided, NaN) | {m['masked_pixels']} pixels, {100 * m['masked_share']:.3f} % of reference pixels"
              + (f", {100 * roi:.3f} % inside the region of interest |" if roi is not None else " |"),
              "", "Each reference is the two HQ frames around the LQ frame's instant, warped and combined: depth "
              "linear in time where both see one surface, the crossing time of the moving edge where they see two "
              f"(`align/motion.py`); pairs under {m['min_dt_ms']:g} ms apart keep the plain warp. Per pair: "
              "`aligned.json` -> `motion.per_pair`.", ""]
    return lines


def write_report(root: Path, setup, pf, table, example: dict, meta: dict, truth=None, background=None) -> Path:
    """Write ``report.md``, ``report.html`` and ``figures/`` into ``root``; returns the Markdown path.
    ``truth`` (simulated sessions): the end-to-end error of the loop's section against it, its references built
    with ``background`` (the ROI's, as the dataset's)."""
    root = Path(root)
    figs = root / "figures"
    _loss_figure(figs / "loss_vs_shift.png", pf)
    _residual_figure(figs / "residuals.png", pf, table)
    _timeline_figure(figs / "timeline.png", pf, table)
    if example:
        _example_figure(figs / "example.png", example)
    sh, fit = pf.shift, pf.fit
    counts = table.counts()
    res = meta["residuals"]
    lines = [f"# Alignment report: {setup.session.name} ({setup.hq} -> {setup.lq})", ""]
    if not sh.observable:
        lines += [f"> **WARNING: the time shift is unobservable.** {sh.reason}. "
                  f"`time_shift_us` = {meta['time_shift_us']} is a placeholder (declared value or 0), not a measurement.", ""]
    angle = pf.T_lq_hq.rotation_angle_deg()
    lines += [
        "| quantity | value |", "|---|---|",
        f"| time shift Delta (HQ stamp t is LQ stamp t + Delta) | **{sh.time_shift_us / 1000:.3f} ms** "
        f"(+- {sh.std_us / 1000:.3f} ms, 1 sigma) |" if np.isfinite(sh.std_us) else
        f"| time shift Delta | {sh.time_shift_us / 1000:.3f} ms (uncertainty unknown) |",
        f"| time model | {sh.model}, drift {sh.drift_ppm:.2f} ppm |",
        f"| evidence | {sh.n_probes} probe frames, {sh.n_features} tracked features, {sh.n_moving} moving |",
        f"| T_lq_hq | rotation {angle:.3f} deg, translation {1000 * np.linalg.norm(pf.T_lq_hq.t):.1f} mm "
        f"(+- {meta['T_lq_hq_std']['rotation_deg']:.4f} deg, +- {meta['T_lq_hq_std']['translation_mm']:.2f} mm) |",
        f"| feature residuals (eq. 31) | {fit.n_inliers} of {fit.n_pairs} inliers, RMS {fit.rms_px:.3f} px, "
        f"median {fit.median_px:.3f} px |",
        f"| depth residual per pair | median {100 * res['depth'].get('median', float('nan')):.2f} % |",
        f"| pairs | {res['pairs']['kept']} kept of {res['pairs']['candidates']} |",
        "",
        "Dropped pairs: " + (", ".join(f"{n} x {r}" for r, n in counts.items()) if counts else "none") + ".",
        "",
        "Timestamps: " + ", ".join(f"{k}: {v.get('method')}" + (f" (jitter RMS {v['jitter_rms_us']:.0f} us)"
                                                                  if "jitter_rms_us" in v else "")
                                   for k, v in setup.clocks.items()) + ".",
        "", "## T_lq_hq (HQ depth camera -> LQ depth camera, metres)", "", _fmt_T(pf.T_lq_hq), "",
        "## Loss against the time shift", "",
        "![Robust eq. 31 loss against the time shift: coarse scan, and a zoom on the minimum with +-1 sigma]"
        "(figures/loss_vs_shift.png)", "",
        "Each candidate Delta is scored by eq. 31 on the probe frames' features, with the LQ feature tracks "
        "interpolated at the HQ instant (see `align/time_shift.py`).", "",
        "## Residuals", "", "![Residual histograms: feature reprojection (eq. 31), per-pair depth, pair time difference]"
        "(figures/residuals.png)", "",
        "![Per-pair depth residual and local time-shift estimates over the session](figures/timeline.png)", "",
    ]
    if example:
        lines += ["## One frame", "", "![LQ colour and depth, the warped HQ depth, their difference and the region "
                  "of interest](figures/example.png)", ""]
    lines += _motion_section(meta.get("motion"))
    if getattr(pf, "loop", None) is not None:
        from align.loop.report import loop_section

        lines += loop_section(root, setup, pf, truth, reference=ReferenceOptions.from_meta(meta), background=background)
    md = "\n".join(lines)
    path = root / "report.md"
    path.write_text(md)
    (root / "report.html").write_text(_html(md, f"Alignment report: {setup.session.name}"))
    return path


def write_rig_report(root: Path, session, rig, fits: dict, outputs: dict) -> Path:
    """``report.md``/``report.html`` of a multi-view rig: the rig (with the refinement's sds, pairs and
    warnings when it ran), then one line and a link per view."""
    root = Path(root)
    ref = rig.refinement or {}
    lines = [f"# Rig calibration: {session.name}", "", f"Rig frame: the depth camera of `{rig.reference}`.", ""]
    if rig.warnings:
        lines += ["> **WARNING: the refined rig is not consistent.**", ">"] + [f"> - {w}" for w in rig.warnings] + [""]
    lines += ["| sensor | Delta vs source (ms) | +- (ms) | rotation (deg) | translation (mm) | sd (deg / mm) | "
              "feature RMS (px) | feature fit off the rig (sd) | pairs kept | report |",
              "|---|--:|--:|--:|--:|--:|--:|--:|--:|---|"]
    off = ref.get("feature_fit_sd_off", {})
    for v, pf in fits.items():
        T = rig.T_rig_sensor.get(v)
        rot = T.rotation_angle_deg() if T is not None else float("nan")
        tr = 1000 * np.linalg.norm(T.t) if T is not None else float("nan")
        sd = rig.std.get(v)
        sd_txt = f"{sd[1]:.3f} / {1000 * sd[0]:.1f}" if sd is not None and v != rig.reference else "-"
        how = " (depth)" if pf.shift.model == "depth" else "" if pf.shift.observable else " (placeholder)"
        lines.append(f"| {v} (from {pf.setup.hq}) | {pf.shift.time_shift_us / 1000:.3f}{how} | {pf.shift.std_us / 1000:.3f} | "
                     f"{rot:.3f} | {tr:.1f} | {sd_txt} | {pf.fit.rms_px:.3f} | {off.get(v, float('nan')):.1f} | "
                     f"{outputs[v].kept} | [{v}/report.md]({v}/report.md) |")
    if ref:
        lines += ["", f"Refinement: {ref['method']}; loop check chi2 {ref['chi2']:.1f} on {ref['dof']} degrees of "
                  f"freedom, covariances scaled by {ref['variance_factor']:.2f}. A feature fit more than 4.7 sd off the "
                  "refined rig (p = 0.001) is flagged: its reported covariance does not hold.", "",
                  "| pair | correspondences | fitness | RMS (mm) | used | loop residual (sd) |", "|---|--:|--:|--:|---|--:|"]
        for p in ref["pairs"]:
            loop = "-" if p["loop_sd"] is None else f"{p['loop_sd']:.2f}"
            lines.append(f"| {p['a']} - {p['b']} | {p['correspondences']} | {p['fitness']:.2f} | {p['rmse_mm']:.1f} | "
                         f"{'yes' if p['used'] else 'no'} | {loop} |")
        if ref.get("notes"):
            lines += ["", "Feature fits flagged (the refined rig replaces them):", ""] + [f"- {n}" for n in ref["notes"]]
    if rig.loop_errors:
        lines += ["", "Loop closure (a direct fit against the composition through the rig frame):", ""]
        for a, b, dt, dr in rig.loop_errors:
            lines.append(f"- {a} <- {b}: {1000 * dt:.2f} mm, {dr:.4f} deg")
    lines += ["", "Transforms `T_rig_sensor` (and their sds, the feature rig) are in `rig.json`."]
    md = "\n".join(lines) + "\n"
    path = root / "report.md"
    path.write_text(md)
    (root / "report.html").write_text(_html(md, f"Rig calibration: {session.name}",
                                            links={f"{v}/report.md": f"{v}/report.html" for v in fits}))
    return path
