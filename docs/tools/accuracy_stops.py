#!/usr/bin/env python3
"""Where a run would stop for each accuracy, and how the error estimate compares with the truth.

Reads the `<scene>-report.json` files that `glissade report <scene> --accuracy 1e-6
--max-iterations 600` writes (the run followed well past its default stop) and prints, per report
and accuracy a in 1e-2, 1e-3, 1e-4: the first iteration whose estimate is at most a (where a run
asking for a stops), the true contact-traction error there, true / a, estimate / true, and the
first iteration whose true error is at most a; then, over every iteration with a true error below
1e-2 and an estimate, the share within a factor 3 of the true error and the share below it. The
same for the bound alone (the estimate without its calibration, recomputed from the report's
force steps and contact indicators), for comparison.

    python3 docs/tools/accuracy_stops.py recordings/*-report.json
"""
import json
import math
import sys

ACCURACIES = (1e-2, 1e-3, 1e-4)
RATE_WINDOW, STEP_WINDOW = 20, 10


def bound(points, n):
    """The bound alone at iteration n (nodes/mechanics/src/estimate.rs without the calibration):
    the largest force step of the last 10 iterations / (1 − ρ̂), ρ̂ from a log-linear fit of e_c
    over the last 20; None before iteration 20 or without contraction."""
    if n < RATE_WINDOW:
        return None
    largest = max(p["force_step"] for p in points[n - STEP_WINDOW + 1:n + 1])
    if largest == 0:
        return 0.0
    r = [p["contact_indicator"] for p in points[n - RATE_WINDOW + 1:n + 1]]
    if any(v <= 0 or not math.isfinite(v) for v in r):
        return None
    xm = (RATE_WINDOW - 1) / 2
    ym = sum(math.log(v) for v in r) / RATE_WINDOW
    sxy = sum((k - xm) * (math.log(v) - ym) for k, v in enumerate(r))
    sxx = sum((k - xm) ** 2 for k in range(RATE_WINDOW))
    rate = math.exp(sxy / sxx)
    return largest / (1 - rate) if rate < 1 else None


def main(paths):
    print("| report | a | stop iteration | true error at the stop | true / a | estimate / true | first iteration with true error ≤ a | stop with the bound alone (true / a) |")
    print("|---|---|---|---|---|---|---|---|")
    totals = {"estimate": [0, 0, 0.0, 0, 0, 0], "bound alone": [0, 0, 0.0, 0, 0, 0]}
    for path in paths:
        report = json.load(open(path))
        name = path.rsplit("/", 1)[-1].replace("-report.json", "")
        points = report["points"]
        kinds = {
            "estimate": [p["estimate"] for p in points],
            "bound alone": [bound(points, n) for n in range(len(points))],
        }
        for kind, est in kinds.items():
            t = totals[kind]
            for p, e in zip(points, est):
                err = p["traction_error"]
                if err is not None and e is not None and 0 < err < 1e-2:
                    t[3] += 1
                    t[4] += 1 / 3 <= e / err <= 3
                    t[5] += e < err
        for a in ACCURACIES:
            stops = {}
            for kind, est in kinds.items():
                n = next((n for n, e in enumerate(est) if e is not None and e <= a), None)
                if n is None or not points[n]["traction_error"]:
                    continue
                err = points[n]["traction_error"]
                stops[kind] = (n, err)
                t = totals[kind]
                t[0] += 1
                t[1] += err <= a
                t[2] = max(t[2], err / a)
            if "estimate" not in stops:
                continue
            n, err = stops["estimate"]
            first = next((p["iteration"] for p in points if p["traction_error"] is not None and p["traction_error"] <= a), None)
            alone = stops.get("bound alone")
            alone = f"{points[alone[0]]['iteration']} ({alone[1] / a:.2f})" if alone else "—"
            print(f"| {name} | {a:.0e} | {points[n]['iteration']} | {err:.2e} | {err / a:.2f} | "
                  f"{kinds['estimate'][n] / err:.1f} | {first} | {alone} |")
    print()
    for kind, (stops, within_a, worst, below, within3, under) in totals.items():
        print(f"{kind}: {within_a} of {stops} stops within the requested accuracy, the worst at {worst:.2f}× it; "
              f"over {below} iterations below 1e-2 within 3× of the true error in "
              f"{100 * within3 / max(below, 1):.0f} % and below it in {100 * under / max(below, 1):.0f} %")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
