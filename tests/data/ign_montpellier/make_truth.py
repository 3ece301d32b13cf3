#!/usr/bin/env python3
"""Footprints and roof truth for the IGN Montpellier photo tile, from the LiDAR alone.

Source: IGN — LiDAR HD and BD ORTHO (Licence Ouverte / Etalab 2.0), the files of
/work/shared/data/ign_montpellier (see README.md beside this script). Nothing here uses dbms.

    python3 make_truth.py [SOURCE_DIR]      # needs numpy, scipy, laspy[lazrs], pillow

Writes, beside this script:
  footprints.geojson  one Polygon per building part (EPSG:2154), with the LiDAR's truth:
                      roof_z, eave_z, roof_form, roof_azimuth_deg, pitch_deg, ground_z, ...
  faces.geojson       the fitted roof planes of the pitched parts (polygons of their cells)

Method (0.5 m cells on the DTM's lattice):
  1. building cells: at least one class-6 (building) point; closed by one cell, holes filled;
  2. building parts: cells joined when their median class-6 heights differ by < STEP_M
     (a wall is a step, a roof slope of 45 deg is 0.5 m a cell), parts < MIN_AREA_M2 merged
     into the neighbour they share most border with, parts outside the photo tile dropped;
     a part filling < SPLIT_FILL of its rectangle: its strips thinner than THIN_M
     (lean-tos along a block) made parts of their own;
  3. outline: the cells' minimum-area rectangle when they fill >= RECT_FILL of it, else their
     boundary, simplified (Douglas-Peucker, SIMPLIFY_M);
  4. truth, from the part's class-6 points less its outermost cell (walls, overhangs): roof
     planes (local normals by PCA within 1 m, faces by aspect quadrant around the dominant
     axis, least squares refitted on the points within INLIER_M); flat when fewer than 40 %
     of the points slope by more than FLAT_PITCH_DEG, shed with one face, gable with two
     opposite ones, hip with end faces too; pitch = the main faces' slope, ridge azimuth =
     across their aspect (shed: the way it rises); roof_z = 99th percentile of the points
     within INLIER_M of the fitted roof (chimneys and antennas left out; roof_z_all_p99 keeps
     them), eave_z = 2nd percentile of the pitched faces' points (flat: roof_z);
     ground_z = the highest DTM cell under the part.
"""
import glob
import json
import math
import os
import sys

import laspy
import numpy as np
from PIL import Image
from scipy import ndimage

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = sys.argv[1] if len(sys.argv) > 1 else "/work/shared/data/ign_montpellier"
CELL = 0.5
TILE = (770550.0, 6277550.0, 770600.0, 6277600.0)  # the photo's tile
MARGIN = 15.0  # parts reaching out of the tile are outlined whole
X0, Y1 = 770549.75 - 30 * CELL, 6277600.25 + 30 * CELL  # DTM lattice, extended
N = int((50.5 + 2 * 30 * CELL) / CELL)
STEP_M = 0.8
MIN_AREA_M2 = 6.0
SIMPLIFY_M = 0.6
RECT_FILL = 0.85
THIN_M = 2.5
SPLIT_FILL = 0.5
FLAT_PITCH_DEG = 8.0
INLIER_M = 0.3


def load_points():
    xs, ys, zs, cs = [], [], [], []
    for f in sorted(glob.glob(os.path.join(SRC, "lidar", "*.laz"))):
        las = laspy.read(f)
        xs.append(np.asarray(las.x))
        ys.append(np.asarray(las.y))
        zs.append(np.asarray(las.z))
        cs.append(np.asarray(las.classification))
    x, y, z, c = (np.concatenate(a) for a in (xs, ys, zs, cs))
    keep = (x > TILE[0] - MARGIN) & (x < TILE[2] + MARGIN) & (y > TILE[1] - MARGIN) & (y < TILE[3] + MARGIN)
    return x[keep], y[keep], z[keep], c[keep]


def cell_of(x, y):
    return ((Y1 - y) / CELL).astype(int), ((x - X0) / CELL).astype(int)


def read_tif(path):
    return np.array(Image.open(path), dtype=np.float64)


