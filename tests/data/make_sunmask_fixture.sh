#!/bin/sh
# Regenerate tests/data/sunmask/fixture.txt, read by the shadow module's test
# `agrees_with_grass_r_sunmask_fixture`: GRASS GIS `r.sunmask -z` masks of a small DEM.
# Needs grass-core (GRASS 8.2.1 made the committed file) and python3 (standard library only).
# The DEM: 24 x 18 cells of 10 m at (500 000, 5 300 000) (top-left, UTM 14N), heights in metres,
# multiples of 0.25 (exact in f32): rolling hills, a ridge and two towers; cells (5, 4) and
# (17, 11) are nodata. Fixture format: comment lines (#), then "W H cell_x cell_y", H rows of
# heights ("nan" = nodata), then per sun a line "sun ELEVATION AZIMUTH" and H rows of one
# character a cell: 1 shadow, 0 lit, . nodata.
# Usage: sh tests/data/make_sunmask_fixture.sh
set -eu
cd "$(dirname "$0")"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
W=24 H=18 CELL=10
SUNS="10,45 15,135 8,200.5 12,290 20,0 6,333.3 9,90 7,300 11,30"

python3 - "$tmp" $W $H $CELL <<'PY'
import math, sys
out, W, H, cell = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
nodata = {(5, 4), (17, 11)}
def z(c, r):
    v = 120 + 9 * math.sin(c * 0.5) + 7 * math.cos(r * 0.45) + (14 if c == 12 and 3 <= r <= 14 else 0)
    v += 25 if (c, r) in {(8, 8), (19, 5)} else 0
    return round(v * 4) / 4
with open(f"{out}/dem.asc", "w") as f:
    f.write(f"ncols {W}\nnrows {H}\nxllcorner 500000\nyllcorner {5300000 - H * cell}\ncellsize {cell}\nNODATA_value -9999\n")
    for r in range(H):
        f.write(" ".join("-9999" if (c, r) in nodata else repr(z(c, r)) for c in range(W)) + "\n")
PY

for sun in $SUNS; do
    el=${sun%,*} az=${sun#*,}
    grass --tmp-location EPSG:32614 --exec sh -c "
        r.in.gdal --quiet -o input=$tmp/dem.asc output=dem &&
        g.region raster=dem &&
        r.sunmask --quiet -z elevation=dem output=sh altitude=$el azimuth=$az &&
        r.out.ascii --quiet -h input=sh output=$tmp/mask_${el}_${az}.txt null_value=N" >/dev/null 2>&1
done

python3 - "$tmp" $W $H $CELL "$SUNS" > sunmask/fixture.txt <<'PY'
import sys
out, W, H, cell, suns = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5].split()
print("# GRASS GIS r.sunmask -z masks of a small DEM; made by tests/data/make_sunmask_fixture.sh")
print(f"{W} {H} {cell} {cell}")
rows = [l.split() for l in open(f"{out}/dem.asc").read().splitlines()[6:]]
for r in rows:
    print(" ".join("nan" if v == "-9999" else v for v in r))
for sun in suns:
    el, az = sun.split(",")
    print(f"sun {el} {az}")
    mask = [l.split() for l in open(f"{out}/mask_{el}_{az}.txt").read().splitlines()]
    for r, (hr, mr) in enumerate(zip(rows, mask)):
        print("".join("." if h == "-9999" else ("1" if m == "1" else "0") for h, m in zip(hr, mr)))
PY
