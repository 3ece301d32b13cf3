#!/usr/bin/env python3
"""Per-building table: dbms shadow-height's output against the LiDAR truth (footprints.geojson).

    python3 compare.py HEIGHTS.geojson CELL_M    # prints a Markdown table
"""
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def fmt(v, nd=2):
    return "—" if v is None else (f"{v:.{nd}f}" if isinstance(v, float) else str(v))


def main():
    out = json.load(open(sys.argv[1]))["features"]
    cell = float(sys.argv[2])
    truth = json.load(open(os.path.join(HERE, "footprints.geojson")))["features"]
    print("| part | truth form, pitch, ridge az | truth roof_z / eave_z | dbms roof_z [95 %] | at least | dbms form, eave_z, az | roof error (cells) | flags |")
    print("|---|---|---|---|---|---|---|---|")
    for t, o in zip(truth, out):
        tp, op = t["properties"], o["properties"]
        rz = op.get("roof_z")
        err = None if rz is None else (rz - tp["roof_z"]) / cell
        iv = op.get("roof_z_interval_95")
        form = op.get("roof_form") or "flat"
        print(f"| {tp['name']} ({tp['area_m2']} m², {int(100 * tp['in_tile'])} % in tile) "
              f"| {tp['roof_form']}, {tp['pitch_deg']}°, {fmt(tp.get('roof_azimuth_deg'), 0)}° "
              f"| {tp['roof_z']:.2f} / {tp['eave_z']:.2f} "
              f"| {fmt(rz)} {'' if iv is None else f'[{iv[0]:.2f}, {iv[1]:.2f}]'} "
              f"| {fmt(op.get('roof_z_at_least'))} "
              f"| {form}, {fmt(op.get('eave_z'))}, {fmt(op.get('roof_azimuth_deg'), 0)} "
              f"| {fmt(err, 1)} | {', '.join(op.get('flags', [])) or '—'} |")


if __name__ == "__main__":
    main()
