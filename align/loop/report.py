"""The loop's part of the alignment report: figures, tables and the end-to-end error (I/O layer).

:func:`loop_section` writes ``figures/loop_*.png`` and returns Markdown lines:

* the effects table (declared / found, parameters with 95 % intervals, held-out comparison,
  look-alikes) and the search's stages;
* per found effect, the residual plot that pointed to it, before and after;
* what stays unexplained (a signature still structured after the final model), with its plot;
* the held-out alignment residual before/after, always; and where the session has truth (read
  here, by the report, after the fit), the warped HQ reference against the truth before/after
  the loop (built as the aligned dataset's, :mod:`align.pair_reference`), and the raw LQ depth
  against the truth before/after a depth correction.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from align.association import nearest_mapping  # noqa: E402
from align.pair_reference import ReferenceOptions  # noqa: E402
from align.pipeline import pair_references  # noqa: E402


def _plot_signature(ax, sig, title: str, color: str = "C0") -> None:
    if sig is None or sig.centers.size == 0:
        ax.text(0.5, 0.5, "no data", ha="center", transform=ax.transAxes)
        return
    if sig.sample_x.size:
        ax.plot(sig.sample_x, sig.sample_y, ",", color="0.6", alpha=0.5)
    ax.errorbar(sig.centers, sig.means, yerr=np.where(np.isfinite(sig.sems), sig.sems, 0), fmt="o-", color=color,
                ms=4, capsize=2)
    ax.axhline(0, color="k", lw=0.6)
    lo, hi = np.nanmin(sig.means - 3 * np.nan_to_num(sig.sems)), np.nanmax(sig.means + 3 * np.nan_to_num(sig.sems))
    pad = 0.5 * max(hi - lo, 1e-6)
    ax.set_ylim(min(lo - pad, -pad), max(hi + pad, pad))
    ax.set_xlabel(sig.covariate, fontsize=8)
    ax.set_ylabel(sig.response, fontsize=8)
    stat = "mean" if sig.level else "slope"
    ax.set_title(f"{title}: {sig.name}, {stat} z = {sig.z:.1f}", fontsize=9)


def _signature_figure(path: Path, before, after, title: str) -> None:
    fig, axes = plt.subplots(1, 2 if before is not None else 1, figsize=(10 if before is not None else 5.2, 3.2),
                             squeeze=False)
    if before is not None:
        _plot_signature(axes[0, 0], before, "before", "C3")
    _plot_signature(axes[0, -1], after, "after", "C0")
    fig.suptitle(title, fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=85, bbox_inches="tight")
    plt.close(fig)


def _fmt_params(d: dict) -> str:
    parts = []
    for k, v in d["params"].items():
        iv = d.get("interval95", {}).get(k)
        me = d.get("model_error", {}).get(k)
        parts.append(f"{k} = {v:.4g}" + (f" [{iv[0]:.4g}, {iv[1]:.4g}]" if iv else "")
                     + (f" (model error {me:.2g} included)" if me else ""))
    return ", ".join(parts)


def _sig(lst, name):
    return next((s for s in lst if s.name == name), None)


def end_to_end(setup, pf, loop, truth, *, pairs: int = 12, reference: ReferenceOptions | None = None,
               background=None) -> dict | None:
    """Warped HQ depth against the LQ truth (MAE, RMSE, mm) with the base geometry and with the loop's, and
    raw LQ depth against truth before/after the loop's depth correction, over ``pairs`` pairs.

    The references are built as ``align`` builds the aligned dataset's (:mod:`align.pair_reference`:
    the warp, carried to the LQ instant, the edge rule; ``reference``: the options the dataset was
    written with, ``None``: ``align``'s defaults; ``background``: the ROI's background model ``(H, W)`` float32 metres the
    dataset's rule used, for the rules that mask only what the ROI scores), so "after" is the error of the references written.
    Per geometry: ``reference_mae_mm``, ``reference_rmse_mm``, ``lq_mae_mm``, ``pairs`` and ``frames``
    (``(hq_frame, lq_frame)`` of each pair used) with ``frame_mae_mm``, the reference's MAE on each."""
    if truth is None:
        return None
    b = loop.base
    geoms = {"before": (b["T_lq_hq"], b["K_lq"], lambda t: b["shift_us"] + b["drift_ppm"] * 1e-6 * (t - b["t0_us"])),
             "after": (loop.T_lq_hq, loop.K_lq, lambda t: loop.shift_us + loop.drift_ppm * 1e-6 * (t - b["t0_us"]))}
    out = {}
    sess = setup.session
    for key, (T, K, shift_at) in geoms.items():
        shift = shift_at(setup.t_hq.astype(np.float64))
        lq_of = nearest_mapping(setup.t_hq, setup.t_lq, shift)
        dt = setup.t_lq[lq_of] - (setup.t_hq + shift)  # the LQ instant after its HQ frame's, on the HQ clock
        ok = np.flatnonzero(np.abs(dt) < setup.lq_period_us / 2)
        ok = ok[~np.isin(lq_of[ok], loop.lq_duplicates)] if key == "after" else ok
        pick = ok[np.unique(np.linspace(0, ok.size - 1, min(pairs, ok.size)).round().astype(int))]
        refs = pair_references(setup, T_lq_hq=T, K_lq=K, options=reference, background=background)
        errs, raw = [], []
        for i in pick:
            fl = int(setup.f_lq[lq_of[i]])
            tr = truth.depth(fl)
            ref = refs(int(i), float(dt[i])).depth
            lq = sess.read_depth(setup.lq, fl, stream=setup.lq_depth)
            if key == "after":
                lq = loop.correct_lq_depth(lq)
            m = np.isfinite(ref) & np.isfinite(tr)
            errs.append(np.abs(ref[m] - tr[m]))
            m = np.isfinite(lq) & np.isfinite(tr)
            raw.append(np.abs(lq[m] - tr[m]))
        e, r = np.concatenate(errs) if errs else np.zeros(0), np.concatenate(raw) if raw else np.zeros(0)
        out[key] = {"reference_mae_mm": 1e3 * float(np.mean(e)) if e.size else float("nan"),
                    "reference_rmse_mm": 1e3 * float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan"),
                    "lq_mae_mm": 1e3 * float(np.mean(r)) if r.size else float("nan"), "pairs": int(pick.size),
                    "frames": [(int(setup.f_hq[i]), int(setup.f_lq[lq_of[i]])) for i in pick],
                    "frame_mae_mm": [1e3 * float(np.mean(x)) if x.size else float("nan") for x in errs]}
    return out


