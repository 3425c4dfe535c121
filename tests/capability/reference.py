#!/usr/bin/env python3
"""Independent reference for camloop's capability statistics, written with numpy and scipy
only (no code shared with camloop). Reads data sets as JSON on stdin:

    {"datasets": [{"name": ..., "values": [...], "lower": x|null, "upper": x|null,
                   "bounded_at_zero": bool}, ...]}

and prints, per data set, the statistics under the conventions of camloop's manual
("Capability"): sigma within = mean moving range / d2 (d2 = 2/sqrt(pi)); sigma overall with
n - 1; normal model: Cp = (U - L)/6 sw, Cpk = min(U - mean, mean - L)/3 sw, Pp/Ppk with
sigma overall; bounded at zero: folded normal, log-normal and Weibull (location 0) fitted by
maximum likelihood (here scipy's optimisers and log-densities), the largest likelihood
chosen, percentile method Ppu = (U - X50)/(X99.865 - X50), Cpu with the spread scaled by
sw/so; lower 95 % bounds by chi-square (Cp, Pp) and Bissell (the k indices).
"""

import json
import math
import sys

import numpy as np
from scipy import optimize, stats

D2 = 2.0 / math.sqrt(math.pi)
P_HI = 0.99865


def chi_bound(value, n):
    return value * math.sqrt(stats.chi2.ppf(0.05, n - 1) / (n - 1))


def bissell(value, n):
    z = stats.norm.ppf(0.95)
    return value - z * math.sqrt(1.0 / (9 * n) + value * value / (2.0 * (n - 1)))


def fit_foldnorm(x):
    """MLE of the folded normal by Nelder-Mead on (c, scale), c = mu/sigma >= 0."""
    def nll(p):
        c, scale = p
        if c < 0 or scale <= 0:
            return np.inf
        return -np.sum(stats.foldnorm.logpdf(x, c, loc=0, scale=scale))

    c0, _, s0 = stats.foldnorm.fit(x, floc=0)
    best = optimize.minimize(nll, [c0, s0], method="Nelder-Mead",
                             options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 200000,
                                      "maxfev": 400000})
    c, scale = best.x
    return stats.foldnorm(c, loc=0, scale=scale), {"mu": c * scale, "sigma": scale}


def fit_lognorm(x):
    s, _, scale = stats.lognorm.fit(x, floc=0)
    return stats.lognorm(s, loc=0, scale=scale), {"mu": math.log(scale), "sigma": s}


def fit_weibull(x):
    def nll(p):
        k, lam = p
        if k <= 0 or lam <= 0:
            return np.inf
        return -np.sum(stats.weibull_min.logpdf(x, k, loc=0, scale=lam))

    k0, _, l0 = stats.weibull_min.fit(x, floc=0)
    best = optimize.minimize(nll, [k0, l0], method="Nelder-Mead",
                             options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 200000,
                                      "maxfev": 400000})
    k, lam = best.x
    return stats.weibull_min(k, loc=0, scale=lam), {"shape": k, "scale": lam}


def assess(d):
    x = np.asarray(d["values"], dtype=float)
    n = len(x)
    lo, up = d["lower"], d["upper"]
    mean = float(np.mean(x))
    so = float(np.std(x, ddof=1))
    sw = float(np.mean(np.abs(np.diff(x))) / D2)
    out = {"name": d["name"], "n": n, "mean": mean, "sigma_within": sw, "sigma_overall": so}
    if d["bounded_at_zero"]:
        fits = [("folded normal",) + fit_foldnorm(x)]
        if np.all(x > 0):
            fits.append(("log-normal",) + fit_lognorm(x))
            fits.append(("Weibull",) + fit_weibull(x))
        scored = sorted(((float(np.sum(dist.logpdf(x))), name, dist, params)
                         for name, dist, params in fits), key=lambda t: -t[0])
        loglik, name, dist, params = scored[0]
        out.update({"model": name, "log_likelihood": loglik, "params": params,
                    "candidates": {s[1]: s[0] for s in scored}})
        med = float(dist.ppf(0.5))
        hi = float(dist.ppf(P_HI)) - med
        scale_w = sw / so
        if up is not None:
            ppu = (up - med) / hi
            cpu = (up - med) / (hi * scale_w)
            out.update({"cpk": cpu, "cpk_lower_95": bissell(cpu, n), "ppk": ppu,
                        "ppk_lower_95": bissell(ppu, n),
                        "expected_share_out": float(dist.sf(up))})
    else:
        out["model"] = "normal"
        ks = lambda s: min(v for v in [(up - mean) / (3 * s) if up is not None else None,
                                        (mean - lo) / (3 * s) if lo is not None else None]
                           if v is not None)
        if lo is not None or up is not None:
            cpk, ppk = ks(sw), ks(so)
            exp = (stats.norm.cdf(lo, mean, so) if lo is not None else 0.0) + \
                  (stats.norm.sf(up, mean, so) if up is not None else 0.0)
            out.update({"cpk": cpk, "cpk_lower_95": bissell(cpk, n), "ppk": ppk,
                        "ppk_lower_95": bissell(ppk, n), "expected_share_out": float(exp)})
            if lo is not None and up is not None:
                cp, pp = (up - lo) / (6 * sw), (up - lo) / (6 * so)
                out.update({"cp": cp, "cp_lower_95": chi_bound(cp, n), "pp": pp,
                            "pp_lower_95": chi_bound(pp, n)})
    if lo is not None or up is not None:
        bad = np.sum((x < lo) if lo is not None else 0) + np.sum((x > up) if up is not None else 0)
        out["observed_share_out"] = float(bad) / n
    return out


def main():
    data = json.load(sys.stdin)
    json.dump({"scipy": __import__("scipy").__version__,
               "results": [assess(d) for d in data["datasets"]]}, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
