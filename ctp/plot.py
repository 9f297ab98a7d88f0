"""Figures: the scene with its contacts, and DAFC directions as in the paper's Fig. 4(a)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from analysis.geometry import object_origin
from analysis.kinematics import HandKinematics

if TYPE_CHECKING:
    from analysis.combination import CombinationReport
    from analysis.scene import Scene

#: one colour per contact state, the same as the dashboard's (api/static/app.js, COLORS)
STATE_COLOURS = {"F": "#2a9d8f", "S": "#e9a03b", "D": "#d1495b", "N": "#577590"}
#: DAFC members, the same green as the dashboard's DAFC plot
DAFC_COLOUR = "#2a9d8f"


def draw_scene(ax: Any, scene: Scene, combination: str | None = None) -> None:
    """Draw a scene (2-D: in the plane; 3-D: projected on x-z) with contact normals and cones."""
    hand = HandKinematics.from_scene(scene)
    i0, i1 = (0, 1) if scene.dim == 2 else (0, 2)
    po = object_origin(scene)
    shape = scene.object.shape
    if shape.type in ("disk", "sphere"):
        ax.add_patch(plt.Circle((po[i0], po[i1]), shape.radius, fill=False, lw=2, color="k"))
    ax.plot(po[i0], po[i1], "k+")
    for b in scene.fixed_bodies:
        s = b.shape
        if s.type == "segment":
            P = np.asarray(s.points)
            ax.plot(P[:, i0], P[:, i1], color="saddlebrown", lw=4)
        elif s.type == "box":
            ctr = np.asarray(s.position if s.position is not None else np.zeros(scene.dim))
            h = np.asarray(s.size) / 2
            ax.add_patch(plt.Rectangle((ctr[i0] - h[i0], ctr[i1] - h[i1]), 2 * h[i0], 2 * h[i1],
                                       color="saddlebrown", alpha=0.6))
    for f in hand.fingers:
        for name in f.body_names():
            ref = hand.resolve_body(name)
            assert ref is not None
            a, b2 = hand.body_segment(ref, hand.q0)
            ax.plot([a[i0], b2[i0]], [a[i1], b2[i1]], "-o", color="tab:purple", lw=3, ms=4)
    size = 0.25
    for ci, c in enumerate(scene.contacts):
        p, n = np.asarray(c.point), np.asarray(c.normal)
        state = combination[ci] if combination else "F"
        col = STATE_COLOURS.get(state, "k")
        ax.annotate("", xy=(p[i0] + size * n[i0], p[i1] + size * n[i1]), xytext=(p[i0], p[i1]),
                    arrowprops={"arrowstyle": "->", "color": col, "lw": 2})
        if c.mu > 0 and scene.dim == 2 and state == "F":
            t = np.array([-n[1], n[0]])
            for sgn in (1, -1):
                e = n + sgn * c.mu * t
                e = e / np.linalg.norm(e)
                ax.plot([p[0], p[0] + size * e[0]], [p[1], p[1] + size * e[1]], color=col, lw=0.8)
        # contacts numbered from 0, as on the dashboard and in `ctp simulate`
        ax.text(p[i0], p[i1], f" {ci}:{state}", fontsize=8, color=col)
    ax.set_aspect("equal")
    ax.set_title(f"{scene.name}" + (f"  [{combination}]" if combination else ""))
    ax.autoscale_view()


def plot_report(path: str | Path, scene: Scene, report: CombinationReport | None) -> Path:
    """Scene (left) and DAFC unit directions (right; 2-D object: (x, y, theta) space)."""
    path = Path(path)
    fig = plt.figure(figsize=(11, 5))
    ax0 = fig.add_subplot(1, 2, 1)
    draw_scene(ax0, scene, report.summary.combination if report else None)
    if report is not None and report.dafc is not None and len(report.dafc.directions):
        ds = report.dafc
        ax1 = fig.add_subplot(1, 2, 2, projection="3d")
        X = ds.directions[:, :3]  # 2-D: (x, y, theta); 3-D: the translation part
        m = ds.member
        ax1.scatter(X[m, 0], X[m, 1], X[m, 2], c=DAFC_COLOUR, s=12, label="DAFC")
        ax1.scatter(X[~m, 0], X[~m, 1], X[~m, 2], c="lightgray", s=4, label="not in DAFC")
        labels = ("x", "y", "theta") if scene.dim == 2 else ("x", "y", "z")
        for setter in (ax1.set_xlim, ax1.set_ylim, ax1.set_zlim):
            setter(-1.05, 1.05)
        ax1.set_xlabel(labels[0])
        ax1.set_ylabel(labels[1])
        ax1.set_zlabel(labels[2])
        ax1.set_title(f"DAFC of {report.summary.combination} (dim {ds.dim}, "
                      f"{'exact' if ds.exact else 'sampled'})")
        ax1.legend(loc="upper left", fontsize=8)
    elif report is not None:
        ax1 = fig.add_subplot(1, 2, 2)
        ax1.text(0.5, 0.5, f"{report.summary.combination}: {report.summary.reason}", ha="center")
        ax1.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