def _refined_fit_lines(loop) -> list[str]:
    if not loop.refined_fit.startswith(("refitted", "fell back")):
        return []
    return [f"Final feature model (pose, shift, found effects' parameters) on the photometrically refined "
            f"keypoints, chosen on the detected ones: {loop.refined_fit}.", ""]


def loop_section(root: Path, setup, pf, truth=None, *, reference: ReferenceOptions | None = None,
                 background=None) -> list[str]:
    """Markdown lines (and figures under ``root/figures``) for the loop of ``pf.loop``; ``reference``: how the
    dataset's references were built, ``background`` the ROI's (:func:`end_to_end`)."""
    loop, figs = pf.loop, Path(root) / "figures"
    fl, dl = loop.features, loop.depth
    before = list(fl.before) + (list(dl.before) if dl else [])
    after = list(fl.after) + (list(dl.after) if dl else [])
    effects = loop.effects_json()
    lines = ["## Effects the alignment model needed (the loop)", ""]
    lines += [f"The search adds an effect of the library only when it lowers the robust error on held-out probes "
              f"(feature phase) or frame pairs (depth phase) -- contiguous time blocks with a gap -- by more than "
              f"z = {fl.threshold:.2f} (parametric bootstrap, {fl.null_z.size} replicates, false-alarm rate 1 % per "
              f"stage, never below 3) and the BIC falls. See `align/loop/`.", ""] + _refined_fit_lines(loop)
    if effects:
        lines += ["| effect | source | parameters (95 % interval) | z | held-out loss before -> after | look-alikes |",
                  "|---|---|---|--:|---|---|"]
        for d in effects:
            ho = (f"{d['heldout_loss_before']:.4g} -> {d['heldout_loss_after']:.4g}" if "heldout_loss_before" in d
                  else "-")
            lines.append(f"| `{d['name']}` | {d['source']} | {_fmt_params(d)} | "
                         f"{d['z']:.1f} | {ho} | {', '.join(d.get('look_alikes', [])) or '-'} |"
                         if "z" in d else f"| `{d['name']}` | {d['source']} | {_fmt_params(d)} | - | {ho} | - |")
        lines.append("")
    else:
        lines += ["No effect was added: the base model (constant time shift, one rigid transform, pinhole cameras) "
                  "explains the held-out data as well as any effect of the library.", ""]
    stages = [(s.stage, s.candidates, s.accepted or (f"none ({s.undone})" if s.undone else None), "features")
              for s in fl.stages] + ([(s.stage, s.candidates, s.accepted, "depth") for s in dl.stages] if dl else [])
    if stages:
        lines += ["| phase | stage | candidate: z / held-out improvement / delta BIC | accepted |", "|---|--:|---|---|"]
        for st, cands, acc, phase in stages:
            c = "; ".join(f"{n}: {v.z:.1f} / {100 * v.improvement:.2f} % / {v.delta_bic:.0f}" for n, v in cands.items())
            lines.append(f"| {phase} | {st} | {c} | {acc or 'none'} |")
        lines.append("")
    ho_f = fl.heldout_before, fl.heldout_after
    lines += ["| held-out alignment residual | before | after |", "|---|--:|--:|",
              f"| feature reprojection, median abs (px) | {ho_f[0].get('median_abs', float('nan')):.3f} | "
              f"{ho_f[1].get('median_abs', float('nan')):.3f} |"]
    if dl is not None:
        lines.append(f"| LQ - warped HQ depth, median abs (%) | {100 * dl.heldout_before['median_abs']:.3f} | "
                     f"{100 * dl.heldout_after['median_abs']:.3f} |")
    lines.append("")
    e2e = end_to_end(setup, pf, loop, truth, reference=reference, background=background)
    if e2e:
        ro = reference or ReferenceOptions()
        how = f"edge rule `{ro.reference_edges}`" + (", carried to the LQ instant" if ro.motion else "")
        lines += [f"End to end, against the simulator's truth (read by this report only, after the fit; the references "
                  f"built as the aligned dataset's: {how}):", "",
                  "| | before the loop | after |", "|---|--:|--:|",
                  f"| warped HQ reference vs truth, MAE (mm) | {e2e['before']['reference_mae_mm']:.2f} | "
                  f"{e2e['after']['reference_mae_mm']:.2f} |",
                  f"| warped HQ reference vs truth, RMSE (mm) | {e2e['before']['reference_rmse_mm']:.2f} | "
                  f"{e2e['after']['reference_rmse_mm']:.2f} |",
                  f"| LQ depth (as written) vs truth, MAE (mm) | {e2e['before']['lq_mae_mm']:.2f} | "
                  f"{e2e['after']['lq_mae_mm']:.2f} |", ""]
    for d in effects:
        if d["source"] != "found":
            continue
        name = d["signature"]
        path = figs / f"loop_{d['name']}.png"
        _signature_figure(path, _sig(before, name), _sig(after, name), f"{d['name']}: the residual that pointed to it")
        lines += [f"### `{d['name']}`", "", d["what"] + ".", "", f"![{d['name']}](figures/{path.name})", ""]
    unexplained = loop.unexplained()
    lines += ["### Unexplained", ""]
    if unexplained:
        lines += ["**Something is here that the library cannot model**: these residual signatures still depend on "
                  "their covariate after the final model (|z| > 4).", ""]
        for s in unexplained:
            path = figs / f"loop_unexplained_{s.name}.png"
            _signature_figure(path, None, s, f"unexplained: {s.name}")
            stat = f"mean {s.level_mean:.3g} +- {s.level_se:.2g}" if s.level else f"slope {s.slope:.3g} +- {s.slope_se:.2g}"
            lines += [f"- `{s.name}` ({s.response} against {s.covariate}): {stat}, z = {s.z:.1f}", "",
                      f"![{s.name}](figures/{path.name})", ""]
    else:
        lines += ["No residual signature is left with structure (|z| <= 4 for every one).", ""]
    sec = loop.seconds
    lines += [f"Loop time: {sec.get('total', 0):.1f} s (features {sec.get('features', 0):.1f} s, of which bootstrap "
              f"{sec.get('features.bootstrap', 0):.1f} s; depth {sec.get('depth', 0):.1f} s).", ""]
    return lines
