#!/usr/bin/env python3
"""Does the photo's roof shading match the LiDAR's pitch under the estimated sun?

Source: IGN — LiDAR HD and BD ORTHO (Licence Ouverte / Etalab 2.0). Nothing here uses dbms.

    python3 shading.py     # after make_truth.py and estimate_sun.py; writes shading.json

Lambertian model: a face of albedo b, unit normal n (its LiDAR plane), under a sun s of
strength S and a sky of strength A (isotropic, every face sees about the same sky at these
pitches), is seen at I = b (S max(0, n.s) + A). Two faces of one roof share b, so their ratio
I1/I2 = (S cos t1 + A)/(S cos t2 + A) depends on the pitch and the sun only. A/S from the
ground: lit and shadowed open ground (the LiDAR surface's cast shadow under the same sun, as
in estimate_sun.py) give I_shadow/I_lit = A/(S sin e + A).

Observed: the mean linear luminance (sRGB decoded; Rec. 709 weights) of the photo's pixels
inside each face polygon of faces.geojson (planes fitted by make_truth.py) less 0.6 m along
its outline, after moving the polygons by the one offset that puts the LiDAR's pitched roofs on
the photo's tile-coloured roofs (the photo is not a true orthophoto), trimmed to the 10-90th
percentiles (chimneys, skylights).
"""
import json
import math
import os
import sys

import numpy as np
from PIL import Image
from scipy import ndimage

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import estimate_sun as es  # noqa: E402
import make_truth as mt  # noqa: E402

PX0, PY1, PC = es.PHOTO_X0, es.PHOTO_Y1, es.PHOTO_CELL


def linear(v):
    v = v / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def photo():
    rgb = np.array(Image.open(os.path.join(mt.SRC, "ortho", "ortho_rgb_0p20m_epsg2154.tif")), float)
    lin = linear(rgb)
    lum = 0.2126 * lin[..., 0] + 0.7152 * lin[..., 1] + 0.0722 * lin[..., 2]
    tile_red = (rgb[..., 0] - rgb[..., 1] > 25) & (rgb[..., 0] > 120)
    return lum, tile_red


def pixel_mask(poly, dx=0.0, dy=0.0, shape=(252, 252)):
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    X = PX0 + (cols + 0.5) * PC - dx
    Y = PY1 - (rows + 0.5) * PC - dy
    return mt.point_in_poly(X.ravel(), Y.ravel(), poly).reshape(shape)


def scene_offset(tile_red):
    """The shift (east, north, metres) of the photo's tile-coloured roofs from the LiDAR's:
    the one shift (whole photo pixels, within 2 m) that maximises the share of tile-coloured
    pixels inside the pitched parts' footprints minus the share in a 1 m ring around them."""
    fp = json.load(open(os.path.join(HERE, "footprints.geojson")))["features"]
    pad = 10
    m = np.zeros((252 + 2 * pad, 252 + 2 * pad), bool)
    for f in fp:
        if f["properties"]["roof_form"] in ("gable", "hip") and f["properties"]["in_tile"] > 0.5:
            m[pad:-pad, pad:-pad] |= pixel_mask(f["geometry"]["coordinates"][0])
    ring = ndimage.binary_dilation(m, iterations=5) & ~m
    best = (-2.0, 0, 0)
    for di in range(-pad, pad + 1):
        for dj in range(-pad, pad + 1):
            mi = np.roll(m, (di, dj), axis=(0, 1))[pad:-pad, pad:-pad]
            ri = np.roll(ring, (di, dj), axis=(0, 1))[pad:-pad, pad:-pad]
            s = tile_red[mi].mean() - tile_red[ri].mean()
            if s > best[0]:
                best = (s, di, dj)
    s, di, dj = best
    return round(dj * PC, 1), round(-di * PC, 1), round(float(s), 3)


def cos_incidence(pitch, aspect, az, el):
    p, a, z, e = (math.radians(v) for v in (pitch, aspect, az, el))
    return max(0.0, math.sin(p) * math.cos(e) * math.cos(a - z) + math.cos(p) * math.sin(e))


