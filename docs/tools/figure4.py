#!/usr/bin/env python3
"""The paper's Figure 4 from `glissade report --variants` JSON files (docs/pgd.md).

(a) η (solid) and the contact-traction error against the monolithic reference (dashed) against
the LATIN iterations, one colour per report; (b) the PGD basis size of the chosen subdomains
(numbered from 1, as the scene files number them) against the iterations, one dash pattern per
subdomain. `glissade report` draws the same figure as `<scene>-iterations.svg`; this script
redraws it from the JSON files with shorter labels.

    python3 docs/tools/figure4.py REPORT.json... --subdomains 7 12 --out FIGURE.svg
"""

import argparse
import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def label(report):
    """A short name of a report's variant: stage (PGD: criterion, ξ₀,₁/ξ₀,₂, new modes) and
    acceleration."""
    stage = report["linear_stage"].replace(", macro modes off", "").replace("ξ₀ = ", "ξ₀ ")
    accel = "Anderson" if report["acceleration"] != "none" else "plain"
    return f"{stage}, {accel}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reports", nargs="+", help="report JSON files")
    ap.add_argument("--subdomains", nargs="+", type=int, default=[7, 12])
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default=None)
    a = ap.parse_args()
    reports = [json.load(open(p)) for p in a.reports]
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(11, 10), gridspec_kw={"height_ratios": [3, 2]})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    dashes = ["-", "--", ":", "-."]
    for k, r in enumerate(reports):
        c = colours[k % len(colours)]
        it = [p["iteration"] for p in r["points"]]
        ax.semilogy(it, [p["eta"] for p in r["points"]], color=c, lw=1.4, label=label(r))
        err = [(p["iteration"], p["traction_error"]) for p in r["points"] if p["traction_error"]]
        ax.semilogy([e[0] for e in err], [e[1] for e in err], color=c, lw=1.2, ls="--")
        n = max((len(p["basis_sizes"]) for p in r["points"]), default=0)
        for j, s in enumerate(x for x in a.subdomains if 1 <= x <= n):
            pts = [(p["iteration"], p["basis_sizes"][s - 1]) for p in r["points"] if len(p["basis_sizes"]) >= s]
            bx.plot([q[0] for q in pts], [q[1] for q in pts], color=c, ls=dashes[j % len(dashes)], lw=1.4,
                    label=f"subdomain {s}: {label(r)}")
    scene = reports[0]["scene"]
    ax.set_title(a.title or f"{scene}: (a) η (solid) and contact-traction error against the reference (dashed)")
    ax.axhline(1e-3, color="grey", lw=0.6)
    ax.set_xlabel("LATIN iteration")
    ax.set_ylabel("η, relative error")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    names = " and ".join(str(s) for s in a.subdomains)
    bx.set_title(f"(b) PGD basis size of subdomains {names} (solid: {a.subdomains[0]}, dashed: {a.subdomains[-1]})")
    bx.set_xlabel("LATIN iteration")
    bx.set_ylabel("modes")
    bx.axhline(60, color="grey", lw=0.6)
    bx.grid(True, alpha=0.3)
    bx.legend(fontsize=7, ncol=2, loc="upper left")
    fig.tight_layout()
    fig.savefig(a.out, metadata={"Date": None})


if __name__ == "__main__":
    main()
