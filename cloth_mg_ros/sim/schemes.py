"""The integration schemes a step may use, and generalised-alpha's constants.

``euler`` (implicit Euler) and ``bdf2`` need no constants beyond the step; generalised-alpha
(Chung and Hulbert, J. Appl. Mech. 60:371, 1993) takes four, which follow from one number,
the spectral radius rho_inf at infinite frequency (`GenAlpha`), and its contacts a damper
(`contact_eta`). sim.integrator builds and finishes the steps.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from cloth_mg_ros.errors import ClothInputError

__all__ = ["DEFAULT_SPECTRAL_RADIUS", "LINEARISE_AT", "SCHEMES", "GenAlpha", "contact_eta"]

SCHEMES = ("euler", "bdf2", "genalpha")
# where a step's first Newton iteration linearises the forces: where the cloth starts (the
# paper's step, Baraff and Witkin's) or where it goes at its velocities (sim.newton's
# predicted_step: implicit Euler and BDF2 only)
LINEARISE_AT = ("start", "prediction")
# genalpha's rho_inf where nothing sets it: 0, the fastest modes (the stretch modes no
# affordable step resolves) gone in a step. Every value up to 0.8 holds in every cell of the
# stability maps, but the larger, the faster the jump's cape (3.8 m/s at 0, 6.0 at 0.5, 8.4
# at 0.8; 1 blows up in 12 of 60 cells: doc/benchmarks/stability.md): 0 keeps landings as
# implicit Euler and BDF2 have them, and a swing still keeps its energy as BDF2's does
# (damping ratio 0.0085 at 1/30 s against implicit Euler's 0.090: doc/benchmarks/dynamics.md)
DEFAULT_SPECTRAL_RADIUS = 0.0


@dataclass(frozen=True)
class GenAlpha:
    """Generalised-alpha's constants for a step of h s at spectral radius rho_inf (Chung and
    Hulbert 1993, eq. 25 and their second-order condition):
    alpha_m = (2 rho - 1) / (rho + 1), alpha_f = rho / (rho + 1),
    gamma = 1/2 - alpha_m + alpha_f, beta = (1 - alpha_m + alpha_f)^2 / 4."""

    h: float
    rho_inf: float
    alpha_m: float
    alpha_f: float
    gamma: float
    beta: float

    @classmethod
    def of(cls, h: float, rho_inf: float) -> GenAlpha:
        if not 0.0 <= rho_inf <= 1.0:
            raise ClothInputError(f"spectral_radius must be in 0..1, got {rho_inf!r}")
        am = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
        af = rho_inf / (rho_inf + 1.0)
        return cls(float(h), float(rho_inf), am, af, 0.5 - am + af, 0.25 * (1.0 - am + af) ** 2)

    @property
    def s(self) -> float:
        """The system's scale, gamma h / (1 - alpha_m), s: b's factor of the forces."""
        return self.gamma * self.h / (1.0 - self.alpha_m)

    @property
    def h_d(self) -> float:
        """A's factor of -D, s."""
        return self.s * (1.0 - self.alpha_f)

    @property
    def h_k(self) -> float:
        """A's factor of -K, s^2."""
        return self.h * self.h * self.beta * (1.0 - self.alpha_f) / (1.0 - self.alpha_m)

    @property
    def c(self) -> float:
        """x_{n+1} = x_n + h v_n + c a_n + h_dv dv: c = h^2 (1/2 - beta / gamma), s^2."""
        return self.h * self.h * (0.5 - self.beta / self.gamma)

    @property
    def h_dv(self) -> float:
        """x_{n+1}'s factor of dv, h beta / gamma, s."""
        return self.h * self.beta / self.gamma

    def contact_damping(self, kappa: float) -> float:
        """The damper a contact penalty k = kappa m / h_k gets, as eta in c = eta m / h_d: the
        one under which the contact's own mode dies fastest in this scheme (`contact_eta`)."""
        return contact_eta(self.rho_inf, kappa)

    @property
    def c_m(self) -> float:
        """b's factor of M a_n, h ((1 - gamma) - gamma alpha_m / (1 - alpha_m)), s."""
        return self.h * ((1.0 - self.gamma) - self.gamma * self.alpha_m / (1.0 - self.alpha_m))


@functools.lru_cache(maxsize=64)
def contact_eta(rho_inf: float, kappa: float) -> float:
    """A contact's damper for generalised-alpha, eta (c = eta m / h_d, dimensionless).

    A penalty contact is a spring far stiffer than the step resolves (k h_k = kappa m). Implicit
    Euler damps it out numerically: a particle pushed out of a limb stops at the surface (its
    mode keeps 0.30 of its amplitude a step at kappa 10). Generalised-alpha keeps about rho_inf
    of it (0.76 at rho_inf 0.5, all at 1): the cloth bounces off the body, and a limb swinging
    into it pumps energy in (the walking dress's kinetic energy peaked at 2.2 J against BDF2's
    0.45 J, doc/benchmarks/dynamics.md). Cloth meets a body inelastically, so the contact gets
    a damper along its normal, the one that minimises the spectral radius of the contact's own
    mode (a particle of mass m on the spring and damper alone) under this rho_inf: 0.17 at
    rho_inf 0.5 (eta 11.75, with the penalty's kappa 10; at eta 10 it is 0.26). Found on a
    grid of eta (a cached one-off: both numbers are the scheme's and the model's
    constants)."""
    ga = GenAlpha.of(1.0, rho_inf)  # h = 1: the mode's amplification does not depend on h

    def radius(eta: float) -> float:
        k, c = kappa / ga.h_k, eta / ga.h_d
        amp = np.empty((3, 3))
        for col, (x, v, a) in enumerate(np.eye(3)):
            dv = (ga.s * (-k * x - c * v) - ga.h_d * k * (v + ga.c * a) + ga.c_m * a) / (
                1.0 + ga.h_d * c + ga.h_k * k)
            amp[:, col] = (x + v + ga.c * a + ga.h_dv * dv, v + dv,
                           (dv - (1.0 - ga.gamma) * a) / ga.gamma)
        return float(np.max(np.abs(np.linalg.eigvals(amp))))

    etas = np.linspace(0.0, 50.0, 201)
    return float(etas[int(np.argmin([radius(e) for e in etas]))])
