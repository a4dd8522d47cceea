#!/usr/bin/env python3
"""Worked example (docs/calibration.md, "Beyond the catalogue"), all in Python.

A master whose pot drums are eccentric: each reading carries an error that
repeats every drum circumference of cable. No catalogued effect has that
shape. This script
  1. makes a jig dataset from a true model that has it (libcdm's own model,
     with the effect registered from Python, evaluated by Calibration.lengths),
  2. diagnoses it knowing only the catalogue: unexplained, and the residual's
     periodogram against cable length names the period,
  3. registers the effect the user now suspects and diagnoses again: explained.

    PYTHONPATH=bindings/python CDM_LIBRARY=build/src/libcdm.so.1 python3 docs/examples/user_effect.py
"""
import argparse
import json
import math
import os
import sys
import tempfile

import numpy as np

import cdm

PERIOD_MM = 37.0  # what the periodogram reports; a drum of 11.8 mm diameter


def drum_ripple(params, position, readings):
    for i in range(4):
        ph = 2 * math.pi * readings[i] / PERIOD_MM
        readings[i] += params[0] * math.sin(ph) + params[1] * math.cos(ph)


def register():
    cdm.register_effect("drum_ripple", ["sin_mm", "cos_mm"], [0.05, 0.05], drum_ripple,
                        doc="reading error periodic in cable length (eccentric drum)")


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
            "effects": [{"name": "drum_ripple", "params": {"sin_mm": 0.06, "cos_mm": -0.04}}]}))
        data = os.path.join(tmp, "jig.csv")
        make_dataset(data, truth, np.random.default_rng(11))
        del truth
        cdm.unregister_effect("drum_ripple")  # the tool does not know it yet

        r1 = cdm.diagnose(data, device)
        periodic = [f for f in r1["unexplained_structure"]["findings"] if f["kind"] == "periodic"]
        print("catalogue only: explained =", r1["explained"])
        print("  verdict:", r1["verdict"])
        for f in periodic:
            print("  finding: period %.1f mm, amplitude %.3f mm (p = %.2g)" % (f["period_mm"], f["amplitude_mm"], f["p_value"]))

        register()
        r2 = cdm.diagnose(data, device, effects=["drum_ripple"], candidates=False)
        p = r2["params"]["drum_ripple"]
        print("with drum_ripple: explained =", r2["explained"], " chi2/dof %.3f" % r2["chi2_per_dof"])
        print("  sin %.4f ± %.4f mm, cos %.4f ± %.4f mm (true 0.06, -0.04)" % (
            p["sin_mm"]["value"], p["sin_mm"]["std"], p["cos_mm"]["value"], p["cos_mm"]["std"]))
        print("  x RMS %.4f mm -> %.4f mm (noise floor %.4f)" % (
            r1["error_mm"]["x"]["rms"], r2["error_mm"]["x"]["rms"], r2["noise_floor_mm"]["x"]["rms"]))
        cdm.unregister_effect("drum_ripple")
        ok = (not r1["explained"] and periodic and abs(periodic[0]["period_mm"] - PERIOD_MM) < 0.1 * PERIOD_MM
              and r2["explained"])
        if args.check and not ok:
            print("the workflow did not end as described", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
