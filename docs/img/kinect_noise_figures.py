"""The figure and the FSPF table of docs/kinect_noise.md.

    .venv/bin/python docs/img/kinect_noise_figures.py          # the figure
    .venv/bin/python docs/img/kinect_noise_figures.py --table  # FSPF planes per frame

The figure is the depth residual (noisy minus true depth) of one frame of a flat wall
under the independent and the correlated noise model, side by side, and one image row of
each. The table runs FSPF with BV2012 Table I's parameters on walls at 1-4 m under both
models.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from autonomy.perception.camera import CameraIntrinsics, pixel_rays  # noqa: E402
from autonomy.perception.fspf import FSPFConfig, fspf  # noqa: E402
from sim.simulator.kinect_noise import KinectNoiseConfig, apply_kinect_noise  # noqa: E402

INTR = CameraIntrinsics()
MODELS = {
    "independent": KinectNoiseConfig(correlated=False, pattern=False),
    "correlated (default)": KinectNoiseConfig(),
}


def wall_depth(normal, dist_m: float) -> np.ndarray:
    """Planar depth of the wall {p : n . p = -dist} in the optical frame (0 where not in view)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    den = pixel_rays(INTR) @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(np.abs(den) > 1e-9, -dist_m / den, -1.0)
    return np.where((z > 0) & (z < 20), z, 0.0).astype(np.float32)


def figure(path: Path, dist_m: float = 2.5, seed: int = 4) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    clean = wall_depth([0.04, 0.12, -1.0], dist_m)
    fig, axes = plt.subplots(
        2, 2, figsize=(11, 6.2), gridspec_kw={"height_ratios": [3, 1.3]}, layout="constrained"
    )
    row = 240
    lim = 40.0
    for k, (name, cfg) in enumerate(MODELS.items()):
        noisy = apply_kinect_noise(clean, INTR, cfg, seed)
        resid = np.where(noisy > 0, (noisy - clean) * 1e3, np.nan)
        ax = axes[0, k]
        im = ax.imshow(resid, cmap="coolwarm", vmin=-lim, vmax=lim, interpolation="nearest")
        ax.axhline(row, color="k", lw=0.6, ls=":")
        ax.set_title(f"{name}: std {np.nanstd(resid):.1f} mm")
        ax.set_xticks([])
        ax.set_yticks([])
        ax = axes[1, k]
        ax.plot(resid[row], lw=0.7, color="C0")
        ax.set_xlim(0, INTR.width)
        ax.set_ylim(-lim, lim)
        ax.set_xlabel("image column (px)")
        ax.set_ylabel(f"row {row} (mm)")
        ax.grid(alpha=0.3)
    fig.colorbar(im, ax=axes[0, :], shrink=0.8, label="depth residual (mm)")
    fig.suptitle(
        f"A flat wall {dist_m} m away (tilted 7 and 2 degrees), one Kinect v1 frame: noisy minus true depth"
    )
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def fspf_table(seeds: range = range(5)) -> None:
    """FSPF (Table I parameters) planes per frame on a wall, mean (min) over seeds, and the
    neighbourhoods it sampled."""
    walls = {"tilted (normal 0, 0.2, -1)": [0.0, 0.2, -1.0], "facing (normal 0, 0, -1)": [0.0, 0.0, -1.0]}
    print("| wall | model | " + " | ".join(f"{d} m" for d in (1.0, 2.0, 3.0, 3.5, 4.0)) + " |")
    print("| --- | --- |" + " --- |" * 5)
    for wname, normal in walls.items():
        for mname, cfg in MODELS.items():
            cells = []
            for dist in (1.0, 2.0, 3.0, 3.5, 4.0):
                clean = wall_depth(normal, dist)
                res = [fspf(apply_kinect_noise(clean, INTR, cfg, s), INTR, FSPFConfig(), seed=s, mount=None) for s in seeds]
                planes = [r.planes for r in res]
                k = np.mean([r.neighbourhoods for r in res])
                cells.append(f"{np.mean(planes):.1f} ({min(planes)}), k {k:.0f}")
            print(f"| {wname} | {mname} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", action="store_true", help="print the FSPF table instead of drawing the figure")
    args = ap.parse_args()
    if args.table:
        fspf_table()
    else:
        figure(Path(__file__).resolve().parent / "kinect_noise_wall_residual.png")
