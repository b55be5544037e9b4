"""Read what ``bench diagnose`` measures: sessions, aligned datasets and the real captures.

The I/O layer of :mod:`bench.diagnose`: every loader returns a list of
:class:`bench.diagnose.data.SensorFrames` (one per depth sensor). Recognised inputs:

* a session folder (``session.json``): every depth sensor; the simulator's ``truth/`` is the
  reference when present, else local planes;
* an aligned dataset (``aligned.json``): the LQ depth against the warped HQ reference (``fused``),
  or against the simulator's truth when the dataset carries it;
* the real captures of ``../shared/data/real`` (``SOURCES.md``) by their layout:
  ``alr_d435_charuco`` (D435, depth aligned to colour, ChArUco board: the board plane),
  ``vcl3d_d415`` (D415, local planes), ``azure_kinect_pyk4a`` or any Azure Kinect ``.mkv``
  (local planes), ``tum_kinect1_sample`` (Kinect v1, local planes), ``ddrnet_person``
  (structured light against its multi-frame fused reference).

Stereo geometry of real sensors (focal length at the matcher's resolution, baseline) is taken
from the capture's documentation and Intel's datasheet (D415 55 mm, D435 50 mm baselines);
Kinect v1 from the literature (75 mm baseline, disparity in 1/8 px).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np

from bench.diagnose.data import BoardView, SensorFrames
from bench.errors import BenchError
from capture.camera import Intrinsics

#: Baselines of real stereo sensors (m): Intel datasheet (D415 55 mm, D435 50 mm); Kinect v1 75 mm.
BASELINES_M = {"D415": 0.055, "D435": 0.050, "Kinect v1": 0.075}


def load(path: str | os.PathLike, *, max_frames: int = 60) -> list[SensorFrames]:
    """Recognise ``path`` and load it (``max_frames`` evenly spaced frames per sensor at most)."""
    p = Path(path)
    if not p.exists():
        raise BenchError(f"{p}: does not exist")
    if p.is_file() and p.suffix.lower() == ".mkv":
        return [load_azure(p, max_frames=max_frames)]
    if not p.is_dir():
        raise BenchError(f"{p}: not a session, aligned dataset or known real capture")
    if (p / "session.json").is_file():
        return load_session(p, max_frames=max_frames)
    if (p / "aligned.json").is_file():
        return [load_aligned(p, max_frames=max_frames)]
    for marker, loader in (("camera_docs.md", load_d435_charuco), ("device_repository.json", load_d415),
                           ("recording.mkv", lambda q: load_azure(q / "recording.mkv", max_frames=max_frames)),
                           ("TUM_depth.png", load_tum), ("group1", load_ddrnet)):
        if (p / marker).exists():
            return [loader(p)]
    raise BenchError(f"{p}: not a session, aligned dataset or known real capture (see 'bench diagnose --help')")


def _spaced(n: int, k: int) -> list[int]:
    return list(range(n)) if n <= k else sorted(set(np.linspace(0, n - 1, k).round().astype(int).tolist()))


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0


def _read_png16(path: Path, unit_m: float) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        raise BenchError(f"{path}: not a single-channel 16-bit PNG")
    z = img.astype(np.float32) * np.float32(unit_m)
    z[img == 0] = np.nan
    return z


def _read_rgb(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise BenchError(f"{path}: not a readable image")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


# ----------------------------------------------------------------------------- sessions
def load_session(root: Path, *, max_frames: int) -> list[SensorFrames]:
    """Every depth sensor of a session; the truth is the reference of simulated sessions."""
    from capture.session import open_session

    s = open_session(root)
    truth = None
    if (root / "truth" / "truth.json").is_file():
        from capture.truth import read_truth

        truth = read_truth(root)
    out = []
    for sid, info in s.sensors.items():
        if "depth" not in info.streams:
            continue
        numbers = s.frames(sid, "depth")["frame_number"].to_numpy()
        numbers = numbers[_spaced(len(numbers), max_frames)]
        K = s.intrinsics(sid, "depth")
        noise = s.manifest["sensors"][sid].get("noise") or {}
        co_reg = "color" in info.streams and info.streams["color"].intrinsics == K and (
            info.T_depth_color is None or info.T_depth_color.is_close(info.T_depth_color.identity()))
        depth, ref, lum = [], [], []
        for n in numbers:
            depth.append(s.read_depth(sid, int(n)))
            ref.append(truth.depth(sid, int(n)) if truth is not None else None)
            lum.append(_luminance(s.read_color(sid, int(n))) if co_reg else None)
        tech = "tof" if noise.get("model") == "tof" else "stereo" if noise.get("model") == "stereo" else \
            _technology(info.model)
        baseline = noise.get("baseline_m") or _baseline(info.model)
        out.append(SensorFrames(sid, info.model, tech, K, depth, ref, "truth" if truth is not None else "planes",
                                luminance=lum, stereo_focal_px=K.fx if baseline else None, baseline_m=baseline,
                                depth_unit_m=float(info.streams["depth"].depth_unit_m or 0.001), source=str(root),
                                notes=_profile_notes(noise)))
    if not out:
        raise BenchError(f"{root}: the session has no depth stream")
    return out


def _profile_notes(noise: dict) -> list[str]:
    """What the simulator says about a measured sensor profile it used (``noise.profile``)."""
    prof = noise.get("profile")
    if not isinstance(prof, dict):
        return []
    return [f"simulated with the sensor profile {prof.get('name')!r} (its pixel parameters x "
            f"{float(prof.get('pixel_factor', float('nan'))):.4g} from its native focal length "
            f"{float(prof.get('native_focal_px', float('nan'))):.6g} px)"]


def _technology(model: str) -> str:
    m = model.lower()
    return "tof" if ("azure" in m or "tof" in m or "kinect v2" in m) else "stereo" if "realsense" in m or "oak" in m \
        else "structured_light"


def _baseline(model: str) -> float | None:
    for key, b in BASELINES_M.items():
        if key.lower() in model.lower():
            return b
    return None


def load_aligned(root: Path, *, max_frames: int) -> SensorFrames:
    """The LQ sensor of an aligned dataset against its reference (the truth when it has one)."""
    from align.dataset import AlignedDataset

    ds = AlignedDataset(root)
    idx = _spaced(len(ds), max_frames)
    frames = [ds.frame(i) for i in idx]
    has_truth = all(f.truth is not None for f in frames)
    lum = [None if f.lq_color is None else _luminance(f.lq_color) for f in frames]
    model = ds.meta.get("lq_model", "LQ sensor")
    return SensorFrames("lq", model, _technology(model), ds.lq_intrinsics, [f.lq_depth for f in frames],
                        [f.truth if has_truth else f.reference for f in frames], "truth" if has_truth else "fused",
                        luminance=lum, depth_unit_m=ds.depth_unit_m, source=str(root))


# ----------------------------------------------------------------------------- real captures
def load_d435_charuco(root: Path) -> SensorFrames:
    """The alr D435 ChArUco captures: 3 poses x 3 frames, depth aligned to the 1920x1080 colour.

    The board (7 x 5 squares, DICT_4X4_250, markers 0.8 of a square, size undocumented) gives
    per pose a plane in square units from the colour image (PnP). The stereo focal length is the
    depth camera's at 1280x720 (639.04 px, ``camera_docs.md``), the baseline 50 mm.
    """
    from align.charuco import BoardSpec, board_pose, detect_board

    K = Intrinsics(1920, 1080, 1377.6449, 1375.7240, 936.4847, 537.4878)
    spec = BoardSpec(7, 5, 1.0, 0.8, "DICT_4X4_250")
    depth, lum, group, boards = [], [], [], []
    for g, first in enumerate((0, 6, 27)):
        rgb = _read_rgb(root / "color" / f"{first}.png")
        xy, ids = detect_board(rgb, spec)
        pose = board_pose(xy, ids, spec, K)
        hull = cv2.convexHull(xy.astype(np.float32)).astype(np.int32)
        mask = np.zeros(K.shape, np.uint8)
        cv2.fillConvexPoly(mask, hull, 1)
        mask = cv2.erode(mask, np.ones((15, 15), np.uint8)).astype(bool)
        n = pose.T_cam_board.R[:, 2]
        d = float(pose.T_cam_board.t @ n)
        n, d = (-n, -d) if d < 0 else (n, d)
        view = BoardView(n, d, mask, pose.n_corners, pose.rms_px, xy, spec.corner_points()[ids])
        for f in range(first, first + 3):
            depth.append(_read_png16(root / "depth" / f"{f}.png", 0.001))
            lum.append(_luminance(rgb))
            group.append(g)
            boards.append(view)
    return SensorFrames("d435", "Intel RealSense D435", "stereo", K, depth, [None] * len(depth), "board",
                        luminance=lum, group=group, board=boards, stereo_focal_px=639.0427, baseline_m=0.050,
                        source=str(root), notes=["depth aligned to colour by the RealSense SDK (1920x1080)"])


def load_d415(root: Path) -> SensorFrames:
    """The two VCL3D D415 frames (device M11, 640x360: the 1280x720 depth intrinsics halved)."""
    try:
        devices = json.loads((root / "device_repository.json").read_text())
        dev = next(d for d in devices if d.get("Device") == "M11")
        k = next(v for e in dev["Depth Intrinsics"] for key, v in e.items() if key == "1280x720")
    except (OSError, ValueError, StopIteration, KeyError, TypeError) as exc:
        raise BenchError(f"{root / 'device_repository.json'}: no 1280x720 depth intrinsics of M11 ({exc})") from None
    K = Intrinsics(640, 360, k[0] / 2, k[4] / 2, (k[2] + 0.5) / 2 - 0.5, (k[5] + 0.5) / 2 - 0.5)
    files = sorted(root.glob("0_M11_depth_*.png"))
    depth = [_read_png16(f, 0.001) for f in files]
    return SensorFrames("d415", "Intel RealSense D415", "stereo", K, depth, [None] * len(depth), "planes",
                        stereo_focal_px=K.fx, baseline_m=0.055, source=str(root),
                        notes=["f B is taken at the 640x360 of the files; had the camera matched at 1280x720 and "
                               "the frames been downscaled, f B and the subpixel value would be twice as large"])


def load_azure(path: Path, *, max_frames: int = 60) -> SensorFrames:
    """Depth frames of an Azure Kinect recording (factory calibration from the file)."""
    from capture.drivers.azure_kinect import open_mkv

    rec = open_mkv(path, streams=("depth",))
    K = rec.calibration.depth_intrinsics
    depth = []
    for fr in rec.frames():
        if fr.stream == "depth":
            z = fr.image.astype(np.float32) * np.float32(0.001)
            z[fr.image == 0] = np.nan
            depth.append(z)
    depth = [depth[i] for i in _spaced(len(depth), max_frames)]
    return SensorFrames("azure", "Azure Kinect DK", "tof", K, depth, [None] * len(depth), "planes", source=str(path))


def load_tum(root: Path) -> SensorFrames:
    """The TUM Kinect v1 sample (depth / 5000 = metres; TUM default intrinsics; disparity in 1/8 px,
    focal 580 px at 640x480 for the IR camera, 75 mm baseline)."""
    K = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
    depth = [_read_png16(root / "TUM_depth.png", 1 / 5000)]
    lum = [_luminance(_read_rgb(root / "TUM_color.png"))]
    return SensorFrames("kinect1", "Microsoft Kinect v1", "structured_light", K, depth, [None], "planes",
                        luminance=lum, stereo_focal_px=580.0, baseline_m=0.075, depth_unit_m=0.0002,
                        source=str(root))


def load_ddrnet(root: Path) -> SensorFrames:
    """DDRNet's structured-light person: raw depth against the multi-frame fused reference."""
    K = Intrinsics(640, 480, 536.628, 536.606, 310.591, 234.759)
    depth, ref, group = [], [], []
    for g, grp in enumerate(sorted(p for p in root.iterdir() if p.is_dir())):
        for f in sorted((grp / "depth_map").glob("*.png")):
            hq = grp / "high_quality_depth" / f.name
            if hq.is_file():
                depth.append(_read_png16(f, 0.001))
                ref.append(_read_png16(hq, 0.001))
                group.append(100 * g + len(depth))
    return SensorFrames("ddrnet", "structured-light camera (DDRNet)", "structured_light", K, depth, ref, "fused",
                        group=group, source=str(root))
