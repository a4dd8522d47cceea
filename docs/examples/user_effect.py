#!/usr/bin/env python3
"""Worked example (docs/calibration.md, "Beyond the catalogue"), all in Python.

A master whose pot tracks are worn where the wiper rests most: every reading
in a narrow band of cable length (around 180 mm) is off by a dip. No
catalogued effect is local in cable length. This script
  1. makes a jig dataset from a true model that has it (libcdm's own model,
     with the effect registered from Python, evaluated by Calibration.lengths),
  2. diagnoses it knowing only the catalogue: the recommended model does not
     explain it, and the length residual shows where,
  3. registers the effect the user now suspects, with initial values for its
     centre and width (both fitted), and diagnoses again: explained.

    PYTHONPATH=bindings/python CDM_LIBRARY=build/src/libcdm.so.1 python3 docs/examples/user_effect.py
"""
import argparse
import json
import os
import sys
import tempfile

import numpy as np

import cdm

TRUTH = {"depth_mm": -0.25, "centre_mm": 180.0, "width_mm": 6.0}


def worn_spot(params, positions, readings):
    # Every position at once (vectorized=True): positions (n, 3), readings
    # (n, 4), changed in place.
    depth, centre, width = params
    u = (readings - centre) / width
    readings += depth * np.exp(-u * u)


def register():
    # The centre and width enter non-linearly: started where the length
    # residual plot shows the dip, and fitted with the depth.
    cdm.register_effect("worn_spot", ["depth_mm", "centre_mm", "width_mm"], [0.1, 10.0, 2.0], worn_spot,
                        doc="a dip worn into the pot tracks around one cable length",
                        lower=[-5.0, 50.0, 1.0], upper=[5.0, 400.0, 50.0], initial=[0.0, 178.0, 5.0],
                        vectorized=True)


def make_dataset(path, truth, rng, holes=13, pitch=10.0, heights=(30, 40, 50, 60, 70), samples=20,
                 noise=0.05, quant=0.01, jig_tol=0.03):
    c = (holes - 1) / 2
    with open(path, "w") as f:
        f.write("point,x_ref,y_ref,z_ref,l1,l2,l3,l4\n")
        point = 0
        for h in heights:
            for iz in range(holes):
                for iy in range(holes):
                    ref = np.array([h, (iy - c) * pitch, (iz - c) * pitch])
                    true = ref + jig_tol * rng.standard_normal(3)  # the hole's own error
                    L = np.array(truth.lengths(true))
                    for _ in range(samples):
                        l = np.round((L + noise * rng.standard_normal(4)) / quant) * quant
                        f.write("%d,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n" % (point, *ref, *l))
                    point += 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 unless the workflow ends as described")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        device = os.path.join(tmp, "device.json")
        with open(device, "w") as f:
            json.dump({"a_mm": 150.0, "b_mm": 150.0, "m_mm": 30.0}, f)
        register()
        truth = cdm.Calibration.parse(json.dumps({
            "format": "cdm-calibration", "version": 1,
            "device": {"a_mm": 150.0, "b_mm": 150.0, "m_mm": 30.0},
            "effects": [{"name": "worn_spot", "params": TRUTH}]}))
        data = os.path.join(tmp, "jig.csv")
        make_dataset(data, truth, np.random.default_rng(11))
        del truth
        cdm.unregister_effect("worn_spot")  # the tool does not know it yet

        r1 = cdm.diagnose(data, device)
        rec = r1["recommended"]
        print("catalogue only: recommended", " + ".join(rec["effects"]) or "nominal",
              "explained =", rec["explained"])
        print("  verdict:", r1["verdict"])
        # Where it fails: the length residual against the length, in 5 mm bins.
        L = np.array(r1["positions"]["lengths_mm"]).ravel()
        R = np.array(r1["positions"]["length_residual_mm"]).ravel()
        bins = np.arange(np.floor(L.min() / 5) * 5, L.max() + 5, 5)
        idx = np.digitize(L, bins)
        means = [(bins[k - 1] + 2.5, R[idx == k].mean()) for k in range(1, len(bins)) if (idx == k).sum() > 20]
        worst = min(means, key=lambda m: m[1])
        print("  length residual dips to %.3f mm around %.0f mm of cable" % (worst[1], worst[0]))

        register()
        # candidates=False: the catalogue was tried above; this checks the fit.
        r2 = cdm.diagnose(data, device, effects=["worn_spot"], candidates=False)
        p = r2["params"]["worn_spot"]
        print("with worn_spot: explained =", r2["explained"], " chi2/dof %.3f" % r2["chi2_per_dof"])
        for k in ("depth_mm", "centre_mm", "width_mm"):
            print("  %s %.4f ± %.4f (true %g)" % (k, p[k]["value"], p[k]["std"], TRUTH[k]))
        print("  x RMS %.4f mm -> %.4f mm (noise floor %.4f)" % (
            r1["error_mm"]["x"]["rms"], r2["error_mm"]["x"]["rms"], r2["noise_floor_mm"]["x"]["rms"]))
        cdm.unregister_effect("worn_spot")
        # Recovered within 5 standard errors (the fit's own uncertainty).
        ok = (not rec["explained"] and r2["explained"] and abs(worst[0] - 180) <= 10
              and all(abs(p[k]["value"] - TRUTH[k]) < 5 * p[k]["std"] for k in TRUTH))
        if args.check and not ok:
            print("the workflow did not end as described", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
