#!/usr/bin/env python3
"""OpenCV peer for needle-vision marker tracking.

Runs OpenCV matchTemplate (TM_CCOEFF_NORMED) in a +-6 px window around each
prediction, with a 3-point parabola fit of the correlation peak in x and y
(the usual subpixel add-on), on the frames written by

    cargo run --release -p needle-vision --example render_peer_frames -- /tmp/vision-peer

and prints its accuracy and time beside needle-vision's (read from ours.csv).

Set-up (any Python 3.9+):
    python3 -m venv /tmp/peer-env && /tmp/peer-env/bin/pip install opencv-python-headless numpy
    /tmp/peer-env/bin/python bench/peers/vision_opencv_peer.py /tmp/vision-peer

Single-threaded (cv2.setNumThreads(1)) to compare with our one-core figure.
"""

import csv
import sys
import time
from pathlib import Path

import cv2
import numpy as np

SEARCH = 6
HALF = 16


def parabola(m1, m0, p1):
    denominator = m1 - 2.0 * m0 + p1
    return 0.0 if denominator == 0.0 else 0.5 * (m1 - p1) / denominator


def main():
    folder = Path(sys.argv[1])
    cv2.setNumThreads(1)
    template_full = cv2.imread(str(folder / "template.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 256.0
    c = template_full.shape[0] // 2
    template = np.ascontiguousarray(template_full[c - HALF : c + HALF + 1, c - HALF : c + HALF + 1])
    truth = {}
    with open(folder / "truth.csv") as f:
        for row in csv.DictReader(f):
            truth[(int(row["frame"]), int(row["id"]))] = tuple(float(row[k]) for k in ("u", "v", "pred_u", "pred_v"))
    frames = sorted({k[0] for k in truth})
    errors, seconds, lost = [], [], 0
    for k in frames:
        image = cv2.imread(str(folder / f"{k:06d}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32)
        ids = sorted(i for (f, i) in truth if f == k)
        start = time.perf_counter()
        found = {}
        for i in ids:
            u, v, pu, pv = truth[(k, i)]
            # Template centre pixel candidates: round(prediction) +- SEARCH.
            cu, cv_ = int(round(pu)), int(round(pv))
            x0, y0 = cu - SEARCH - HALF, cv_ - SEARCH - HALF
            window = image[y0 : y0 + 2 * (SEARCH + HALF) + 1, x0 : x0 + 2 * (SEARCH + HALF) + 1]
            score = cv2.matchTemplate(window, template, cv2.TM_CCOEFF_NORMED)
            _, best, _, (bx, by) = cv2.minMaxLoc(score)
            if best < 0.9 or bx in (0, score.shape[1] - 1) or by in (0, score.shape[0] - 1):
                continue
            dx = parabola(score[by, bx - 1], score[by, bx], score[by, bx + 1])
            dy = parabola(score[by - 1, bx], score[by, bx], score[by + 1, bx])
            found[i] = (x0 + HALF + bx + dx, y0 + HALF + by + dy)
        seconds.append(time.perf_counter() - start)
        for i in ids:
            if i in found:
                u, v, _, _ = truth[(k, i)]
                errors.append((found[i][0] - u, found[i][1] - v))
            else:
                lost += 1
    e = np.array(errors)
    print(
        f"OpenCV matchTemplate + parabola: {len(e)} tracked, {lost} lost, error per coordinate std "
        f"{e.std(axis=0).mean():.5f} px, mean ({e[:, 0].mean():.5f}, {e[:, 1].mean():.5f}) px, "
        f"max |error| {np.abs(e).max():.4f} px, median {1e3 * np.median(seconds):.2f} ms per frame (one thread)"
    )
    ours, our_seconds = [], {}
    with open(folder / "ours.csv") as f:
        for row in csv.DictReader(f):
            k, i = int(row["frame"]), int(row["id"])
            our_seconds[k] = float(row["seconds_per_frame"])
            if row["status"] == "tracked":
                u, v, _, _ = truth[(k, i)]
                ours.append((float(row["u"]) - u, float(row["v"]) - v))
    o = np.array(ours)
    print(
        f"needle-vision ZNCC + IC-GN:      {len(o)} tracked, error per coordinate std {o.std(axis=0).mean():.5f} px, "
        f"mean ({o[:, 0].mean():.5f}, {o[:, 1].mean():.5f}) px, max |error| {np.abs(o).max():.4f} px, "
        f"median {1e3 * np.median(list(our_seconds.values())):.2f} ms per frame (one core)"
    )


if __name__ == "__main__":
    main()
