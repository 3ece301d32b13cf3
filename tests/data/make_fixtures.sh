#!/bin/sh
# Regenerate the raster fixtures read by tests/io_formats.rs (and described in docs/formats-input.md).
# Needs gdal-bin (GDAL 3.6 made the committed files) and python3 (standard library only).
# Every raster is 20 x 15 cells made from these formulas (c = column, r = row, from the top-left):
#   elevation e(c, r) = 1000 + 37c - 53r            (cells (3,2) and (10,7) are nodata where a file has nodata)
#   int32             = 1000 * e
#   float32           = e / 4                       (exact in f32)
#   float64           = e / 3                       (full f64 precision)
#   colour            R = 10c + 5, G = 15r + 3, B = (7c + 11r) mod 256, alpha 0 where (c + r) mod 5 == 0
# Usage: sh tests/data/make_fixtures.sh   (rewrites the files in tests/data)
set -eu
cd "$(dirname "$0")"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

python3 - "$tmp" <<'PY'
import struct, sys, math
out = sys.argv[1]
W, H = 20, 15
nodata_cells = {(3, 2), (10, 7)}
def e(c, r): return 1000 + 37 * c - 53 * r
def write(name, fmt, gdal_type, values, geotransform=None):
    with open(f"{out}/{name}.bin", "wb") as f:
        f.write(struct.pack("<%d%s" % (len(values), fmt), *values))
    size = struct.calcsize(fmt)
    gt = "" if geotransform is None else "<GeoTransform>%s</GeoTransform>" % ", ".join(repr(v) for v in geotransform)
    with open(f"{out}/{name}.vrt", "w") as f:
        f.write(f'<VRTDataset rasterXSize="{W}" rasterYSize="{H}">{gt}'
                f'<VRTRasterBand dataType="{gdal_type}" band="1" subClass="VRTRawRasterBand">'
                f'<SourceFilename relativeToVRT="1">{name}.bin</SourceFilename>'
                f'<ImageOffset>0</ImageOffset><PixelOffset>{size}</PixelOffset><LineOffset>{size * W}</LineOffset>'
                f'<ByteOrder>LSB</ByteOrder></VRTRasterBand></VRTDataset>\n')
cells = [(c, r) for r in range(H) for c in range(W)]
write("e", "h", "Int16", [e(c, r) for c, r in cells])
write("e_nd", "h", "Int16", [-32768 if (c, r) in nodata_cells else e(c, r) for c, r in cells])
write("e_i32", "i", "Int32", [1000 * e(c, r) for c, r in cells])
write("e_f32", "f", "Float32", [math.nan if (c, r) in nodata_cells else e(c, r) / 4 for c, r in cells])
write("e_f64", "d", "Float64", [e(c, r) / 3 for c, r in cells])
write("red", "B", "Byte", [10 * c + 5 for c, r in cells])
write("green", "B", "Byte", [15 * r + 3 for c, r in cells])
write("blue", "B", "Byte", [(7 * c + 11 * r) % 256 for c, r in cells])
write("alpha", "B", "Byte", [0 if (c + r) % 5 == 0 else 255 for c, r in cells])
# Sparse files (GDAL SPARSE_OK=TRUE): columns 16.. nodata (one whole tile), rows 8.. zero (two strips).
write("e_sparse_nd", "h", "Int16", [-32768 if c >= 16 else e(c, r) for c, r in cells])
write("e_sparse_zero", "h", "Int16", [0 if r >= 8 else e(c, r) for c, r in cells])
# South-up (positive cell height): GDAL writes ModelTransformation. Rotated: a rotation term.
write("south_up", "h", "Int16", [e(c, r) for c, r in cells], (500000.0, 30.0, 0.0, 4999550.0, 0.0, 30.0))
write("rotated", "h", "Int16", [e(c, r) for c, r in cells], (500000.0, 30.0, 5.0, 5000000.0, 0.0, -30.0))
# DTED level 0 needs 121 x 121 posts: d(c, r) = 100 + 3c - 2r.
W = H = 121
write("dted", "h", "Int16", [100 + 3 * c - 2 * r for r in range(H) for c in range(W)])
PY