def dtm_grid():
    """IGN's DTM (0.5 m, origin 770549.75, 6277600.25) placed on this script's grid."""
    dtm = read_tif(os.path.join(SRC, "rasters", "DTM_test_data_77055_627760_50CM.tif"))
    dtm[dtm < -9000] = np.nan
    g = np.full((N, N), np.nan)
    g[30:30 + dtm.shape[0], 30:30 + dtm.shape[1]] = dtm
    return g


def building_parts(x, y, z, c):
    r, k = cell_of(x[c == 6], y[c == 6])
    zz = z[c == 6]
    ok = (r >= 0) & (r < N) & (k >= 0) & (k < N)
    r, k, zz = r[ok], k[ok], zz[ok]
    mask = np.zeros((N, N), bool)
    mask[r, k] = True
    mask = ndimage.binary_fill_holes(ndimage.binary_closing(mask, iterations=1))
    # median class-6 height per cell (cells filled by the closing: their neighbours' median)
    flat = r * N + k
    order = np.argsort(flat)
    flat, zs = flat[order], zz[order]
    uniq, start = np.unique(flat, return_index=True)
    med = np.full(N * N, np.nan)
    for u, a, b in zip(uniq, start, np.append(start[1:], len(flat))):
        med[u] = np.median(zs[a:b])
    med = med.reshape(N, N)
    for _ in range(3):  # cells the closing added: their neighbours' median
        with np.errstate(all="ignore"):
            fill = ndimage.generic_filter(med, lambda v: np.nan if np.isnan(v).all() else np.nanmedian(v), size=3, mode="nearest")
        med = np.where(np.isnan(med), fill, med)
    med[~mask] = np.nan
    return region_grow(mask, med)


def region_grow(mask, med):
    lab = np.zeros((N, N), int)
    nxt = 0
    for r0, k0 in zip(*np.nonzero(mask)):
        if lab[r0, k0]:
            continue
        nxt += 1
        lab[r0, k0] = nxt
        stack = [(r0, k0)]
        while stack:
            r, k = stack.pop()
            for dr, dk in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                a, b = r + dr, k + dk
                if 0 <= a < N and 0 <= b < N and mask[a, b] and not lab[a, b]:
                    za, zb = med[r, k], med[a, b]
                    if np.isnan(za) or np.isnan(zb) or abs(za - zb) < STEP_M:
                        lab[a, b] = nxt
                        stack.append((a, b))
    return merge_small(split_thin(lab))


def split_thin(lab):
    """Cut each part that fills less than SPLIT_FILL of its minimum-area rectangle (an L of a
    wing and a row of lean-tos) into its body (an opening by a THIN_M square) and the thin
    strips left over, each connected piece a part of its own."""
    out = np.zeros_like(lab)
    nxt = 0
    k = int(round(THIN_M / CELL))
    for part in np.unique(lab[lab > 0]):
        cells = lab == part
        if cells.sum() < 3 or min_area_rectangle(cells)[1] >= SPLIT_FILL:
            nxt += 1
            out[cells] = nxt
            continue
        body = ndimage.binary_opening(cells, structure=np.ones((k, k)))
        for piece in (body, cells & ~body):
            pl, n = ndimage.label(piece)
            for i in range(1, n + 1):
                nxt += 1
                out[pl == i] = nxt
    return out


def merge_small(lab):
    min_cells = MIN_AREA_M2 / CELL**2
    while True:
        ids, counts = np.unique(lab[lab > 0], return_counts=True)
        small = ids[counts < min_cells]
        if len(small) == 0:
            return lab
        s = small[np.argmin(counts[counts < min_cells])]
        ring = ndimage.binary_dilation(lab == s) & (lab != s) & (lab > 0)
        if ring.any():
            nb, nc = np.unique(lab[ring], return_counts=True)
            lab[lab == s] = nb[np.argmax(nc)]
        else:
            lab[lab == s] = 0


