#!/usr/bin/env python3
"""The photo's sun, estimated from the photo and the LiDAR (the photo's date is unknown).

Source: IGN — LiDAR HD and BD ORTHO (Licence Ouverte / Etalab 2.0). Nothing here uses dbms.

    python3 estimate_sun.py [SOURCE_DIR]   # needs numpy, scipy, laspy[lazrs], pillow; writes sun.json

Method: the LiDAR's surface (highest point of every class but noise, 0.5 m cells on the DTM's
lattice) casts shadows for a candidate sun (azimuth, elevation); on the open ground of the photo
tile (IGN's DHM < 0.5 m), the shadow predicted is compared with the photo's darkness (its
shadow index: Rec. 601 luminance, lowered for bluish sky-lit cells, as dbms's docs describe).
The score is their correlation; the sun is its maximum over a grid of 2 deg (coarse) then
0.5 deg (fine). This is Z = L tan e over every edge of the scene at once: each wall, crown and
roof edge of known LiDAR height places its shadow's far boundary at L = Z / tan e along the
azimuth. The uncertainty: the spread of the maximum when the ground cells are resampled in
5 m x 5 m blocks (block bootstrap, 200 draws): neighbouring cells are not independent.
"""
import json
import math
import os
import sys

import numpy as np
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import make_truth as mt  # noqa: E402  (the same points, grid and DTM)

PHOTO_X0, PHOTO_Y1, PHOTO_CELL = 770549.8, 6277600.2, 0.2
STEP_M = 0.5
TOL_M = 0.3  # a ray must pass this far below the surface to count as blocked


def surface(x, y, z, c):
    keep = c < 7  # 1 unclassified .. 6 building; 64 is IGN's "other/noise"
    r, k = mt.cell_of(x[keep], y[keep])
    ok = (r >= 0) & (r < mt.N) & (k >= 0) & (k < mt.N)
    dsm = np.full((mt.N, mt.N), -np.inf)
    np.maximum.at(dsm, (r[ok], k[ok]), z[keep][ok])
    from scipy import ndimage
    holes = ~np.isfinite(dsm)
    filled = ndimage.maximum_filter(np.where(holes, -1e9, dsm), size=3)
    dsm[holes] = filled[holes]
    return dsm


def shadow_index_grid():
    """The photo's shadow index averaged over each 0.5 m cell (5 x 5 samples a cell)."""
    rgb = np.array(Image.open(os.path.join(mt.SRC, "ortho", "ortho_rgb_0p20m_epsg2154.tif")), float)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    y = 0.299 * r + 0.587 * g + 0.114 * b
    blue = b / np.maximum(r + g + b, 1)
    idx = y * (1 - np.maximum(0, blue - 1 / 3))
    idx[(rgb == 255).all(axis=2)] = np.nan
    out = np.full((mt.N, mt.N), np.nan)
    sub = (np.arange(5) + 0.5) / 5 * mt.CELL
    rows, cols = np.mgrid[0:mt.N, 0:mt.N]
    acc = np.zeros((mt.N, mt.N))
    cnt = np.zeros((mt.N, mt.N))
    for dy in sub:
        for dx in sub:
            X = mt.X0 + cols * mt.CELL + dx
            Y = mt.Y1 - rows * mt.CELL - dy
            pc = np.floor((X - PHOTO_X0) / PHOTO_CELL).astype(int)
            pr = np.floor((PHOTO_Y1 - Y) / PHOTO_CELL).astype(int)
            ok = (pc >= 0) & (pc < idx.shape[1]) & (pr >= 0) & (pr < idx.shape[0])
            v = np.full((mt.N, mt.N), np.nan)
            v[ok] = idx[pr[ok], pc[ok]]
            good = np.isfinite(v)
            acc[good] += v[good]
            cnt[good] += 1
    out[cnt == 25] = acc[cnt == 25] / 25
    return out


