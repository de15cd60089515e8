"""Tube garments, the skirt and the dress: a flared tube around the torso axis whose top ring
hugs the body, widening towards the hem as far as the arms leave room."""

from __future__ import annotations

import math

import numpy as np

from cloth_mg_ros.errors import ClothInputError
from cloth_mg_ros.mesh.garments.body import ARM_SEGMENTS
from cloth_mg_ros.mesh.garments.design import Design, smax
from cloth_mg_ros.mesh.garments.rows import RowSurface, build_row_garment

# Flare at the hem (m) and how it grows from the top ring (power of the fraction of the
# length). Walking asks for room: a thigh swung forward by 30 degrees moves the knee about
# 0.2 m forward, so an A-line (power ~1) with a generous flare lets the avatar stride without
# the legs stretching the cloth; a narrow bell (power 2) would be stretched by every step.
SKIRT_FLARE, SKIRT_FLARE_POWER = 0.22, 1.0
DRESS_FLARE, DRESS_FLARE_POWER = 0.34, 1.1


def tube_surface(d: Design, name: str, z_top: float, z_bot: float, flare: float,
                  power: float, pad: float) -> RowSurface:
    """A flared tube around the torso axis from z_top down to z_bot: radius per direction
    rho = smax(body reach, top ring + s^power * amplitude), s = 0 at the top, 1 at the hem.
    The top ring hugs the body. The flare amplitude per direction is `flare`, reduced
    (smoothly around the body) where the arms leave less room."""
    theta = np.linspace(0.0, 2.0 * math.pi, 256, endpoint=False)
    z = np.linspace(z_top, z_bot, 96)
    inner = d.mask(ARM_SEGMENTS, invert=True)
    reach = d.reach(theta, z, pad, inner)
    room, who = d.room(theta, z, pad, ~inner)
    s = ((z_top - z) / (z_top - z_bot))[:, None] ** power
    base = reach[0][None, :]
    clash = reach > room
    if clash.any():
        iz, it = np.argwhere(clash)[0]
        raise ClothInputError(
            f"{name}: segment '{d.names[who[iz, it]]}' is too close to the body at height "
            f"{z[iz]:.3f} m for the {name} to clear both by the clearance")
    fracs = np.linspace(0.0, 1.0, 41)
    rho_c = smax(reach[None], base[None] + s[None] * fracs[:, None, None] * flare)
    ok = (rho_c <= room[None]).all(axis=1)   # (41, nt)
    frac = np.where(ok.all(axis=0), 1.0, fracs[np.argmin(ok, axis=0) - 1].clip(0.0))
    if not ok[0].all():
        it = int(np.argmin(ok[0]))
        iz = int(np.argmax(rho_c[0, :, it] > room[:, it]))
        raise ClothInputError(
            f"{name}: segment '{d.names[who[iz, it]]}' leaves no room for the {name} at height "
            f"{z[iz]:.3f} m")
    # Smooth the allowed flare around the body without exceeding it anywhere: a circular
    # minimum over +-32 samples, then a box blur over +-16.
    w = 32
    ext = np.concatenate([frac[-w:], frac, frac[:w]])
    mins = np.lib.stride_tricks.sliding_window_view(ext, 2 * w + 1).min(axis=1)
    ext = np.concatenate([mins[-w // 2:], mins, mins[:w // 2]])
    frac = np.lib.stride_tricks.sliding_window_view(ext, w + 1).mean(axis=1)
    rho = smax(reach, base + s * frac[None, :] * flare)
    return RowSurface(d, theta, z, rho, closed=True)


def dress_top(d: Design, pad: float) -> float:
    """Highest height below the armpits where a ring around the torso clears the arms with
    2 cm to spare over a 4 cm band below it."""
    theta = np.linspace(0.0, 2.0 * math.pi, 128, endpoint=False)
    shoulder = min(d.body['upper_arm_l'][0][2], d.body['upper_arm_r'][0][2])
    z = np.arange(shoulder - 0.04, d.bottom_z('lower_torso'), -0.005)
    inner = d.mask(ARM_SEGMENTS, invert=True)
    spare = (d.room(theta, z, pad, ~inner)[0] - d.reach(theta, z, pad, inner)).min(axis=1)
    fits = spare >= 0.02
    band = 8
    for i in range(len(z) - band):
        if fits[i:i + band + 1].all():
            return float(z[i])
    raise ClothInputError(
        'dress: the upper arms hang too close to the torso: no height between the shoulders '
        'and the waist leaves room for the top of the dress between torso and arms')


def build_tube(name: str, d: Design, pad: float, target: int, depth: int | None
               ) -> tuple[np.ndarray, np.ndarray, int, dict[str, np.ndarray]]:
    """Coarse mesh (rest, faces), depth and pins of the skirt or the dress, its design
    `pad` metres (clearance and margin) off the capsules."""
    body = d.body
    if name == 'skirt':
        z_top = d.top_z('pelvis') + 0.5 * body['pelvis'][2]
        knee = 0.5 * (d.bottom_z('upper_leg_l') + d.bottom_z('upper_leg_r'))
        hip = 0.5 * (d.top_z('upper_leg_l') + d.top_z('upper_leg_r'))
        surface = tube_surface(d, name, z_top, knee + 0.25 * (hip - knee), SKIRT_FLARE,
                               SKIRT_FLARE_POWER, pad)
        return build_row_garment(name, surface, 'pelvis', target, depth)
    z_top = dress_top(d, pad)
    calf = 0.25 * sum(body[f'lower_leg_{s}'][k][2] for s in 'lr' for k in (0, 1))
    surface = tube_surface(d, name, z_top, calf, DRESS_FLARE, DRESS_FLARE_POWER, pad)
    return build_row_garment(name, surface, 'upper_torso', target, depth)