def outline(cells):
    """The outer boundary of a set of cells (bool grid) as a closed ring of world points."""
    edges = {}
    rr, kk = np.nonzero(cells)
    inside = set(zip(rr.tolist(), kk.tolist()))
    for r, k in inside:
        # corners as (row, col) lattice points; boundary walked with the inside on the left
        if (r - 1, k) not in inside:
            edges[(r, k + 1)] = (r, k)
        if (r + 1, k) not in inside:
            edges[(r + 1, k)] = (r + 1, k + 1)
        if (r, k - 1) not in inside:
            edges[(r, k)] = (r + 1, k)
        if (r, k + 1) not in inside:
            edges[(r + 1, k + 1)] = (r, k + 1)
    # the longest chain is the outer ring (holes were filled)
    rings, seen = [], set()
    for s in edges:
        if s in seen:
            continue
        ring, p = [], s
        while p not in seen:
            seen.add(p)
            ring.append(p)
            p = edges[p]
        rings.append(ring)
    ring = max(rings, key=len)
    pts = [(X0 + k * CELL, Y1 - r * CELL) for r, k in ring]
    pts = douglas_peucker(pts + [pts[0]], SIMPLIFY_M)
    if signed_area(pts) < 0:
        pts = pts[::-1]
    return pts


def min_area_rectangle(cells):
    """The smallest rectangle around the cells (their corners), and the share of it they fill."""
    from scipy.spatial import ConvexHull
    rr, kk = np.nonzero(cells)
    corners = np.array([(X0 + (k + dk) * CELL, Y1 - (r + dr) * CELL)
                        for r, k in zip(rr, kk) for dr in (0, 1) for dk in (0, 1)])
    hull = corners[ConvexHull(corners).vertices]
    best = None
    for i in range(len(hull)):
        e = hull[(i + 1) % len(hull)] - hull[i]
        u = e / np.hypot(*e)
        v = np.array([-u[1], u[0]])
        a, b = hull @ u, hull @ v
        area = (a.max() - a.min()) * (b.max() - b.min())
        if best is None or area < best[0]:
            best = (area, u, v, a.min(), a.max(), b.min(), b.max())
    area, u, v, a0, a1, b0, b1 = best
    ring = [tuple(float(t) for t in (a * u + b * v)) for a, b in ((a0, b0), (a1, b0), (a1, b1), (a0, b1), (a0, b0))]
    if signed_area(ring) < 0:
        ring = ring[::-1]
    return ring, cells.sum() * CELL**2 / area


def footprint(cells):
    """A part's outline: its minimum-area rectangle when the cells fill at least RECT_FILL of
    it (most parts here: rectangular houses and blocks), else the traced, simplified outline."""
    rect, fill = min_area_rectangle(cells)
    return (rect, "rectangle", fill) if fill >= RECT_FILL else (outline(cells), "traced", fill)


def signed_area(p):
    return 0.5 * sum(p[i][0] * p[i + 1][1] - p[i + 1][0] * p[i][1] for i in range(len(p) - 1))


def douglas_peucker(p, tol):
    def rec(a, b):
        (x0, y0), (x1, y1) = p[a], p[b]
        L = math.hypot(x1 - x0, y1 - y0) or 1e-12
        best, idx = -1.0, None
        for i in range(a + 1, b):
            d = abs((x1 - x0) * (y0 - p[i][1]) - (x0 - p[i][0]) * (y1 - y0)) / L
            if d > best:
                best, idx = d, i
        if idx is not None and best > tol:
            return rec(a, idx)[:-1] + rec(idx, b)
        return [p[a], p[b]]
    # split the closed ring at its farthest point from the start so both halves are open
    far = max(range(len(p)), key=lambda i: math.hypot(p[i][0] - p[0][0], p[i][1] - p[0][1]))
    return rec(0, far)[:-1] + rec(far, len(p) - 1)


def point_in_poly(x, y, poly):
    inside = np.zeros(len(x), bool)
    for (x0, y0), (x1, y1) in zip(poly[:-1], poly[1:]):
        cross = (y0 > y) != (y1 > y)
        xi = x0 + (y - y0) * (x1 - x0) / np.where(y1 == y0, 1e-12, y1 - y0)
        inside ^= cross & (x < xi)
    return inside


def local_normals(px, py, pz, radius=1.0):
    """Unit normal (nz >= 0) of the plane through each point's neighbours within `radius`."""
    from scipy.spatial import cKDTree
    pts = np.c_[px, py, pz]
    tree = cKDTree(pts[:, :2])
    nrm = np.full((len(px), 3), np.nan)
    for i, nb in enumerate(tree.query_ball_point(pts[:, :2], radius)):
        if len(nb) < 6:
            continue
        q = pts[nb] - pts[nb].mean(axis=0)
        w, v = np.linalg.eigh(q.T @ q)
        n = v[:, 0]
        nrm[i] = n if n[2] >= 0 else -n
    return nrm


