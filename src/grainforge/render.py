"""Shaded pictures of grains and contact sheets (PNG, via matplotlib)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["shade", "contact_sheet"]

_LIGHT = np.array([0.45, -0.55, 0.70])


def shade(ax, mesh, *, color=(0.78, 0.68, 0.52), elev: float = 20.0, azim: float = -60.0) -> None:
    """Draw ``mesh`` on a 3D matplotlib axis with Lambert + ambient shading."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v = np.asarray(mesh.vertices)
    f = np.asarray(mesh.faces)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-300
    light = _LIGHT / np.linalg.norm(_LIGHT)
    lam = np.clip(n @ light, 0.0, 1.0)
    base = np.asarray(color)
    rgb = np.clip(base[None, :] * (0.30 + 0.75 * lam[:, None]), 0, 1)
    coll = Poly3DCollection(tri, facecolors=rgb, edgecolors="none", linewidths=0, antialiased=False)
    ax.add_collection3d(coll)
    c = (v.max(0) + v.min(0)) / 2
    r = (v.max(0) - v.min(0)).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()


def contact_sheet(
    meshes: Sequence, labels: Sequence[str], out: str | Path, *, columns: int | None = None,
    title: str | None = None, panel_size: float = 2.4, dpi: int = 110,
) -> Path:
    """Write a PNG with one shaded, labelled panel per mesh.

    Parameters
    ----------
    meshes : sequence of trimesh.Trimesh or Grain
    labels : sequence of str
        One label per panel.
    out : path
        PNG file to write (atomically).
    columns : int, optional
        Panels per row (default: about square).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import atomic_write

    if len(meshes) != len(labels):
        raise ValueError("one label per mesh is needed")
    if not meshes:
        raise ValueError("nothing to render")
    n = len(meshes)
    cols = columns or int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / cols))
    fig = plt.figure(figsize=(panel_size * cols, panel_size * rows + (0.4 if title else 0)), dpi=dpi)
    for i, (m, lab) in enumerate(zip(meshes, labels)):
        ax = fig.add_subplot(rows, cols, i + 1, projection="3d")
        shade(ax, m.mesh if hasattr(m, "params") else m)
        ax.set_title(lab, fontsize=8, pad=-2)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92 if title else 0.97, wspace=0, hspace=0.08)
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Software": None})
    plt.close(fig)
    return atomic_write(out, buf.getvalue())