def cast(dsm, rows, cols, az, el):
    """Is each cell (rows, cols) in the shadow of the surface for a sun at az/el (degrees)?"""
    s, c = math.sin(math.radians(az)), math.cos(math.radians(az))
    t = math.tan(math.radians(el))
    z0 = dsm[rows, cols]
    top = np.nanmax(dsm)
    shade = np.zeros(len(rows), bool)
    for i in range(1, int((top - z0.min()) / t / STEP_M) + 2):
        d = i * STEP_M
        rr = np.rint(rows - d * c / mt.CELL).astype(int)
        kk = np.rint(cols + d * s / mt.CELL).astype(int)
        ok = (rr >= 0) & (rr < mt.N) & (kk >= 0) & (kk < mt.N)
        blocked = np.zeros(len(rows), bool)
        blocked[ok] = dsm[rr[ok], kk[ok]] > z0[ok] + d * t + TOL_M
        shade |= blocked
    return shade


def score(pred, dark):
    p = pred.astype(float)
    if p.std() == 0:
        return -1.0
    return float(np.corrcoef(p, dark)[0, 1])


def main():
    x, y, z, c = mt.load_points()
    dsm = surface(x, y, z, c)
    dtm = mt.dtm_grid()
    idx = shadow_index_grid()
    ground = np.isfinite(idx) & np.isfinite(dtm) & (dsm - dtm < 0.5)
    rows, cols = np.nonzero(ground)
    dark = -idx[rows, cols]
    coarse = [(a, e) for a in range(90, 272, 4) for e in range(26, 80, 2)]
    sc = [score(cast(dsm, rows, cols, a, e), dark) for a, e in coarse]
    a0, e0 = coarse[int(np.argmax(sc))]
    fine = [(a0 + da, e0 + de) for da in np.arange(-6, 6.01, 0.5) for de in np.arange(-4, 4.01, 0.5)]
    preds = np.array([cast(dsm, rows, cols, a, e) for a, e in fine], float)
    best = fine[int(np.argmax([score(p, dark) for p in preds]))]
    # block bootstrap over 5 m x 5 m blocks of ground cells
    block = (rows // 10) * 1000 + cols // 10
    ids = np.unique(block)
    rng = np.random.default_rng(39)
    draws = []
    for _ in range(200):
        pick = rng.choice(ids, len(ids))
        w = np.concatenate([np.nonzero(block == b)[0] for b in pick])
        d = dark[w]
        draws.append(fine[int(np.argmax([score(p[w], d) for p in preds]))])
    draws = np.array(draws)
    out = {
        "source": "IGN — LiDAR HD and BD ORTHO (Etalab 2.0)",
        "method": "estimate_sun.py: LiDAR surface's cast shadow vs the photo's shadow index on open ground, max correlation",
        "sun_azimuth_deg": best[0], "sun_elevation_deg": best[1],
        "score": round(max(score(p, dark) for p in preds), 3),
        "coarse_best": {"azimuth_deg": a0, "elevation_deg": e0, "score": round(max(sc), 3)},
        "bootstrap_sd": {"azimuth_deg": round(float(draws[:, 0].std()), 2),
                         "elevation_deg": round(float(draws[:, 1].std()), 2)},
        "bootstrap_range_95": {"azimuth_deg": [float(np.percentile(draws[:, 0], 2.5)), float(np.percentile(draws[:, 0], 97.5))],
                               "elevation_deg": [float(np.percentile(draws[:, 1], 2.5)), float(np.percentile(draws[:, 1], 97.5))]},
        "ground_cells": int(len(rows)),
    }
    with open(os.path.join(HERE, "sun.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    print(json.dumps(out, indent=1))
    # the score surface, coarse grid, for the record
    with open(os.path.join(HERE, "sun_scores.tsv"), "w") as fh:
        fh.write("azimuth_deg\televation_deg\tscore\n")
        for (a, e), s in zip(coarse, sc):
            fh.write(f"{a}\t{e}\t{s:.4f}\n")


if __name__ == "__main__":
    main()