def sky_ratio(az, el, lum):
    """A/S from the open ground's lit and shadowed cells (linear luminance, 0.5 m cells)."""
    x, y, z, c = mt.load_points()
    dsm = es.surface(x, y, z, c)
    dtm = mt.dtm_grid()
    rows, cols = np.nonzero(np.isfinite(dtm) & (dsm - dtm < 0.5))
    inside = (rows >= 30) & (rows < 130) & (cols >= 30) & (cols < 130)
    rows, cols = rows[inside], cols[inside]
    shade = es.cast(dsm, rows, cols, az, el)
    X = mt.X0 + (cols + 0.5) * mt.CELL
    Y = mt.Y1 - (rows + 0.5) * mt.CELL
    pr = np.clip(((PY1 - Y) / PC).astype(int), 0, 251)
    pc = np.clip(((X - PX0) / PC).astype(int), 0, 251)
    v = lum[pr, pc]
    q = np.median(v[shade]) / np.median(v[~shade])
    return q * math.sin(math.radians(el)) / (1 - q), float(q)


def main():
    sun = json.load(open(os.path.join(HERE, "sun.json")))
    az, el = sun["sun_azimuth_deg"], sun["sun_elevation_deg"]
    lum, tile_red = photo()
    faces = json.load(open(os.path.join(HERE, "faces.geojson")))["features"]
    a_over_s, q = sky_ratio(az, el, lum)
    by_building = {}
    for f in faces:
        by_building.setdefault(f["properties"]["building"], []).append(f)
    dx, dy, contrast = scene_offset(tile_red)
    out = {"sun": {"azimuth_deg": az, "elevation_deg": el},
           "photo_offset_m": [dx, dy], "offset_contrast": contrast,
           "ground_shadow_over_lit": round(q, 3), "sky_over_sun": round(a_over_s, 3), "roofs": []}
    for name, fs in by_building.items():
        polys = [f["geometry"]["coordinates"][0] for f in fs]
        rows = []
        for f, poly in zip(fs, polys):
            # the face's interior: 0.6 m in from its outline (ridge, eaves, neighbours' faces)
            m = ndimage.binary_erosion(pixel_mask(poly, dx, dy), iterations=3)
            v = lum[m]
            lo, hi = np.percentile(v, [10, 90]) if len(v) else (0, 0)
            v = v[(v >= lo) & (v <= hi)]
            p = f["properties"]
            c = cos_incidence(p["pitch_deg"], p["aspect_deg"], az, el)
            rows.append({"aspect_deg": p["aspect_deg"], "pitch_deg": p["pitch_deg"], "pixels": int(m.sum()),
                         "observed_linear_luminance": round(float(v.mean()), 4) if len(v) else None,
                         "observed_sd": round(float(v.std()), 4) if len(v) else None,
                         "cos_incidence": round(c, 4)})
        entry = {"building": name, "faces": rows}
        if len(rows) >= 2 and all(r["observed_linear_luminance"] for r in rows[:2]):
            f1, f2 = rows[0], rows[1]
            entry["predicted_ratio_direct_only"] = round(f1["cos_incidence"] / f2["cos_incidence"], 3)
            entry["predicted_ratio_with_sky"] = round((f1["cos_incidence"] + a_over_s) / (f2["cos_incidence"] + a_over_s), 3)
            entry["observed_ratio"] = round(f1["observed_linear_luminance"] / f2["observed_linear_luminance"], 3)
            # what the same sun would show at other pitches (same aspects): is it observable?
            entry["predicted_ratio_by_pitch"] = {
                str(pp): round((cos_incidence(pp, f1["aspect_deg"], az, el) + a_over_s)
                               / (cos_incidence(pp, f2["aspect_deg"], az, el) + a_over_s), 3)
                for pp in (10, 20, 30, 45)}
        out["roofs"].append(entry)
    with open(os.path.join(HERE, "shading.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
