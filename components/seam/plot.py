"""A picture of a fitted seam: the path, the segments, corners and dwells seen from above
and from the side, and each point's distance to the seam (PNG, matplotlib)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from humanpt.seam.fit import Seam, distance_to_seam, sample_segment

__all__ = ["plot_seam"]


def plot_seam(seam: Seam, p_mm: np.ndarray, out: str | Path, title: str = "") -> Path:
    """Draw ``seam`` over the (N, 3) path points it was fitted on; write ``out`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = np.asarray(p_mm, dtype=float)
    res = distance_to_seam(seam, p)
    fig = plt.figure(figsize=(12, 8))
    gs = fig.add_gridspec(2, 2, height_ratios=[3, 2])
    top, side, resid = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, :])
    for ax, (i, j), name in ((top, (0, 1), "from above: x, y (mm)"), (side, (0, 2), "from the side: x, z (mm)")):
        ax.plot(p[:, i], p[:, j], ".", color="0.6", ms=3, label="taught path")
        for k, seg in enumerate(seam.segments):
            q = sample_segment(seg)
            ax.plot(q[:, i], q[:, j], "-", lw=1.6, color="tab:blue" if seg.kind == "line" else "tab:orange",
                    label=(seg.kind if k == next(n for n, s in enumerate(seam.segments) if s.kind == seg.kind)
                           else None))
        if seam.corners:
            c = np.array([c.point_mm for c in seam.corners])
            ax.plot(c[:, i], c[:, j], "kx", ms=8, mew=2, label="corner")
        if seam.dwells:
            d = np.array([d.point_mm for d in seam.dwells])
            ax.plot(d[:, i], d[:, j], "o", mfc="none", mec="tab:green", ms=10, label="dwell")
        bad = list(seam.outliers)
        if bad:
            ax.plot(p[bad, i], p[bad, j], "r+", ms=9, label="outlier")
        ax.set_title(name)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    top.legend(loc="best", fontsize=8)
    resid.plot(np.arange(len(p)), res, ".-", lw=0.6, ms=3, color="tab:blue")
    resid.axhline(seam.config.tolerance_mm, color="tab:red", ls="--", lw=1,
                  label=f"tolerance {seam.config.tolerance_mm:g} mm")
    for k in seam.corner_cut:
        resid.axvline(k, color="0.85", lw=3, zorder=0)
    resid.set_xlabel("path point")
    resid.set_ylabel("distance to the seam (mm)")
    resid.set_title(f"residuals: RMS {seam.residual_rms_mm:.3f} mm over fitted points, path noise "
                    f"{seam.noise_mm:.3f} mm (grey: the hand rounding a corner, not fitted)")
    resid.legend(loc="upper right", fontsize=8)
    resid.grid(alpha=0.3)
    kinds = [s.kind for s in seam.segments]
    fig.suptitle(title or f"seam: {kinds.count('line')} lines, {kinds.count('arc')} arcs, "
                 f"{len(seam.corners)} corners, {len(seam.dwells)} dwells")
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
