"""The peer of cdm's model search that a Python user would write: the same
greedy forward search by BIC over nominal + cable_offset + cable_gain +
exit_pulley, on the same per-position means and whitening (written by
bench_search), each candidate fitted by scipy.optimize.least_squares (its
default trust-region reflective method with bounds, finite-difference
Jacobian) from the current model's parameters.

    python3 search_peer.py MEANS.csv OUT.json

MEANS.csv (from bench_search): per position, the cable vectors
d_i = P + h_i - A_i of the nominal geometry (12 columns, device frame, mm),
the four mean readings and the whitening of the fit (each position's four
readings as one block: ten lower-triangular entries). OUT.json: the seconds the
search took, the effects added in order, the BIC changes and the final
chi-square. The model kernel below is a re-implementation of those three
built-ins (src/model/effects/exit_pulley.h, cable_gain.h, cable_offset.h;
pot axis +x), in the kernel's order: path, then gain, then offset.
"""
import json
import math
import sys
import time

import numpy as np
from scipy.optimize import least_squares

# name: (parameters, lower, upper, start); one radius, or one per cable
EFFECTS = {
    "exit_pulley": (1, 0.0, 40.0, 0.0),
    "cable_gain": (4, -0.2, 0.2, 0.0),
    "cable_offset": (4, -20.0, 20.0, 0.0),
}
ORDER = ["exit_pulley", "cable_gain", "cable_offset"]  # the kernel's order


def predict(D, active, x):
    """Readings (N x 4) of the model with `active` effects at parameters x."""
    o = 0
    prm = {}
    for e in ORDER:
        if e in active:
            n = EFFECTS[e][0]
            prm[e] = x[o:o + n]
            o += n
    if "exit_pulley" in prm:
        r = prm["exit_pulley"][0]
        hs = D[:, :, 0]
        ht = np.hypot(D[:, :, 1], D[:, :, 2])
        dt = ht - r
        D2 = hs * hs + dt * dt
        beta = np.arctan2(dt, hs) + math.pi / 2 - np.arccos(r / np.sqrt(D2))
        length = r * beta + np.sqrt(D2 - r * r)
    else:
        length = np.sqrt((D * D).sum(axis=2))
    if "cable_gain" in prm:
        length = (1 + prm["cable_gain"]) * length
    if "cable_offset" in prm:
        length = length + prm["cable_offset"]
    return length


def main():
    data = np.loadtxt(sys.argv[1], delimiter=",", skiprows=1)
    D = data[:, 0:12].reshape(-1, 4, 3)
    mean = data[:, 12:16]
    # each position's whitening (lower triangular, ten entries row by row)
    L = np.zeros((len(data), 4, 4))
    L[:, [0, 1, 1, 2, 2, 2, 3, 3, 3, 3], [0, 0, 1, 0, 1, 2, 0, 1, 2, 3]] = data[:, 16:26]
    n_obs = mean.size

    def fit(active, x0):
        lo = np.concatenate([[EFFECTS[e][1]] * EFFECTS[e][0] for e in ORDER if e in active] or [[]])
        hi = np.concatenate([[EFFECTS[e][2]] * EFFECTS[e][0] for e in ORDER if e in active] or [[]])

        def res(x):
            return np.einsum("pij,pj->pi", L, mean - predict(D, active, x)).ravel()

        if len(x0) == 0:
            r = res(np.zeros(0))
            return np.zeros(0), float(r @ r)
        sol = least_squares(res, x0, bounds=(lo, hi))
        return sol.x, float(2 * sol.cost)

    def start(active, cur, xcur, new):
        # the current model's fitted values, the new effect at its start
        x, o = [], 0
        for e in ORDER:
            if e not in active:
                continue
            n = EFFECTS[e][0]
            if e == new:
                x += [EFFECTS[e][3]] * n
            else:
                i = [f for f in ORDER if f in cur].index(e)
                off = sum(EFFECTS[f][0] for f in [g for g in ORDER if g in cur][:i])
                x += list(xcur[off:off + n])
            o += n
        return np.array(x)

    t0 = time.perf_counter()
    cur, xcur = [], np.zeros(0)
    _, chi2 = fit(cur, xcur)
    bic = chi2
    path = []
    while True:
        best = None
        for e in ORDER:
            if e in cur:
                continue
            act = [f for f in ORDER if f in cur or f == e]
            x, c2 = fit(act, start(act, cur, xcur, e))
            b = c2 + len(x) * math.log(n_obs)
            if best is None or b < best[0]:
                best = (b, e, act, x, c2)
        if best is None or best[0] >= bic:
            break
        path.append({"added": best[1], "bic_change": best[0] - bic})
        bic, cur, xcur, chi2 = best[0], best[2], best[3], best[4]
    seconds = time.perf_counter() - t0
    with open(sys.argv[2], "w") as f:
        json.dump({"seconds": seconds, "path": path, "effects": cur, "chi2": chi2,
                   "params": list(map(float, xcur))}, f)


if __name__ == "__main__":
    main()
