"""Figures of the study (matplotlib, Agg backend), numbered as in the paper.

Each ``make_*`` function builds a :class:`matplotlib.figure.Figure` (so tests can
inspect its layout); the function of the same name without ``make_`` writes it as
PNG and closes it. Every axis is labelled with its quantity, frame and unit;
legends sit outside the data and the layout is constrained, so no two labels
overlap (``tests/test_report_layout.py`` checks this).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import io
import threading
from pathlib import Path
from typing import BinaryIO

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..io.atomic import atomic_write
from .pinch import pinch_labels

COLORS = {"reference": "#2ca02c", "user_axis": "#1f77b4", "orthogonal": "#d62728"}
LABELS = {
    "reference": "distal sensor",
    "user_axis": "user-axis model",
    "orthogonal": "orthogonal model",
}
DPI = 110


def save(fig: Figure, path: Path) -> Path:
    """Write a PNG atomically and close the figure."""
    with atomic_write(path, "wb") as fh:
        save_to(fig, fh)
    return path


def save_to(fig: Figure, fh: BinaryIO, *, tight: bool = True) -> None:
    """Write a PNG to an open binary file (or ``io.BytesIO``) and close the figure.

    ``tight=False`` keeps the figure's own canvas instead of cropping it to its
    artists (``bbox_inches="tight"``), which draws the figure once instead of twice;
    for a figure whose layout already keeps every artist inside.
    """
    try:
        fig.savefig(fh, format="png", dpi=DPI, bbox_inches="tight" if tight else None)
    finally:
        plt.close(fig)


# A figure with one group per subject stops growing here (7040 px at DPI): a study of
# ~500 subjects would pass the PNG limit of 65536 px, and its workers' memory grew with it.
MAX_WIDTH_IN = 64.0


def _tick_labels(ax, labels: list[str], axis_len_in: float) -> None:
    """Category tick labels, rotated when they would not fit side by side; every k-th
    label only when even rotated ones (~0.17 in apart at 9 pt) would overlap."""
    longest = max((len(str(s)) for s in labels), default=1)
    per_label_in = axis_len_in / max(1, len(labels))
    rotate = longest * 0.075 > per_label_in  # ~0.075 in per character at 9 pt
    step = max(1, int(np.ceil(0.17 / max(per_label_in, 1e-9))))
    ax.set_xticks(
        range(0, len(labels), step),
        list(labels)[::step],
        rotation=45 if rotate else 0,
        ha="right" if rotate else "center",
    )


#: Above this many groups a box plot is drawn as a few collections (boxes, whiskers,
#: medians, points) instead of matplotlib's artists per box: the same statistics, and a
#: drawing whose memory and time grow with the numbers only (about 260 KB per subject
#: before, in the worker that draws Figs. 8 and 10). 60 is where groups begin to share
#: the figure's width (:data:`MAX_WIDTH_IN`).
SUMMARY_ABOVE = 60


def _boxes(
    ax,
    data: list[np.ndarray],
    positions: np.ndarray,
    width: float,
    color: str,
    alpha: float,
    fliers: bool,
) -> None:
    """Box plots of ``data`` (one array per group) at ``positions``: matplotlib's
    ``boxplot`` for a few groups; beyond :data:`SUMMARY_ABOVE`, the same statistics
    (``matplotlib.cbook.boxplot_stats``: quartiles, whiskers at 1.5 IQR, outliers) as one
    box collection, one line collection and one marker line."""
    if len(data) <= SUMMARY_ABOVE:
        bp = ax.boxplot(
            data, positions=positions, widths=width, patch_artist=True, showfliers=fliers
        )
        for b in bp["boxes"]:
            b.set_facecolor(color)
            b.set_alpha(alpha)
        return
    from matplotlib.cbook import boxplot_stats
    from matplotlib.collections import LineCollection, PolyCollection

    stats = [
        (x, st) for x, v in zip(positions, data, strict=True) if len(v) for st in boxplot_stats(v)
    ]
    if not stats:
        return
    x = np.array([p for p, _ in stats])
    q1, q3, med, lo, hi = (
        np.array([st[k] for _, st in stats]) for k in ("q1", "q3", "med", "whislo", "whishi")
    )
    h = width / 2
    boxes = np.stack(
        [
            np.stack([x - h, q1], 1),
            np.stack([x + h, q1], 1),
            np.stack([x + h, q3], 1),
            np.stack([x - h, q3], 1),
        ],
        axis=1,
    )
    ax.add_collection(
        PolyCollection(boxes, facecolors=color, edgecolors="k", linewidths=0.5, alpha=alpha)
    )
    lines = np.concatenate(
        [
            np.stack([np.stack([x, lo], 1), np.stack([x, q1], 1)], 1),  # lower whiskers
            np.stack([np.stack([x, q3], 1), np.stack([x, hi], 1)], 1),  # upper whiskers
            np.stack([np.stack([x - h, med], 1), np.stack([x + h, med], 1)], 1),  # medians
        ]
    )
    median_color = matplotlib.rcParams["boxplot.medianprops.color"]  # as matplotlib's boxes
    colors = ["k"] * (2 * len(x)) + [median_color] * len(x)
    segments = LineCollection(lines, colors=colors, linewidths=0.6)
    # The x-limits of matplotlib's boxplot: the outer positions +- 0.5, no margin beyond
    segments.sticky_edges.x.extend([x.min() - 0.5, x.max() + 0.5])
    ax.add_collection(segments)
    lim = ax.dataLim.intervalx
    lim[:] = (min(lim[0], x.min() - 0.5), max(lim[1], x.max() + 0.5))
    if fliers:
        fx = np.concatenate([np.full(len(st["fliers"]), p) for p, st in stats])
        fy = np.concatenate([np.asarray(st["fliers"], dtype=float) for _, st in stats])
        ax.plot(fx, fy, "o", ms=2, mfc="none", mec="k", mew=0.4)
    ax.autoscale_view()


def make_axis_quality(distances: pd.DataFrame) -> Figure:
    """Fig. 8: distance of each cycle's centre of rotation to the fitted axis, per subject.

    ``distances`` has columns ``subject``, ``finger``, ``joint``, ``distance_mm``. With
    the thumb's joints (``cmc``, ``mcp``, ``ip``) a third panel shows them.
    """
    subjects = list(pd.unique(distances["subject"]))  # study order
    width_in = min(MAX_WIDTH_IN, max(10.0, 1.0 * len(subjects) + 3))
    thumb = bool(distances["joint"].isin(("cmc", "mcp", "ip")).any())
    if thumb:
        width_in = min(MAX_WIDTH_IN, max(13.0, 1.5 * len(subjects) + 4))
    fig, axes = plt.subplots(
        1, 3 if thumb else 2, figsize=(width_in, 4.0), layout="constrained", squeeze=False
    )
    axes = axes[0]
    panels = ((axes[0], ("dip", "pip"), "(a) DIP and PIP"), (axes[1], ("mp",), "(b) MP"))
    if thumb:  # the joints with per-cycle centres (a saddle CMC has none)
        tj = tuple(j for j in ("cmc", "mcp", "ip") if (distances["joint"] == j).any())
        panels += ((axes[2], tj, f"(c) thumb {', '.join(j.upper() for j in tj)}"),)
    colors = {
        "dip": "#d62728",
        "pip": "#2ca02c",
        "mp": "#1f77b4",
        "cmc": "#9467bd",
        "mcp": "#8c564b",
        "ip": "#e377c2",
    }
    for ax, joints, title in panels:
        width = 0.8 / len(joints)
        for k, j in enumerate(joints):
            sel = distances[distances["joint"] == j]
            data = [sel.loc[sel["subject"] == s, "distance_mm"].dropna() for s in subjects]
            pos = np.arange(len(subjects)) + (k - (len(joints) - 1) / 2) * width
            _boxes(ax, data, pos, width * 0.9, colors[j], 0.6, fliers=True)
            ax.plot([], [], "s", color=colors[j], label=j.upper())
        _tick_labels(ax, subjects, width_in / len(panels) - 1)
        ax.set_xlabel("subject")
        ax.set_title(title, loc="left", fontsize=10)
        ax.set_ylabel("cycle centre to fitted axis (mm)")
        ax.legend(frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    fig.suptitle(
        "Fig. 8 - axis quality: per-cycle centres of rotation vs the fitted axis", fontsize=10
    )
    return fig


_TRAJECTORY_PLANES = ((0, 1), (2, 1), (2, 0))  # Fig. 9's panels: (x, y), (z, y), (z, x)


def _trajectory_panels(
    time: np.ndarray, tips: dict[str, np.ndarray]
) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """Fig. 9's three panels: per panel the (x, y) of the user-axis and orthogonal lines
    and of the reference points (every 0.1 s), mm, relative to the mean reference tip."""
    dt = np.diff(time)
    dt = dt[np.isfinite(dt) & (dt > 0)]
    step = max(1, round(0.1 / np.median(dt))) if dt.size else 1
    ref = tips["reference"]
    centre = np.nanmean(ref, axis=0)
    lines = [tips[src] - centre for src in ("user_axis", "orthogonal")]
    r = ref[::step] - centre
    return [[(p[:, i], p[:, j]) for p in (*lines, r)] for i, j in _TRAJECTORY_PLANES]


def _trajectory_title(subject: str) -> str:
    return (
        f"Fig. 9 - grasp fingertip trajectories, subject {subject}: hand-sensor frame, "
        "origin at the mean reference fingertip"
    )


def make_trajectories(time: np.ndarray, tips: dict[str, np.ndarray], subject: str) -> Figure:
    """Fig. 9: fingertip trajectories of both models and the distal-sensor reference.

    Parameters
    ----------
    time : ndarray, shape (n,)
        Seconds.
    tips : dict of str to ndarray, shape (n, 3)
        ``reference``, ``user_axis``, ``orthogonal`` fingertips in the hand sensor
        frame (mm); plotted relative to the mean reference fingertip.
    subject : str
        For the title.
    """
    # A fixed layout (room for 4-digit tick labels between the panels): the constrained
    # layout's solver took a third of the time of each study task's PNG.
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.6))
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.2, top=0.87, wspace=0.32)
    handles = []
    panels = _trajectory_panels(time, tips)
    for ax, (i, j), panel in zip(axes, _TRAJECTORY_PLANES, panels, strict=True):
        for src, (x, y) in zip(("user_axis", "orthogonal"), panel, strict=False):
            (h,) = ax.plot(x, y, "-", lw=0.7, color=COLORS[src], label=LABELS[src], alpha=0.8)
            handles.append(h)
        (h,) = ax.plot(
            *panel[2],
            ".",
            ms=3,
            color=COLORS["reference"],
            label=LABELS["reference"] + " (every 0.1 s)",
        )
        handles.append(h)
        ax.set_xlabel(f"hand-sensor {'xyz'[i]} (mm)")
        ax.set_ylabel(f"hand-sensor {'xyz'[j]} (mm)")
        ax.set_title(f"{'xyz'[i]}-{'xyz'[j]} plane", loc="left", fontsize=10)
        ax.set_aspect("equal", adjustable="datalim")
        ax.locator_params(nbins=5)
    fig.legend(handles=handles[:3], loc="lower center", ncols=3, frameon=False, fontsize=9)
    fig.suptitle(_trajectory_title(subject), fontsize=10)
    return fig


_TRAJECTORIES: Figure | None = None  # Fig. 9 kept by trajectories_png, one per process
_TRAJECTORIES_LOCK = threading.Lock()


def trajectories_png(time: np.ndarray, tips: dict[str, np.ndarray], subject: str) -> bytes:
    """Fig. 9 as PNG bytes, the bytes ``save_to(make_trajectories(...), fh, tight=False)``
    writes, drawn on one figure this process keeps.

    Every subject's Fig. 9 has the same panels, labels and legend: the figure, its axes
    and tick artists are made once, and each call gives its lines the subject's data,
    rescales the panels and sets the title (a study task drew a fresh figure in about
    0.3 s, a third of that in making artists). Calls from several threads take turns.

    Parameters
    ----------
    time, tips, subject
        As for :func:`make_trajectories`.
    """
    global _TRAJECTORIES
    with _TRAJECTORIES_LOCK:
        if _TRAJECTORIES is None:
            _TRAJECTORIES = make_trajectories(time, tips, subject)
        else:
            for ax, panel in zip(_TRAJECTORIES.axes, _trajectory_panels(time, tips), strict=True):
                for line, (x, y) in zip(ax.lines, panel, strict=True):
                    line.set_data(x, y)
                ax.relim()
                ax.autoscale_view()
            _TRAJECTORIES.suptitle(_trajectory_title(subject), fontsize=10)
        png = io.BytesIO()
        _TRAJECTORIES.savefig(png, format="png", dpi=DPI)
    return png.getvalue()


def make_paired_boxes(
    data: pd.DataFrame, by: str, title: str, ylabel: str, xlabel: str | None = None
) -> Figure:
    """Box plots of ``user_axis`` vs ``orthogonal`` errors (mm) per value of ``by`` (Fig. 10)."""
    groups = list(pd.unique(data[by])) if by == "subject" else sorted(data[by].unique())
    width_in = min(MAX_WIDTH_IN, max(6.0, 1.2 * len(groups) + 3))
    fig, ax = plt.subplots(figsize=(width_in, 4.0), layout="constrained")
    for k, src in enumerate(("user_axis", "orthogonal")):
        vals = [data.loc[data[by] == g, src].dropna() for g in groups]
        pos = np.arange(len(groups)) + (k - 0.5) * 0.38
        _boxes(ax, vals, pos, 0.33, COLORS[src], 0.4, fliers=False)
        # every value, so small n stays readable (one artist for all groups beyond a few)
        spread = [
            (x + (np.linspace(-0.08, 0.08, len(v)) if len(v) > 1 else np.zeros(len(v))), v)
            for x, v in zip(pos, vals, strict=True)
        ]
        if len(vals) > SUMMARY_ABOVE:
            spread = [tuple(np.concatenate(c) for c in zip(*spread, strict=True))]
        for x, v in spread:
            ax.plot(x, v, "o", ms=3, color=COLORS[src], mec="k", mew=0.3)
        ax.plot([], [], "s", color=COLORS[src], label=LABELS[src])
    _tick_labels(ax, groups, width_in - 3)
    ax.set_xlabel(xlabel or by)
    ax.set_ylabel(ylabel)
    ax.legend(frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax.set_title(title, loc="left", fontsize=10)
    return fig


def make_target_scatter(targets: pd.DataFrame) -> Figure:
    """Fig. 11: mean fingertip minus target, tracker x-y and x-z, by source and target.

    ``targets`` has columns ``target``, ``source``, ``dx``, ``dy``, ``dz`` (mm,
    tracker frame).
    """
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.8), layout="constrained")
    labels = sorted(targets["target"].unique())
    shade = {t: 0.25 + 0.75 * i / max(1, len(labels) - 1) for i, t in enumerate(labels)}
    markers = {"reference": "^", "user_axis": "o", "orthogonal": "s"}
    for ax, (a, b) in zip(axes, (("dx", "dy"), ("dx", "dz")), strict=True):
        for src in ("reference", "user_axis", "orthogonal"):
            g = targets[targets["source"] == src]
            if g.empty:
                continue
            c = matplotlib.colors.to_rgb(COLORS[src])
            cols = [tuple(1 - shade[t] * (1 - np.array(c))) for t in g["target"]]
            ax.scatter(
                g[a],
                g[b],
                c=cols,
                marker=markers[src],
                s=28,
                label=LABELS[src],
                edgecolors="k",
                linewidths=0.3,
            )
        ax.axhline(0, color="k", lw=0.5)
        ax.axvline(0, color="k", lw=0.5)
        ax.set_xlabel(f"fingertip - target, tracker {a[1]} (mm)")
        ax.set_ylabel(f"fingertip - target, tracker {b[1]} (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.locator_params(nbins=6)
        ax.set_title(f"{a[1]}-{b[1]} plane", loc="left", fontsize=10)
    handles, names = axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncols=3, frameon=False, fontsize=9)
    fig.suptitle(
        "Fig. 11 - mean fingertip minus stylus target during each touch "
        "(darker = later target in the list)",
        fontsize=10,
    )
    return fig


def make_target_bars(targets: pd.DataFrame) -> Figure:
    """Fig. 12: mean and SD of the target error (mm) per target and pooled, per source."""
    labels = sorted(targets["target"].unique())
    groups = [*labels, "all"]
    width_in = max(7.0, 0.9 * len(groups) + 3)
    fig, ax = plt.subplots(figsize=(width_in, 4.0), layout="constrained")
    for k, src in enumerate(("reference", "user_axis", "orthogonal")):
        g = targets[targets["source"] == src]
        means = [g.loc[g["target"] == t, "error_mm"].mean() for t in labels] + [
            g["error_mm"].mean()
        ]
        sds = [g.loc[g["target"] == t, "error_mm"].std(ddof=1) for t in labels] + [
            g["error_mm"].std(ddof=1)
        ]
        ax.bar(
            np.arange(len(groups)) + (k - 1) * 0.27,
            means,
            0.25,
            yerr=np.asarray(sds, dtype=float),  # NaN (a single touch): no bar drawn
            capsize=2,
            color=COLORS[src],
            alpha=0.8,
            label=LABELS[src],
        )
    _tick_labels(ax, groups, width_in - 3)
    ax.set_xlabel("target")
    ax.set_ylabel("fingertip to target distance (mm)")
    ax.legend(frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax.set_title("Fig. 12 - target reaching: mean (SD) over touches", loc="left", fontsize=10)
    return fig


def make_pinch(pinches: pd.DataFrame) -> Figure:
    """Pinches: (a) tip-distance error against truth (or, without truth, the tip distance)
    and (b) pad gap, mean (SD) over events per kind of pinch and source.

    ``pinches`` has the columns of :data:`fingerfit.evaluate.pinch.PINCH_COLUMNS` (mm).
    """
    # Two-line labels (kind, digits), 1.4 in per group: side by side without rotation.
    label = pinch_labels(pinches, sep="\n")
    groups = sorted(set(label))
    truth = bool(np.isfinite(pinches["tip_distance_error_mm"]).any())
    first = "tip_distance_error_mm" if truth else "tip_distance_mm"
    width_in = max(8.0, 1.4 * len(groups) + 3)
    fig, axes = plt.subplots(2, 1, figsize=(width_in, 7.5), layout="constrained")
    panels = (
        (
            axes[0],
            first,
            "(a) tip-point distance, model - true" if truth else "(a) tip-point distance",
            "|tip distance error| (mm)" if truth else "thumb tip to finger tip (mm)",
        ),
        (axes[1], "pad_gap_mm", "(b) pad-to-pad gap (pads touch: 0)", "pad-to-pad gap (mm)"),
    )
    for ax, col, title, ylabel in panels:
        for k, src in enumerate(("reference", "user_axis", "orthogonal")):
            g = pinches[pinches["source"] == src]
            lab = label[g.index]
            means = [g.loc[lab == x, col].mean() for x in groups]
            sds = [g.loc[lab == x, col].std(ddof=1) for x in groups]
            ax.bar(
                np.arange(len(groups)) + (k - 1) * 0.27,
                means,
                0.25,
                yerr=np.asarray(sds, dtype=float),
                capsize=2,
                color=COLORS[src],
                alpha=0.8,
                label=LABELS[src],
            )
        if col == "pad_gap_mm" and np.isfinite(pinches["true_pad_gap_mm"]).any():
            true = [pinches.loc[label == x, "true_pad_gap_mm"].mean() for x in groups]
            ax.plot(np.arange(len(groups)), true, "k_", ms=30, mew=2, label="true pad gap")
        ax.set_xticks(range(len(groups)), groups, fontsize=8)
        ax.set_xlabel("pinch (kind, digits)")
        ax.set_ylabel(ylabel)
        ax.set_title(title, loc="left", fontsize=10)
    handles, names = axes[1].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncols=4, frameon=False, fontsize=9)
    fig.suptitle("Pinches: mean (SD) over pinch events", fontsize=10)
    return fig
