"""Synthetic `cdm calib diagnose` JSON for the report tests (not real output).

The nominal x residual is a barrel (the estimate falls short of the truth toward
the corners, the same curvature at every height, as in the seed); the current
model leaves white noise; cable 1 carries a small periodic length ripple.
"""
import json
import math

import numpy as np

A, B, M = 300.0, 250.0, 30.0
SY = (1, 1, -1, -1)
SZ = (-1, 1, -1, 1)


def _stats(r):
    out = {}
    for k, a in enumerate("xyz"):
        v = r[:, k]
        out[a] = {"mean": round(float(v.mean()), 4), "std": round(float(v.std()), 4),
                  "rms": round(float(np.sqrt((v * v).mean())), 4),
                  "max": round(float(np.abs(v).max()), 4)}
    return out


def make_diag(n=25, pitch=5.0, heights=(30, 40, 50, 60, 70), seed=1, irregular=False,
              npos=None, effect_model=("cable_gain",)):
    rng = np.random.default_rng(seed)
    if irregular:
        npos = npos or 80
        ys = rng.uniform(-60, 60, npos)
        zs = rng.uniform(-60, 60, npos)
        pts = [(h, y, z) for h in heights for y, z in zip(ys, zs)]
    else:
        c = (np.arange(n) - (n - 1) / 2) * pitch
        pts = [(h, y, z) for h in heights for z in c for y in c]
        if npos is not None:
            pts = pts[:npos]
    ref = np.array(pts, dtype=float)
    P = len(ref)
    y, z, x = ref[:, 1], ref[:, 2], ref[:, 0]
    barrel = -(y ** 2 + z ** 2) / 3600.0 * (1 + 0.002 * (x - 50))
    nominal = np.column_stack([barrel + rng.normal(0, 0.05, P),
                               0.5 + rng.normal(0, 0.3, P), rng.normal(-0.1, 0.3, P)])
    current = rng.normal(0, 0.04, (P, 3))
    ellip = np.column_stack([0.3 * barrel + rng.normal(0, 0.05, P), nominal[:, 1], nominal[:, 2]])
    lengths = np.empty((P, 4))
    angle = np.empty((P, 4))
    for i in range(4):
        d = np.column_stack([x, y + SY[i] * (M / 2 - A), z + SZ[i] * (M / 2 - B)])
        lengths[:, i] = np.linalg.norm(d, axis=1)
        angle[:, i] = np.degrees(np.arcsin(x / lengths[:, i]))
    lres = rng.normal(0, 0.01, (P, 4))
    lres[:, 0] += 0.05 * np.sin(2 * math.pi * lengths[:, 0] / 12.5)
    failing = (np.abs(current[:, 0]) > 0.09).tolist()
    noise = {a: {"mean": 0.0, "std": 0.0123, "rms": 0.0123, "max": 0.0456} for a in "xyz"}
    fp_gain = np.column_stack([barrel * 0.95, 0.01 * y, 0.01 * z])
    fp_anchor = np.column_stack([0.002 * y * z, 0.003 * y, -0.002 * z])
    d = {
        "tool": "cdm calib diagnose", "version": "1.0.0",
        "data": {"path": "synthetic.csv", "rows": P * 100, "positions": P,
                 "heights": [float(h) for h in heights], "ignored_columns": ["t_us"],
                 "out_of_workspace_samples": 3},
        "device": {"a_mm": A, "b_mm": B, "m_mm": M},
        "model": list(effect_model),
        "params": {"cable_gain": {f"g{i}": {"value": 1e-3 * i, "std": 2e-5, "unit": "1"}
                                  for i in range(1, 5)}} if effect_model else {},
        "fit": {"algorithm": "NLOPT_LD_LBFGS", "evaluations": 87, "seconds": 0.42,
                "converged": True, "free_parameters": 4, "message": "xtol reached"},
        "error_mm": _stats(current), "nominal_error_mm": _stats(nominal),
        "ellipsoid_error_mm": _stats(ellip), "noise_floor_mm": noise,
        "ellipsoid": {"L": 5989.1, "M": 2950.2, "N": 3092.8},
        "jig_tolerance_mm": {"value": 0.03, "per_axis": [0.0, 0.03, 0.03],
                             "source": "estimated"},
        "chi2_per_dof": 1.0734, "dof": 3 * P - 4, "chi2_p_value": 0.2468,
        "structure": {"statistic": 0.8123, "p_value": 0.4172, "method": "Moran's I"},
        "explained": True,
        "verdict": "The model <with cable_gain> explains the data to the noise floor & no "
                   "structure remains.",
        "failing_positions": int(sum(failing)),
        "candidates": [
            {"effect": "anchor_position", "score": 12.5, "delta_chi2": 30.25, "bic_change": -12.75,
             "n_params": 12, "error_mm_after": _stats(current * 0.98),
             "confused_with": ["jig_misalignment"], "residual_correlation": 0.31,
             "explained_after": True, "structure_after": 0.5},
            {"effect": "jig_misalignment", "score": 11.0, "delta_chi2": 25.5, "bic_change": -9.5,
             "n_params": 6, "error_mm_after": _stats(current * 0.99),
             "confused_with": ["anchor_position"], "residual_correlation": 0.29,
             "explained_after": False, "structure_after": 2.5},
            {"effect": "pot_nonlinearity", "score": 0.5, "delta_chi2": 2.0, "bic_change": 31.0,
             "n_params": 4, "error_mm_after": _stats(current), "confused_with": [],
             "residual_correlation": 0.02},
        ],
        "inseparable": [{"effects": ["anchor_position", "jig_misalignment"],
                         "separate_by": "more heights (x range) or a tilted jig plate"}],
        "unexplained_structure": {
            "summary": "A periodic ripple in cable 1's length residual remains.",
            "findings": [{"variable": "length_1", "kind": "periodic", "axis": "l1",
                          "period_mm": 12.5, "amplitude_mm": 0.05, "p_value": 1e-6,
                          "text": "cable 1: ripple, period 12.5 mm (drum circumference?)"},
                         {"variable": "height", "kind": "trend", "axis": "x",
                          "period_mm": None, "amplitude_mm": 0.01, "p_value": 0.03,
                          "text": "x residual rises with height"}]},
        "validation": {"method": "leave-one-height-out",
                       "folds": [{"height": float(h), "rms_mm": {"x": 0.0411, "y": 0.0402,
                                                                 "z": 0.0399}} for h in heights],
                       "rms_mm": {"x": 0.0412, "y": 0.0403, "z": 0.0398},
                       "in_sample_rms_mm": {"x": 0.0401, "y": 0.0391, "z": 0.0389}},
        "seconds": 1.25,
        "positions": {
            "point": list(range(P)), "ref": ref.tolist(), "height": x.tolist(),
            "n": [100] * P, "residual_mm": current.tolist(),
            "nominal_residual_mm": nominal.tolist(), "ellipsoid_residual_mm": ellip.tolist(),
            "sigma_mm": np.full((P, 3), 0.04).tolist(), "failing": failing,
            "lengths_mm": lengths.tolist(), "length_residual_mm": lres.tolist(),
            "cable_angle_deg": angle.tolist()},
        "fingerprints": {"anchor_position": fp_anchor.tolist(),
                         "jig_misalignment": (fp_anchor * 0.9).tolist(),
                         "pot_nonlinearity": fp_gain.tolist()},
    }
    return d


def nominal_run(**kw):
    """The same data diagnosed with the nominal model (before adding an effect)."""
    d = make_diag(effect_model=(), **kw)
    d["error_mm"] = d["nominal_error_mm"]
    d["positions"]["residual_mm"] = d["positions"]["nominal_residual_mm"]
    d["explained"] = False
    d["chi2_per_dof"] = 812.5
    d["verdict"] = "A smooth barrel remains in x: the nominal model is incomplete."
    return d


def write(path, d):
    with open(path, "w", encoding="utf-8") as f:
        json.dump(d, f)
    return str(path)
