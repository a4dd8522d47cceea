#!/usr/bin/env python3
"""The worked example's user effect (docs/examples/user_effect.py, the worn
spot) fitted three ways on the same jig data: Python called per position,
Python on arrays (register_effect(vectorized=True)), and the equivalent C
plugin (docs/examples/worn_spot.c). Prints each one's time for cdm.fit and for
the example's cdm.diagnose(effects=["worn_spot"], candidates=False), and
their ratios to the plugin's (docs/performance.md). Exits 1 when the three
do not recover the same parameters (the ctest smoke checks only that).

    PYTHONPATH=bindings/python CDM_LIBRARY=build/src/libcdm.so.1 \\
      python3 tests/bench/bench_user_effect.py --plugin build/tests/unit/calib/worn_spot.so
"""
import argparse
import importlib.util
import json
import math
import os
import statistics
import sys
import tempfile
import time

import numpy as np

import cdm

SRC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
DEVICE = {"a_mm": 150.0, "b_mm": 150.0, "m_mm": 30.0}
NAMES = ["depth_mm", "centre_mm", "width_mm"]


def _example():
    spec = importlib.util.spec_from_file_location("user_effect_example",
                                                  os.path.join(SRC, "docs", "examples", "user_effect.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


EXAMPLE = _example()


def per_position(params, position, readings):
    # The example's effect as it was before vectorized=True: one position a call.
    depth, centre, width = params
    for i in range(4):
        u = (readings[i] - centre) / width
        readings[i] += depth * math.exp(-u * u)


def register(how, plugin):
    if how == "c_plugin":
        cdm.load_plugin(plugin)
        return
    cdm.register_effect("worn_spot", NAMES, [0.1, 10.0, 2.0],
                        per_position if how == "python_per_position" else EXAMPLE.worn_spot,
                        lower=[-5.0, 50.0, 1.0], upper=[5.0, 400.0, 50.0], initial=[0.0, 178.0, 5.0],
                        vectorized=how == "python_vectorized")


def timed(fn, repeat):
    # Wall time and the process's CPU time (all its threads): on a shared
    # machine the CPU time leaves out the waits for a core.
    times, cpus, out = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return (statistics.median(times), statistics.median(cpus)), out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plugin", required=True, help="docs/examples/worn_spot.c built (the ctest target worn_spot)")
    ap.add_argument("--holes", type=int, default=13)
    ap.add_argument("--heights", default="30,40,50,60,70")
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3, help="runs per timing (median); per position: 1")
    args = ap.parse_args()
    heights = tuple(float(h) for h in args.heights.split(","))
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        device = os.path.join(tmp, "device.json")
        with open(device, "w") as f:
            json.dump(DEVICE, f)
        data = os.path.join(tmp, "jig.csv")
        register("python_vectorized", None)
        truth = cdm.Calibration.parse(json.dumps({
            "format": "cdm-calibration", "version": 1, "device": DEVICE,
            "effects": [{"name": "worn_spot", "params": EXAMPLE.TRUTH}]}))
        EXAMPLE.make_dataset(data, truth, np.random.default_rng(11), holes=args.holes, heights=heights,
                             samples=args.samples)
        del truth
        cdm.unregister_effect("worn_spot")
        n_pos = args.holes * args.holes * len(heights)
        print("%d positions (%d holes x %d heights), %d samples each" % (n_pos, args.holes ** 2, len(heights),
                                                                         args.samples))
        rows = {}
        for how in ("python_per_position", "python_vectorized", "c_plugin"):
            register(how, args.plugin)
            rep = 1 if how == "python_per_position" else args.repeat
            try:
                t_fit, r = timed(lambda: cdm.fit(data, device, ["worn_spot"]), rep)
                t_diag, _ = timed(lambda: cdm.diagnose(data, device, effects=["worn_spot"], candidates=False), rep)
            finally:
                cdm.unregister_effect("worn_spot")
            (e,) = [e for e in r["effects"] if e["name"] == "worn_spot"]
            rows[how] = (t_fit, t_diag, e["params"])
        c_fit, c_diag, c_par = rows["c_plugin"]
        print("%-22s %9s %9s %9s %9s %10s %10s %10s %10s" % ("effect", "fit s", "fit cpu", "diag s", "diag cpu",
                                                             "fit / C", "cpu / C", "diag / C", "cpu / C"))
        for how, (t_fit, t_diag, par) in rows.items():
            print("%-22s %9.3f %9.3f %9.3f %9.3f %10.2f %10.2f %10.2f %10.2f"
                  % (how, t_fit[0], t_fit[1], t_diag[0], t_diag[1], t_fit[0] / c_fit[0], t_fit[1] / c_fit[1],
                     t_diag[0] / c_diag[0], t_diag[1] / c_diag[1]))
            for k in NAMES:
                # The same effect, the same data: the same parameters to round-off
                # (math.exp, numpy's exp and libm's differ by an ulp or so).
                if abs(par[k]["value"] - c_par[k]["value"]) > 1e-3 * c_par[k]["std"]:
                    print("%s: %s = %r, the C plugin's %r" % (how, k, par[k], c_par[k]), file=sys.stderr)
                    ok = False
        print("per position / vectorised (fit): %.1f" % (rows["python_per_position"][0][0]
                                                          / rows["python_vectorized"][0][0]))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
