#!/usr/bin/env python3
"""Where a run stops for each accuracy now that it waits for both estimates, and what it writes.

Reads `glissade report` JSON files (each point has the run's L2 estimate `estimate`, its pointwise
estimate `pointwise_estimate`, and the true errors against the reference `traction_error`,
relative space-time L2, and `pointwise_error`, the largest traction difference at one point and
time point relative to the reference's largest traction). For each report and accuracy a in
1e-2, 1e-3, 1e-4 it prints: the stop (the first iteration where both estimates are at most a),
the true L2 and pointwise errors there and pointwise / a; the first iteration whose true
pointwise error is at most a; and where the L2 estimate alone stops, with the pointwise error
written there. Usage: pointwise_stops.py <report.json>...
"""
import json
import sys


def first(points, test):
    return next((p for p in points if test(p)), None)


def main(paths):
    print("| report | a | stop | L2 error there | pointwise error there | pointwise / a | first pointwise ≤ a | L2 estimate alone: stop (pointwise error there) |")
    print("|---|---|---|---|---|---|---|---|")
    worst = 0.0
    stops = 0
    within = 0
    for path in paths:
        points = json.load(open(path))["points"]
        name = path.rsplit("/", 1)[-1].removesuffix("-report.json")
        for a in (1e-2, 1e-3, 1e-4):
            both = first(points, lambda p: p["estimate"] is not None and p.get("pointwise_estimate") is not None
                         and max(p["estimate"], p["pointwise_estimate"]) <= a)
            alone = first(points, lambda p: p["estimate"] is not None and p["estimate"] <= a)
            truth = first(points, lambda p: p["pointwise_error"] is not None and p["pointwise_error"] <= a)
            if both is None:
                print(f"| {name} | {a:.0e} | — (no stop) | | | | {truth and truth['iteration']} | |")
                continue
            ratio = both["pointwise_error"] / a
            stops += 1
            within += ratio <= 1.0
            worst = max(worst, ratio)
            alone_txt = f"{alone['iteration']} ({alone['pointwise_error']:.2e})" if alone else "—"
            print(f"| {name} | {a:.0e} | {both['iteration']} | {both['traction_error']:.2e} | "
                  f"{both['pointwise_error']:.2e} | {ratio:.2f} | {truth and truth['iteration']} | {alone_txt} |")
    print(f"\n{within} of {stops} stops with every traction within the accuracy; the worst at {worst:.2f} a")


if __name__ == "__main__":
    main(sys.argv[1:])