utm="-a_srs EPSG:32614 -a_ullr 500000 5000000 500600 4999550"
geo="-a_srs EPSG:4326 -a_ullr -97.5 33 -97.48 32.985"
t="gdal_translate -q"
rm -f ./*.tif ./*.tfw ./*.dt0 ./*.vrt ./*.asc ./*.prj ./*.png ./*.pgw ./*.jpg ./*.jgw ./*.aux.xml ./*.txt

$t $utm -a_nodata -32768 -co TILED=NO -co COMPRESS=NONE "$tmp/e_nd.vrt" int16_strip_none_nodata.tif
$t $utm -ot UInt16 -co TILED=YES -co BLOCKXSIZE=16 -co BLOCKYSIZE=16 -co COMPRESS=LZW "$tmp/e.vrt" uint16_tiled_lzw.tif
$t $utm -co COMPRESS=DEFLATE -co PREDICTOR=2 "$tmp/e_i32.vrt" int32_deflate_pred2.tif
$t $utm -a_nodata nan -co TILED=YES -co BLOCKXSIZE=16 -co BLOCKYSIZE=16 -co COMPRESS=DEFLATE -co PREDICTOR=3 "$tmp/e_f32.vrt" float32_tiled_deflate_pred3_nan.tif
$t $utm -co COMPRESS=LZW "$tmp/e_f64.vrt" float64_lzw.tif
$t $utm -a_nodata -32768 -co TILED=YES -co BLOCKXSIZE=16 -co BLOCKYSIZE=16 -co COMPRESS=DEFLATE -co SPARSE_OK=TRUE "$tmp/e_sparse_nd.vrt" sparse_tiled_nodata.tif
$t $utm -co BLOCKYSIZE=4 -co SPARSE_OK=TRUE "$tmp/e_sparse_zero.vrt" sparse_strips_zero.tif
$t $utm -mo AREA_OR_POINT=Point "$tmp/e.vrt" pixel_is_point.tif
$t -a_srs EPSG:32614 "$tmp/south_up.vrt" model_transformation.tif
$t -a_srs EPSG:32614 "$tmp/rotated.vrt" rotated.tif
$t -a_srs EPSG:32614 -gcp 0 0 500000 5000000 -gcp 20 0 500600 5000000 -gcp 0 15 500000 4999550 "$tmp/e.vrt" gcps.tif
$t $geo -a_nodata -32768 "$tmp/e_nd.vrt" geographic_4326.tif
$t -a_srs "+proj=tmerc +lat_0=0 +lon_0=-98.5 +k=0.9996 +x_0=500000 +y_0=0 +datum=WGS84 +units=m +no_defs" \
   -a_ullr 500000 5000000 500600 4999550 "$tmp/e.vrt" user_defined_crs.tif
$t $utm -co BIGTIFF=YES -co COMPRESS=DEFLATE "$tmp/e.vrt" bigtiff.tif
$t "$tmp/e.vrt" no_georef.tif
$t -co TFW=YES -co PROFILE=BASELINE $utm "$tmp/e.vrt" world_file.tif
rm -f world_file.tif.aux.xml

gdalbuildvrt -q -separate "$tmp/rgb.vrt" "$tmp/red.vrt" "$tmp/green.vrt" "$tmp/blue.vrt"
gdalbuildvrt -q -separate "$tmp/rgba.vrt" "$tmp/red.vrt" "$tmp/green.vrt" "$tmp/blue.vrt" "$tmp/alpha.vrt"
$t $utm -co PHOTOMETRIC=RGB "$tmp/rgb.vrt" rgb8.tif
$t $utm -co PHOTOMETRIC=RGB -co ALPHA=YES -co COMPRESS=DEFLATE "$tmp/rgba.vrt" rgba8.tif
$t $utm -co INTERLEAVE=BAND -co PHOTOMETRIC=RGB "$tmp/rgb.vrt" rgb8_planar.tif
$t $utm -b 1 "$tmp/rgb.vrt" grey8.tif
# JPEG-compressed YCbCr (the usual orthophoto TIFF), and GDAL's decoding of it as raw RGB bytes.
$t $utm -co COMPRESS=JPEG -co PHOTOMETRIC=YCBCR "$tmp/rgb.vrt" rgb8_jpeg_ycbcr.tif
$t -of ENVI -co INTERLEAVE=BIP rgb8_jpeg_ycbcr.tif "$tmp/ycbcr_gdal.raw"
cp "$tmp/ycbcr_gdal.raw" rgb8_jpeg_ycbcr.gdal.rgb
$t $utm -ot UInt16 -scale 0 255 0 65535 -co PHOTOMETRIC=RGB "$tmp/rgb.vrt" rgb16.tif

# ASCII grid (GDAL writes the values exactly as integers) with a WKT1 .prj that carries the EPSG code.
$t -of AAIGrid "$tmp/e.vrt" grid.asc -a_ullr 500000 5000000 500600 4999550
gdalsrsinfo -o wkt1 EPSG:32614 | tr -d '\n' | sed 's/  */ /g' > grid.prj
# PNG / JPEG with our own world files (centre of the top-left pixel) and a .prj for the PNG.
$t -of PNG "$tmp/rgba.vrt" ortho.png
printf '30\n0\n0\n-30\n500015\n4999985\n' > ortho.pgw
cp grid.prj ortho.prj
$t -of JPEG -co QUALITY=95 "$tmp/rgb.vrt" ortho.jpg
printf '30\n0\n0\n-30\n500015\n4999985\n' > ortho.jgw
rm -f ./*.aux.xml

# For the gdal feature: a DTED level 0 tile (1 degree, posts at whole 30") and a VRT over a GeoTIFF.
$t -of DTED -a_srs EPSG:4326 -a_ullr -98.004166666666667 33.004166666666667 -96.995833333333333 31.995833333333333 \
   "$tmp/dted.vrt" n32_w098.dt0
gdalbuildvrt -q int16.vrt int16_strip_none_nodata.tif

# Bad inputs: a TIFF cut short inside its image data, a text file, an empty file.
head -c 700 int16_strip_none_nodata.tif > truncated.tif
echo "this is not a raster" > not_a_raster.tif
: > empty.tif
# What GDAL says about the JPEG (lossy: decoders may differ by a level or two) at a few cells.
for cr in "0 0" "7 4" "19 14"; do echo "$cr $(gdallocationinfo -valonly ortho.jpg $cr | tr '\n' ' ')"; done > ortho_jpg_values.txt
