#!/usr/bin/env python3
"""Compares the contact forces of two runs' fields.json (docs/outputs.md) of one scene.

Each pair's force f_n n + f_t t (in the frame of its interface, or of the pair on a curved one)
is weighted by its edge length and summed, as a vector, over the copies of one physical node pair
(a pair at a subdomain corner belongs to two interfaces, and only the sum of its copies is
determined); the x and y components are then compared over every time point:

    python3 docs/tools/compare_fields.py a.fields.json b.fields.json

prints the relative L2 difference (relative to the first file) and the largest difference
relative to the largest force of the first file.
"""
import json
import sys
from collections import defaultdict

import numpy as np


def grouped(path):
    data = json.load(open(path))
    forces = defaultdict(lambda: 0.0)
    for itf in data["interfaces"]:
        if itf["kind"] == "perfect":
            continue
        f_n, f_t = np.asarray(itf["f_n"]), np.asarray(itf["f_t"])
        for p, (xy, w) in enumerate(zip(itf["coords"], itf["weights"])):
            n = np.asarray(itf["normals"][p] if "normals" in itf else itf["normal"], dtype=float)
            t = np.array([-n[1], n[0]]) if "normals" in itf else np.asarray(itf["tangent"], dtype=float)
            at = (round(xy[0], 6), round(xy[1], 6))
            for c in (0, 1):
                forces[at + (c,)] = forces[at + (c,)] + (f_n[:, p] * n[c] + f_t[:, p] * t[c]) * w
    return forces


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    a, b = grouped(sys.argv[1]), grouped(sys.argv[2])
    if a.keys() != b.keys():
        sys.exit("the two files do not have the same contact pairs")
    num = sum(((a[k] - b[k]) ** 2).sum() for k in a)
    den = sum((a[k] ** 2).sum() for k in a)
    worst = max(np.abs(a[k] - b[k]).max() for k in a)
    largest = max(np.abs(a[k]).max() for k in a)
    print(f"contact forces, copies summed: relative L2 {(num / den) ** 0.5:.3e}, largest difference {worst / largest:.3e} of the largest force")


if __name__ == "__main__":
    main()
