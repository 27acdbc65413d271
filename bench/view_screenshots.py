"""The pictures of ``docs/view.md``: Rerun's web viewer in headless Chromium.

Run with ``python bench/view_screenshots.py`` (``--out DIR``, default ``docs``). It runs
the commands the documents show, in a temporary folder::

    fingerfit simulate sim --subjects 1 --seed 1 --fingers thumb,index,middle,ring,little
    fingerfit fit sim/S01
    fingerfit view sim/S01/model.json sim/S01/grasp.csv --robot shadow --web
    fingerfit view sim/S01/model.json sim/S01/grasp.csv --web

and takes a screenshot of each ``--web`` viewer (``fingerfit.view.webshot``: Chromium
on this machine only, WebGL from SwiftShader), once the 3D view shows the hand: the
whole viewer with the robot (``view_web_shadow.png``) and the 3D view of the hand
alone (``view_web_hand.png``), each at most 256 colours. The viewer follows the data
as it arrives, so it shows the recording's last frame.
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

from fingerfit.view.webshot import (
    SCENE_BOX,
    HeadlessChromium,
    coloured_share,
    find_chromium,
    served_view,
    shoot,
)

FINGERFIT = str(Path(sys.executable).with_name("fingerfit"))
#: The page's size (CSS pixels = the screenshot's pixels).
SIZE = (1400, 800)
#: Coloured share of the 3D view (``coloured_share``) that says the hand is drawn.
DRAWN = 0.005


def run(*args: str, cwd: Path) -> None:
    """A ``fingerfit`` command, as the documents show it, in ``cwd``."""
    print("fingerfit", *args, flush=True)
    subprocess.run([FINGERFIT, *args, "-q"], cwd=cwd, check=True, stdout=subprocess.DEVNULL)


def picture(browser: HeadlessChromium, args: list[str], cwd: Path) -> Image.Image:
    """A screenshot of ``fingerfit view ARGS --web`` once the hand is drawn."""
    print("fingerfit view", *args, "--web", flush=True)
    absolute = [str(cwd / a) if (cwd / a).exists() else a for a in args]
    with served_view(absolute) as url:
        png = shoot(browser, url, lambda p: coloured_share(p, SCENE_BOX) > DRAWN)
    return Image.open(io.BytesIO(png)).convert("RGB")


def save(image: Image.Image, path: Path) -> None:
    """``image`` as a PNG of at most 256 colours."""
    image.quantize(256, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)
    print(f"{path}: {image.width} x {image.height}, {path.stat().st_size / 1e3:.0f} kB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs")
    args = ap.parse_args()
    binary = find_chromium()
    if binary is None:
        sys.exit("no chromium here (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        run("simulate", "sim", "--subjects", "1", "--seed", "1", "--fingers",
            "thumb,index,middle,ring,little", cwd=work)  # fmt: skip
        run("fit", "sim/S01", cwd=work)
        data = ["sim/S01/model.json", "sim/S01/grasp.csv"]
        with HeadlessChromium(binary, SIZE) as browser:
            if not browser.webgl():
                sys.exit("no WebGL in headless chromium here: no screenshot")
            full = picture(browser, [*data, "--robot", "shadow"], work)
            hand = picture(browser, data, work)
    save(full, args.out / "view_web_shadow.png")
    w, h = hand.size  # the 3D view, its title bar left out
    save(hand.crop((int(0.145 * w), int(0.08 * h), int(0.525 * w), int(0.745 * h))),
         args.out / "view_web_hand.png")  # fmt: skip


if __name__ == "__main__":
    main()
