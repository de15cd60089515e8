"""The cape: a curved panel behind the body, hanging from its top edge like a cloth."""

from __future__ import annotations

import math

import numpy as np

from cloth_mg_ros.mesh.garments.design import Design
from cloth_mg_ros.mesh.garments.rows import RowSurface, build_row_garment

_CAPE_HALF_ANGLE = math.radians(70.0)  # the panel spans the back +- this about its middle

def cape_surface(d: Design, pad: float) -> RowSurface:
    """A panel behind the body, theta in pi +- 70 degrees, from the top of the shoulders to
    the knees, hanging like a cloth: per direction, the concave hull of the body's reach as a
    function of depth below the top edge, vertical below its widest point, plus a slight
    flare (5 cm at the hem)."""
    body = d.body
    shoulder = 0.5 * (body['upper_arm_l'][0][2] + body['upper_arm_r'][0][2])
    arm_r = 0.5 * (body['upper_arm_l'][2] + body['upper_arm_r'][2])
    z_top = shoulder + 0.5 * arm_r
    z_bot = 0.5 * (d.bottom_z('upper_leg_l') + d.bottom_z('upper_leg_r'))
    theta = math.pi + np.linspace(-_CAPE_HALF_ANGLE, _CAPE_HALF_ANGLE, 121)
    z = np.linspace(z_top, z_bot, 120)
    reach = d.reach(theta, z, pad, np.ones(len(d.names), bool))
    depth = z_top - z
    rho = np.empty_like(reach)
    for k in range(len(theta)):
        col = reach[:, k]
        top = int(np.argmax(col))
        hull = [0]
        for i in range(1, top + 1):  # upper concave hull of (depth, reach) up to the maximum
            while len(hull) >= 2:
                i0, i1 = hull[-2], hull[-1]
                cross = ((depth[i1] - depth[i0]) * (col[i] - col[i0])
                         - (col[i1] - col[i0]) * (depth[i] - depth[i0]))
                if cross >= 0.0:
                    hull.pop()
                else:
                    break
            hull.append(i)
        rho[:, k] = np.where(np.arange(len(z)) <= top,
                             np.interp(depth, depth[hull], col[hull]), col[top])
    rho = np.maximum(rho, reach) + 0.05 * (depth / depth[-1])[:, None] ** 2
    return RowSurface(d, theta, z, rho, closed=False)


def build_cape(d: Design, pad: float, target: int, depth: int | None
               ) -> tuple[np.ndarray, np.ndarray, int, dict[str, np.ndarray]]:
    """Coarse mesh (rest, faces), depth and pins (top edge to 'upper_torso') of the cape."""
    return build_row_garment('cape', cape_surface(d, pad), 'upper_torso', target, depth)
