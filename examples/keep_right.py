"""A recovery strategy plug-in: keep right.

A vehicle that has another vehicle (or an obstacle) ahead of it within ``radius``
shifts its target to its own right, by ``gain * radius * (1 - dist / radius)`` [m]:
nothing at ``radius``, ``gain * radius`` at contact. Only what lies ahead counts (a
component along the heading > 0), so a vehicle never yields to one behind it, and two
vehicles meeting head-on both turn right and pass each other on the left.

Selected by name from YAML once the file is loaded (``plugins: [keep_right.py]`` in the
scenario, or ``--plugin examples/keep_right.py``)::

    recovery: {strategy: keep_right, radius: 3d, gain: 1.0}

See ``examples/keep_right.yaml``; ``sandbox plugins --plugin examples/keep_right.py``
lists it with its parameters.
"""

from __future__ import annotations

import numpy as np

from sandbox.plugins import Param, StrategyContext, register_strategy


@register_strategy(
    "keep_right",
    params={
        "radius": Param(
            "length",
            "3d",
            unit="m",
            doc="Distance ahead below which a vehicle yields",
            minimum=0.0,
            exclusive=True,
        ),
        "gain": Param(
            "number",
            1.0,
            doc="Shift at contact, as a multiple of radius",
            minimum=0.0,
        ),
    },
)
def keep_right(ctx: StrategyContext) -> tuple[np.ndarray, np.ndarray]:
    """Shift each vehicle's target to its right when something is close ahead.

    Returns the shifts, shape (n, 2) [m], and which vehicles yield, shape (n,).
    """
    radius, gain = ctx.params["radius"], ctx.params["gain"]
    heading = np.stack((np.cos(ctx.theta), np.sin(ctx.theta)), axis=-1)
    closeness = np.zeros(ctx.n)  # 0 (nothing within radius ahead) .. 1 (contact)
    i, j, dist = ctx.pairs(radius)
    rel = ctx.pos[j] - ctx.pos[i]  # from i to j
    weight = 1.0 - dist / radius
    ahead_of_i = np.einsum("mk,mk->m", rel, heading[i]) > 0
    ahead_of_j = np.einsum("mk,mk->m", -rel, heading[j]) > 0
    np.maximum.at(closeness, i[ahead_of_i], weight[ahead_of_i])
    np.maximum.at(closeness, j[ahead_of_j], weight[ahead_of_j])
    v, _, surface, away = ctx.obstacles(radius)
    ahead = np.einsum("mk,mk->m", -away, heading[v]) > 0
    np.maximum.at(closeness, v[ahead], 1.0 - np.maximum(surface[ahead], 0.0) / radius)
    right = np.stack((heading[:, 1], -heading[:, 0]), axis=-1)
    shift = gain * radius * closeness[:, None] * right
    return shift, closeness > 0