def fit_plane(px, py, pz):
    """z = a x + b y + c by least squares (coordinates relative to their mean); returns
    (a, b, c, rms, x̄, ȳ)."""
    mx, my = px.mean(), py.mean()
    A = np.c_[px - mx, py - my, np.ones(len(px))]
    sol, *_ = np.linalg.lstsq(A, pz, rcond=None)
    rms = float(np.sqrt(np.mean((A @ sol - pz) ** 2)))
    return sol[0], sol[1], sol[2], rms, mx, my


def roof_planes(px, py, pz):
    """Faces of the roof: points grouped by their local normal's aspect (4 quadrants around
    the dominant axis); returns a list of faces (dict) with pitch, aspect, points' mask."""
    nrm = local_normals(px, py, pz)
    good = ~np.isnan(nrm[:, 0])
    slope = np.degrees(np.arccos(np.clip(nrm[:, 2], -1, 1)))
    # aspect = the way the face looks (downhill), clockwise from north
    aspect = np.degrees(np.arctan2(nrm[:, 0], nrm[:, 1])) % 360
    sloped = good & (slope > FLAT_PITCH_DEG) & (slope < 70)
    if sloped.sum() < 0.4 * good.sum():
        return nrm, []
    # dominant axis: the doubled-angle mean of the sloped points' aspects
    ang = np.radians(aspect[sloped]) * 2
    axis = (math.degrees(math.atan2(np.sin(ang).mean(), np.cos(ang).mean())) / 2) % 180
    faces = []
    for q in range(4):
        centre = (axis + 90 * q) % 360
        d = (aspect - centre + 180) % 360 - 180
        sel = sloped & (np.abs(d) < 45)
        if sel.sum() < 30:
            continue
        a, b, c, rms, mx, my = fit_plane(px[sel], py[sel], pz[sel])
        for _ in range(3):  # drop chimneys, dormers, a neighbour's points: refit on inliers
            res = np.abs(a * (px - mx) + b * (py - my) + c - pz)
            sel = sel & (res < INLIER_M)
            a, b, c, rms, mx, my = fit_plane(px[sel], py[sel], pz[sel])
        pitch = math.degrees(math.atan(math.hypot(a, b)))
        face_aspect = math.degrees(math.atan2(-a, -b)) % 360  # downhill direction
        faces.append({"points": sel, "pitch_deg": pitch, "aspect_deg": face_aspect,
                      "rms_m": rms, "n": int(sel.sum()), "plane": (a, b, c, mx, my)})
    return nrm, faces


def plane_z(f, px, py):
    a, b, c, mx, my = f["plane"]
    return a * (px - mx) + b * (py - my) + c


def roof_truth(px, py, pz):
    """The truth of one part from its class-6 points. roof_z: the 99th percentile of the points
    within INLIER_M of the fitted roof (its planes' lower envelope), so chimneys and antennas
    do not raise it; `roof_z_all_p99`: the same over every point, for comparison."""
    p99_all = float(np.percentile(pz, 99))
    nrm, faces = roof_planes(px, py, pz)
    if not faces:
        a, b, c, rms, mx, my = fit_plane(px, py, pz)
        on = np.abs(a * (px - mx) + b * (py - my) + c - pz) < INLIER_M
        roof_z = float(np.percentile(pz[on], 99))
        return {"roof_z": roof_z, "eave_z": roof_z, "roof_form": "flat",
                "pitch_deg": round(math.degrees(math.atan(math.hypot(a, b))), 1),
                "roof_z_all_p99": p99_all}, []
    big = sorted(faces, key=lambda f: -f["n"])
    main = big[0]
    opposite = [f for f in big[1:] if abs((f["aspect_deg"] - main["aspect_deg"] + 180) % 360 - 180) > 135]
    ends = [f for f in big[1:] if all(f is not o for o in opposite) and f["n"] > 0.1 * main["n"]]
    if not opposite:
        form = "shed"
        az = (main["aspect_deg"] + 180) % 360  # the way it rises
        used = [main]
    else:
        form = "hip" if len(ends) >= 1 else "gable"
        az = (main["aspect_deg"] + 90) % 180
        used = [main, opposite[0]] + ends
    on_faces = np.zeros(len(pz), bool)
    for f in used:
        on_faces |= f["points"]
    model = np.min([plane_z(f, px, py) for f in used], axis=0)
    on_roof = np.abs(model - pz) < INLIER_M
    roof_z = float(np.percentile(pz[on_roof], 99))
    eave_z = float(np.percentile(pz[on_faces], 2))
    pitch = float(np.average([f["pitch_deg"] for f in used[:2]], weights=[f["n"] for f in used[:2]]))
    return {"roof_z": roof_z, "eave_z": eave_z, "roof_form": form,
            "roof_azimuth_deg": round(az, 1), "pitch_deg": round(pitch, 1),
            "roof_z_all_p99": p99_all}, used


