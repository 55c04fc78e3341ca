"""The tables of the uncertainty page (``docs/validation/uncertainty.md``) on posteriors, read from
``benchmarks/results/posterior_study.json`` and ``posterior_coverage.json``.

Registered with :mod:`results_tables` (loaded first by the docs hook): ``<!-- results: posterior_study -->``,
``<!-- results: posterior_coverage -->``.
"""

from __future__ import annotations

import jaxlimb_results_tables as rt  # the sibling the hook loaded before this one

#: The regions of ``benchmarks/posterior_coverage.py``, in the page's words.
REGIONS = (("center", "the posterior's centre (noise only)"),
           ("center_adjusted", "the adjusted posterior's centre (model error: open-faced sandwich)"),
           ("center_locate", "`locate`'s Gaussian (its covariance)"),
           ("radius", "the posterior's radius (noise only)"),
           ("radius_adjusted", "the adjusted posterior's radius"))


@rt.renderer
def posterior_study(rel: str = "posterior_study.json") -> str:
    d = rt.load(rel)
    rows = []
    for c in d["cases"]:
        cmp_ = c["comparison"]
        r0 = cmp_["r0"]
        rows.append([f"`{c['case']}`", rt.f(c["arc_deg"], 0), ",".join(c["fixed"]) or "none", rt.f(c["sigma"], 0),
                     rt.f(r0["post_std"], 4), rt.f(r0["laplace_std"], 4), rt.f(r0["crlb"], 4),
                     rt.f(r0.get("mc_rms"), 4), rt.f(c["posterior"]["converged"]), rt.f(c["posterior"]["wall_s"], 1)])
    head = ["case", "arc (deg)", "held", "σ (DN)", "posterior σ(r0)", "Laplace σ(r0)", "CRLB(r0)", "MC RMS(r0)",
            "chain converged", "wall (s)"]
    return rt.table(head, rows) + rt.source(rel, d)


@rt.renderer
def posterior_coverage(rel: str = "posterior_coverage.json") -> str:
    d = rt.load(rel)
    cov = d["coverage"]
    rows = [[what, f"{cov[k]['68']:.0%}", f"{cov[k]['95']:.0%}", str(cov[k]["n"])] for k, what in REGIONS]
    head = ["region", "truth inside the 68.3 % region", "inside the 95.4 % region", "renders"]
    fails = rt.failures(d.get("failures"))
    note = (f"\n{d['n_ok']} of {d['n']} renders of `{', '.join(d['families'])}` answered ({fails}); chains converged: "
            f"{d['converged']}; median posterior / `locate` σ of the radius {d['median_post_over_locate_r']:.2f}.\n")
    return rt.table(head, rows) + note + rt.source(rel, d)
