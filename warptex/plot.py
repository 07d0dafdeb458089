"""Line charts saved as PNG (loss curves, benchmark scaling), drawn with matplotlib's Agg backend.

matplotlib is imported on first use, so ``import warptex`` stays light.
"""

from __future__ import annotations

import os
from typing import Mapping, Sequence

from warptex.io import _atomic_output, _checked_output_path


def line_chart(
    path: str | os.PathLike,
    panels: Sequence[Mapping],
    *,
    title: str | None = None,
    dpi: int = 110,
) -> None:
    """Write side-by-side line charts to ``path`` (PNG, atomically: a temporary file, then a rename).

    Args:
        path: the PNG file; its folder is created if missing.
        panels: one dict per chart: ``series`` (``{label: (x, y)}``, sequences of numbers; ``None``
            y values are gaps), ``xlabel``, ``ylabel`` and optional ``title``, ``logx``, ``logy``
            (bools, base 2 for x and 10 for y; a linear y axis starts at 0), ``marks`` (``[(x, label)]``, dashed vertical lines)
            and ``note`` (small text under the axes).
        title: a title over all panels.
        dpi: resolution.
    """
    func = "line_chart"
    if not panels:
        raise ValueError(f"{func}(): needs at least one panel")
    for panel in panels:
        if not panel.get("series"):
            raise ValueError(f"{func}(): every panel needs a non-empty 'series' dict")
    target = _checked_output_path(path, func)

    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 3.9), squeeze=False)
    for ax, panel in zip(axes[0], panels):
        for label, (x, y) in panel["series"].items():
            ax.plot(list(x), [float("nan") if v is None else v for v in y], marker="o", markersize=3, linewidth=1.5, label=label)
        placed: dict = {}
        for x, label in panel.get("marks", ()):
            ax.axvline(x, color="0.5", linestyle="--", linewidth=0.8)
            row = placed[x] = placed.get(x, -1) + 1  # marks at one x stack downwards
            ax.annotate(label, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -10 - 9 * row), textcoords="offset points", fontsize=7, color="0.3")
        if panel.get("logx"):
            ax.set_xscale("log", base=2)
        if panel.get("logy"):
            ax.set_yscale("log")
        else:
            ax.set_ylim(bottom=min(0.0, ax.get_ylim()[0]))  # a linear axis starts at 0: small changes look small
        ax.set_xlabel(panel.get("xlabel", ""))
        ax.set_ylabel(panel.get("ylabel", ""))
        if panel.get("title"):
            ax.set_title(panel["title"], fontsize=10)
        if panel.get("note"):
            ax.annotate(panel["note"], (0, -0.22), xycoords="axes fraction", fontsize=7, color="0.35")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    with _atomic_output(target) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)
