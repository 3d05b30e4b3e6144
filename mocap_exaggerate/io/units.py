"""BVH units in metres: given by name, or guessed from the skeleton's height (the GLB, the USD and the
previews are in metres). Apart from `io/gltf.py` so that the command can say what it guessed before
the GLB is built, without importing pygltflib (its import is built beside the BVH, on the GLB's thread).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import ConfigError

__all__ = ["UNITS", "PLAUSIBLE_HEIGHT", "unit_scale", "guessed_units_warning"]

#: Metres per unit.
UNITS = {"m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048, "cmu": 0.0254 / 0.45}


def unit_scale(units: str, height: float) -> tuple[float, str]:
    """Metres per BVH unit, and how it was decided.

    ``auto`` takes centimetres for a skeleton over 50 units tall and metres
    under 3; anything between is scaled to a 1.7 m tall figure (CMU's own
    unit is 1/0.45 inch: pass ``cmu``).
    """
    if units != "auto":
        if units not in UNITS:
            raise ConfigError(f"units must be auto or one of {', '.join(UNITS)}, got {units!r}")
        return UNITS[units], units
    if height >= 50:
        return 0.01, "cm (guessed from the skeleton's height)"
    if height <= 3:
        return 1.0, "m (guessed from the skeleton's height)"
    return 1.7 / height, "scaled to a 1.7 m figure (height between 3 and 50 units; give the units to say what they are)"


#: A figure the guessed units make shorter or taller than this (metres) is likely a wrong guess.
PLAUSIBLE_HEIGHT = (1.0, 2.5)


def guessed_units_warning(units: str, height: float) -> str | None:
    """What to tell the user when ``auto`` units make an unlikely figure: a 64-unit clip read as
    centimetres is 0.64 m tall, though it is likely inches. None when the units were given or
    the figure comes out between 1 and 2.5 m."""
    if units != "auto":
        return None
    scale, how = unit_scale(units, height)
    metres = scale * height
    if PLAUSIBLE_HEIGHT[0] <= metres <= PLAUSIBLE_HEIGHT[1]:
        return None
    named = how.split(" ")[0]
    likely = min(UNITS, key=lambda name: abs(np.log(UNITS[name] * height / 1.75)))
    hint = f" (a 1.75 m figure would be --units {likely})" if likely != named else ""
    return (f"GLB units guessed as {named} from the skeleton's height ({height:.4g} units), which makes the figure "
            f"{metres:.2f} m tall; if that is wrong, say what a unit is with --units{hint}")
