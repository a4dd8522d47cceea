"""Cable sag under gravity, a user effect on the cable's path, in Python
(the C plugin is examples/c/cable_sag.c; docs/effects.md, "User effects").

A cable of weight w per length under tension T, its ends a chord L apart,
hangs in a shallow catenary whose arc the pot counts: longer than the chord
by w_perp^2 L^3 / (24 T^2), w_perp = w sqrt(1 - (u.g)^2) the weight across
the cable (u the cable's direction, g gravity's). So

    extra length = c * L^3 * (1 - (u.g)^2),  c = w^2 / (24 T^2)  in 1/mm^2.

Everything about the geometry comes from the model through the callback
(the chords and directions after anchor_position and holder_geometry at the
values the fit has reached): no frame size, no cable numbering. The one
assumption is the frame's orientation: upright, +z up (GRAVITY below).

    import cable_sag; cable_sag.register()
    cdm.fit("jig.csv", "device.json", ["cable_offset", "cable_sag"], calibration_out="cal.json")
    dev = cdm.open("hid:/dev/hidraw0", calibration="cal.json")   # in the same process

The `cdm` command does not run Python: a calibration with this effect is
used from Python, in a process that registered it first.
"""
from typing import Any

import numpy as np

import cdm

# Gravity's unit vector in the device frame: the frame upright, +z up.
GRAVITY = np.array([0.0, 0.0, -1.0])


def cable_sag(params: "np.ndarray[Any, np.dtype[np.float64]]", geom: cdm.EffectGeometry,
              values: "np.ndarray[Any, np.dtype[np.float64]]") -> None:
    """values (n, 4): the cables' lengths so far (mm); adds each one's sag."""
    (c,) = params
    ug = geom.unit @ GRAVITY  # (n, 4): the cosine between each cable and gravity
    values += c * geom.chord ** 3 * (1.0 - ug * ug)


def register(name: str = "cable_sag") -> None:
    """Registers the effect (again: replaces a registration from this module)."""
    if name in cdm.effect_names():
        cdm.unregister_effect(name)
    # Typical 1e-8 /mm^2 (0.08 mm on a 200 mm horizontal cable); no sag
    # below 0; 1e-6 would be a 1 mm sag on 100 mm, far past shallow.
    cdm.register_effect(name, ["c_per_mm2"], [1e-8], cable_sag, units=["1/mm^2"], lower=[0.0], upper=[1e-6],
                        initial=[0.0], stage="path", geometry=True,
                        doc="Cable sag under gravity: c*L^3*(1 - (u.g)^2) added to each cable's length, "
                            "g along -z (an upright frame), c = w^2/(24 T^2) in 1/mm^2.")
