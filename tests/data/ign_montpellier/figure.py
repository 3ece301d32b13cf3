#!/usr/bin/env python3
"""docs/images/ign-montpellier.png: the photo with the LiDAR's footprints (red), roof faces
(cyan) and the shadow the LiDAR's surface casts under sun.json's sun (blue tint, open ground).

Source: IGN — LiDAR HD and BD ORTHO (Licence Ouverte / Etalab 2.0).

    python3 figure.py      # after make_truth.py and estimate_sun.py
"""
import json
import os
import sys

import numpy as np
from PIL import Image, ImageDraw

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import estimate_sun as es  # noqa: E402
import make_truth as mt  # noqa: E402

SCALE = 2


def main():
    sun = json.load(open(os.path.join(HERE, "sun.json")))
    x, y, z, c = mt.load_points()
    dsm = es.surface(x, y, z, c)
    dtm = mt.dtm_grid()
    rows, cols = np.nonzero(np.isfinite(dtm) & (dsm - dtm < 0.5))
    shade = es.cast(dsm, rows, cols, sun["sun_azimuth_deg"], sun["sun_elevation_deg"])
    rgb = np.array(Image.open(os.path.join(HERE, "ortho_rgb_0p20m.tif")), float)
    # tint the photo's pixels whose 0.5 m cell is predicted in shadow
    pr, pc = np.mgrid[0:252, 0:252]
    X = es.PHOTO_X0 + (pc + 0.5) * es.PHOTO_CELL
    Y = es.PHOTO_Y1 - (pr + 0.5) * es.PHOTO_CELL
    cr, cc = mt.cell_of(X, Y)
    mask = np.zeros((mt.N, mt.N), bool)
    mask[rows[shade], cols[shade]] = True
    tint = mask[cr, cc]
    rgb[tint] = 0.6 * rgb[tint] + 0.4 * np.array([40, 90, 255])
    im = Image.fromarray(rgb.clip(0, 255).astype(np.uint8)).resize((252 * SCALE,) * 2, Image.NEAREST)
    d = ImageDraw.Draw(im)

    def px(p):
        return ((p[0] - es.PHOTO_X0) / es.PHOTO_CELL * SCALE, (es.PHOTO_Y1 - p[1]) / es.PHOTO_CELL * SCALE)

    for name, colour in (("faces.geojson", (0, 255, 255)), ("footprints.geojson", (255, 40, 40))):
        for f in json.load(open(os.path.join(HERE, name)))["features"]:
            ring = [px(p) for p in f["geometry"]["coordinates"][0]]
            d.line(ring, fill=colour, width=1 if name == "faces.geojson" else 2)
            if "name" in f["properties"]:
                xs, ys = zip(*ring[:-1])
                d.text((np.clip(np.mean(xs), 2, 480), np.clip(np.mean(ys), 2, 490)), f["properties"]["name"], fill=(255, 255, 0))
    out = os.path.join(HERE, "..", "..", "..", "docs", "images", "ign-montpellier.png")
    im.save(os.path.normpath(out), optimize=True)


if __name__ == "__main__":
    main()
