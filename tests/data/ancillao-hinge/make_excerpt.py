"""How ``hinge.csv`` and ``axis-markers.csv`` were made from the original (not shipped).

    python tests/data/ancillao-hinge/make_excerpt.py HingeSampleData.mat

``HingeSampleData.mat`` is ``DATA/HingeSampleData.mat`` of github.com/Andrea14-ing/IHA_paper
(commit 2a4adb93e96300c62bfc7d5b673446cdd641e8b3). Frames 0-1199 (the first 12 s, 100 Hz)
are kept, every second one (50 Hz); metres become millimetres; rotation matrices become
w,x,y,z quaternions.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.io as sio

from fingerfit.transforms import quat_wxyz_from_matrix

HERE = Path(__file__).resolve().parent


def main(mat: str) -> None:
    h = sio.loadmat(mat, squeeze_me=True, struct_as_record=False)["hinge"]
    keep = np.arange(0, 1200, 2)
    time = keep / float(h.fs)
    cols = [time[:, None]]
    for t in (h.T1_0, h.T2_0):
        cols.append(quat_wxyz_from_matrix(np.moveaxis(t, -1, 0)[keep, :3, :3]))
    for t in (h.T1_0, h.T2_0):
        cols.append(1000.0 * np.moveaxis(t, -1, 0)[keep, :3, 3])
    header = "Time,w1,x1,y1,z1,w2,x2,y2,z2,loc1_x,loc1_y,loc1_z,loc2_x,loc2_y,loc2_z"
    fmt = ["%.2f"] + ["%.9f"] * 8 + ["%.4f"] * 6
    np.savetxt(HERE / "hinge.csv", np.hstack(cols), fmt=fmt, delimiter=",", header=header,
               comments="")  # fmt: skip
    markers = np.hstack([time[:, None], 1000 * h.markers.ax1[keep], 1000 * h.markers.ax2[keep]])
    np.savetxt(HERE / "axis-markers.csv", markers, fmt=["%.2f"] + ["%.4f"] * 6, delimiter=",",
               header="time,ax1_x,ax1_y,ax1_z,ax2_x,ax2_y,ax2_z", comments="")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1])