def main():
    x, y, z, c = load_points()
    dtm = dtm_grid()
    lab = building_parts(x, y, z, c)
    feats, face_feats = [], []
    tile_cells = np.zeros((N, N), bool)
    tile_cells[30:131, 30:131] = True
    rb, kb = cell_of(x, y)
    for part in np.unique(lab[lab > 0]):
        cells = lab == part
        if (cells & tile_cells).sum() * CELL**2 < 4.0:
            continue
        ring, shape, fill = footprint(cells)
        on = (rb >= 0) & (rb < N) & (kb >= 0) & (kb < N)
        sel = np.zeros(len(x), bool)
        sel[on] = cells[rb[on], kb[on]]
        sel &= c == 6
        # leave out the outermost half cell (walls, eaves' overhang)
        inner = ndimage.binary_erosion(cells)
        sel_in = np.zeros(len(x), bool)
        sel_in[on] = inner[rb[on], kb[on]]
        sel_in &= c == 6
        px, py, pz = x[sel_in], y[sel_in], z[sel_in]
        truth, faces = roof_truth(px, py, pz)
        ground = float(np.nanmax(dtm[cells])) if np.isfinite(dtm[cells]).any() else None
        inside_tile = (cells & tile_cells).sum() / cells.sum()
        props = {"name": f"b{len(feats) + 1}", **{k: (round(v, 2) if isinstance(v, float) else v) for k, v in truth.items()},
                 "ground_z": None if ground is None else round(ground, 2),
                 "area_m2": round(float(cells.sum() * CELL**2), 1),
                 "in_tile": round(float(inside_tile), 2),
                 "outline": shape, "rectangle_fill": round(float(fill), 2),
                 "class6_points": int(sel.sum())}
        feats.append({"type": "Feature", "properties": props,
                      "geometry": {"type": "Polygon", "coordinates": [[[round(a, 2), round(b, 2)] for a, b in ring]]}})
        for f in faces:
            fr, fk = cell_of(px[f["points"]], py[f["points"]])
            fc = np.zeros((N, N), bool)
            fc[fr, fk] = True
            fc = ndimage.binary_opening(ndimage.binary_closing(fc), iterations=1) & cells
            if fc.sum() < 8:
                continue
            lab_f, nf = ndimage.label(fc)
            big = lab_f == (1 + np.argmax(ndimage.sum(fc, lab_f, range(1, nf + 1))))
            fring = outline(big)
            face_feats.append({"type": "Feature", "properties": {
                "building": props["name"], "pitch_deg": round(f["pitch_deg"], 1),
                "aspect_deg": round(f["aspect_deg"], 1), "rms_m": round(f["rms_m"], 3), "points": f["n"]},
                "geometry": {"type": "Polygon", "coordinates": [[[round(a, 2), round(b, 2)] for a, b in fring]]}})
    crs = {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::2154"}}
    for name, fs in (("footprints.geojson", feats), ("faces.geojson", face_feats)):
        with open(os.path.join(HERE, name), "w") as fh:
            json.dump({"type": "FeatureCollection", "crs": crs, "features": fs}, fh, indent=1)
    for f in feats:
        print(json.dumps(f["properties"]))
    for f in face_feats:
        print(json.dumps(f["properties"]))


if __name__ == "__main__":
    main()
