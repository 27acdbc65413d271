"""Figures of the study (matplotlib, Agg backend), numbered as in the paper."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from ..io.atomic import atomic_write

COLORS = {"reference": "#2ca02c", "user_axis": "#1f77b4", "orthogonal": "#d62728"}
LABELS = {
    "reference": "distal sensor",
    "user_axis": "user-axis model",
    "orthogonal": "orthogonal model",
}


def save(fig: plt.Figure, path: Path) -> Path:
    """Write a PNG atomically and close the figure."""
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def axis_quality(distances: pd.DataFrame, path: Path) -> Path:
    """Fig. 8: distance of each cycle's centre of rotation to the fitted axis, per subject.

    ``distances`` has columns ``subject``, ``finger``, ``joint``, ``distance_mm``.
    """
    subjects = sorted(distances["subject"].unique())
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=False)
    panels = ((axes[0], ("dip", "pip"), "(a) DIP and PIP"), (axes[1], ("mp",), "(b) MP"))
    colors = {"dip": "#d62728", "pip": "#2ca02c", "mp": "#1f77b4"}
    for ax, joints, title in panels:
        width = 0.8 / len(joints)
        for k, j in enumerate(joints):
            sel = distances[distances["joint"] == j]
            data = [sel.loc[sel["subject"] == s, "distance_mm"] for s in subjects]
            pos = np.arange(len(subjects)) + (k - (len(joints) - 1) / 2) * width
            bp = ax.boxplot(
                data, positions=pos, widths=width * 0.9, patch_artist=True, showfliers=True
            )
            for b in bp["boxes"]:
                b.set_facecolor(colors[j])
                b.set_alpha(0.6)
            ax.plot([], [], "s", color=colors[j], label=j.upper())
        ax.set_xticks(range(len(subjects)), subjects)
        ax.set_title(title, loc="left")
        ax.set_ylabel("distance of c_i to axis (mm)")
        ax.legend(frameon=False)
    fig.suptitle(
        "Fig. 8 - axis quality: per-cycle centres of rotation vs the fitted axis", fontsize=10
    )
    return save(fig, path)


def trajectories(time: np.ndarray, tips: dict[str, np.ndarray], subject: str, path: Path) -> Path:
    """Fig. 9: fingertip trajectories of both models against the distal-sensor reference, three planes."""
    step = max(1, round(0.1 / np.median(np.diff(time))))
    fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    ref = tips["reference"]
    centre = np.nanmean(ref, axis=0)
    for ax, (i, j, name) in zip(axes, ((0, 1, "X-Y"), (2, 1, "Z-Y"), (2, 0, "Z-X")), strict=True):
        for src in ("user_axis", "orthogonal"):
            p = tips[src] - centre
            ax.plot(p[:, i], p[:, j], "-", lw=0.7, color=COLORS[src], label=LABELS[src], alpha=0.8)
        r = ref[::step] - centre
        ax.plot(
            r[:, i],
            r[:, j],
            ".",
            ms=3,
            color=COLORS["reference"],
            label=LABELS["reference"] + " (0.1 s)",
        )
        ax.set_xlabel(f"{'XYZ'[i]} (mm)")
        ax.set_ylabel(f"{'XYZ'[j]} (mm)")
        ax.set_title(name + " plane", loc="left")
        ax.set_aspect("equal", adjustable="datalim")
    axes[0].legend(frameon=False, fontsize=8)
    fig.suptitle(
        f"Fig. 9 - grasp fingertip trajectories, subject {subject} (hand sensor frame)", fontsize=10
    )
    return save(fig, path)


def paired_boxes(data: pd.DataFrame, by: str, title: str, ylabel: str, path: Path) -> Path:
    """Box plots of ``user_axis`` vs ``orthogonal`` errors per value of ``by`` (Fig. 10 style)."""
    groups = sorted(data[by].unique())
    fig, ax = plt.subplots(figsize=(max(5, 1.2 * len(groups) + 2), 3.8))
    for k, src in enumerate(("user_axis", "orthogonal")):
        vals = [data.loc[data[by] == g, src].dropna() for g in groups]
        pos = np.arange(len(groups)) + (k - 0.5) * 0.38
        bp = ax.boxplot(vals, positions=pos, widths=0.33, patch_artist=True)
        for b in bp["boxes"]:
            b.set_facecolor(COLORS[src])
            b.set_alpha(0.6)
        ax.plot([], [], "s", color=COLORS[src], label=LABELS[src])
    ax.set_xticks(range(len(groups)), groups)
    ax.set_ylabel(ylabel)
    ax.legend(frameon=False)
    ax.set_title(title, loc="left", fontsize=10)
    return save(fig, path)


def target_scatter(targets: pd.DataFrame, path: Path) -> Path:
    """Fig. 11: fingertip offsets from the targets (X-Y of the tracker frame), by source and target."""
    fig, ax = plt.subplots(figsize=(5.5, 5))
    labels = sorted(targets["target"].unique())
    shade = {t: 0.25 + 0.75 * i / max(1, len(labels) - 1) for i, t in enumerate(labels)}
    markers = {"reference": "^", "user_axis": "o", "orthogonal": "s"}
    for src, g in targets.groupby("source"):
        c = matplotlib.colors.to_rgb(COLORS[src])
        cols = [tuple(1 - shade[t] * (1 - np.array(c))) for t in g["target"]]
        ax.scatter(
            g["dx"],
            g["dy"],
            c=cols,
            marker=markers[src],
            s=28,
            label=LABELS[src],
            edgecolors="k",
            linewidths=0.3,
        )
    ax.axhline(0, color="k", lw=0.5)
    ax.axvline(0, color="k", lw=0.5)
    ax.set_xlabel("dx (mm)")
    ax.set_ylabel("dy (mm)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(frameon=False, fontsize=8)
    ax.set_title(
        "Fig. 11 - fingertip minus target (darker = farther target)", loc="left", fontsize=10
    )
    return save(fig, path)


def target_bars(targets: pd.DataFrame, path: Path) -> Path:
    """Fig. 12: mean and SD of the target error per target and pooled, per source."""
    labels = sorted(targets["target"].unique())
    groups = [*labels, "all"]
    fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(groups) + 2), 3.8))
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
            yerr=sds,
            capsize=2,
            color=COLORS[src],
            alpha=0.8,
            label=LABELS[src],
        )
    ax.set_xticks(range(len(groups)), groups)
    ax.set_ylabel("fingertip error to target (mm)")
    ax.legend(frameon=False, fontsize=8)
    ax.set_title("Fig. 12 - target reaching: mean (SD)", loc="left", fontsize=10)
    return save(fig, path)
