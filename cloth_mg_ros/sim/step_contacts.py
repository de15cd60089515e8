"""The contacts and cloth-cloth springs an implicit step is built around (sim.integrator):
the rigid contacts predicted for the step with their penalty terms, and the cloth-cloth
pairs with their springs. Units SI."""

from __future__ import annotations

import numpy as np

from cloth_mg_ros.collision.colliders import Contacts, collide
from cloth_mg_ros.collision.self_contact import spring_forces_hessians
from cloth_mg_ros.frozen_arrays import frozen
from cloth_mg_ros.sim.model import ClothModel


def predicted_contacts(model: ClothModel, colliders: list, x: np.ndarray, v: np.ndarray,
                       dt: float) -> Contacts:
    """Contacts where a particle of x (n, 3) m moving at v (n, 3) m/s is predicted to be within
    the thickness of a collider of ``colliders`` (the model's at their end-of-step poses)
    after dt s.

    The penalty is linearised at x_n along that normal: the distance is from x_n to the
    end-of-step surface (tangent plane), so that the solved h v_{n+1} . n lands the particle at
    the thickness of where the surface will be. (The distance to where a moving surface was
    would make a receding limb push, pumping energy.)"""
    contacts = collide(colliders, x + dt * v, model.thickness, x)
    if len(contacts):
        contacts.distance = contacts.distance - dt * np.einsum(
            "ij,ij->i", v[contacts.index], contacts.normal)
    return contacts


def add_penalty_forces(model: ClothModel, v: np.ndarray, contacts: Contacts, k_c: np.ndarray,
                       ga, h_d: float, f: np.ndarray) -> np.ndarray | None:
    """Add the contacts' penalty forces k_c (thickness - distance) n (k_c (c,) N/m), and
    generalised-alpha's dampers along the normals at the velocities v (n, 3) m/s (ga its
    GenAlpha, None for the other schemes; h_d its factor of D in A, s), to f (n, 3) N;
    returns the dampers (c,) N s/m, None without them."""
    if not len(contacts):
        return None
    depth = model.thickness - contacts.distance
    np.add.at(f, contacts.index, (k_c * depth)[:, None] * contacts.normal)
    if ga is None:
        return None
    c_c = ga.contact_damping(model.contact_stiffness) * model.mass[contacts.index] / h_d
    rel = np.einsum("ij,ij->i", v[contacts.index] - contacts.velocity, contacts.normal)
    np.add.at(f, contacts.index, -(c_c * rel)[:, None] * contacts.normal)
    return c_c


def add_penalty_products(y: np.ndarray, contacts: Contacts, k_c: np.ndarray,
                         k_y: np.ndarray) -> None:
    """Add the contacts' part of K y, -k_c (y . n) n, to k_y (n, 3) (y (n, 3): what K
    multiplies in the step's right-hand side; k_c (c,) N/m)."""
    if len(contacts):
        vn = np.einsum("ij,ij->i", y[contacts.index], contacts.normal)
        np.add.at(k_y, contacts.index, -(k_c * vn)[:, None] * contacts.normal)


def add_penalty_blocks(contacts: Contacts, k_c: np.ndarray, c_c: np.ndarray | None,
                       h_k: float, h_d: float, diag: np.ndarray) -> None:
    """Add each contact's h_k k_c n n^T (and h_d c_c n n^T of generalised-alpha's dampers
    c_c (c,) N s/m; None: none) to A's diagonal blocks ``diag`` (n, 3, 3) kg (h_k, h_d: the
    step's factors of K and D in A)."""
    if len(contacts):
        nn = contacts.normal[:, :, None] * contacts.normal[:, None, :]
        blocks = h_k * k_c if c_c is None else h_k * k_c + h_d * c_c
        np.add.at(diag, contacts.index, blocks[:, None, None] * nn)


_NO_PAIRS = frozen(np.zeros((0, 2), np.int64))


def self_contact_pairs(model: ClothModel, x_pred: np.ndarray) -> np.ndarray:
    """The particle pairs (k, 2) predicted to come within the cloth-cloth contact distance
    at the positions x_pred (n, 3) m (none without self contact)."""
    sc = model.self_contact
    return _NO_PAIRS if sc is None else sc.pairs(x_pred)  # read-only, as the mesh's


def self_contact_springs(model: ClothModel, x: np.ndarray, pairs: np.ndarray, h_k: float,
                         forces: np.ndarray) -> np.ndarray:
    """The cloth-cloth springs of `self_contact_pairs`' pairs (k, 2), linearised at x (n, 3):
    their Hessian blocks (k, 3, 3) N/m; their forces are added to ``forces``. Stiffness: the
    self contact's multiple of m / h_k (h_k: the step's factor of -K in A, h'^2, s^2)."""
    hess = np.empty((len(pairs), 3, 3))
    if len(pairs):
        sc = model.self_contact
        k_spring = sc.stiffness * float(model.mass.mean()) / h_k
        spring_forces_hessians(x, pairs, sc.distance, k_spring, forces, hess)
    return hess
