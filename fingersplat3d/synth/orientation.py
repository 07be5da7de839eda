"""Ridge orientation fields in the flat fingerprint pattern space.

Coordinates are those of :mod:`fingersplat3d.synth.ridges`: ``a`` (mm) runs along the finger from
the fingertip (``a = 0``) toward the base, ``b`` (mm) runs across it, ``b = 0`` on the centre
line of the pad.

Orientations are angles of the ridge *tangent* measured like the minutiae angles,
``theta = atan2(db, da)``, defined modulo pi: ``theta = pi/2`` is a ridge running across the
finger (along ``b``), ``theta = 0`` one running along it.

The field is the zero-pole model of Sherlock and Monro (1993),

    theta(w) = theta_inf + 1/2 * (sum_cores arg(w - c) - sum_deltas arg(w - d)),  w = a + i b,

so a core turns the orientation by +pi around it and a delta by -pi, plus a smooth "arch" term
whose level curves bulge toward the fingertip around the pad centre (the only term an arch has;
loops and whorls get a milder one, giving the arched ridges above a core), a warp that keeps a
loop's legs parallel (see :func:`orientation_field`), and a small random "wobble" (a few long
plane waves) for the irregular flow of real skin. Far from the singular points the cores and
deltas cancel, so ridges near the tip and near the base run across the finger.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["PATTERN_CLASSES", "OrientationModel", "random_orientation_model", "orientation_field"]

PATTERN_CLASSES = ("arch", "loop", "whorl")

WOBBLE_WAVES = 6  # random plane waves added to the orientation (real ridge flow is irregular)
WOBBLE_WAVELENGTH_MM = (5.0, 12.0)
WOBBLE_RMS_RAD = 0.12


@dataclass(frozen=True, eq=False)
class OrientationModel:
    """Parameters of a zero-pole orientation field with an arch term (all lengths in mm)."""

    pattern_class: str
    cores: np.ndarray  # [C, 2] (a, b)
    deltas: np.ndarray  # [D, 2] (a, b)
    theta_inf: float  # far-field ridge orientation (pi/2: across the finger)
    arch_centre: tuple[float, float]  # (a, b) of the top of the arch bump
    arch_height: float  # how far (mm) the level curves bulge toward the tip at the centre
    arch_sigma: tuple[float, float]  # (along a, along b) widths of the arch bump
    core_straightening: float = 0.0  # 0..1: how parallel a loop's legs are (0: plain zero-pole)
    core_radius: float = 5.0  # mm over which the straightening fades out
    wobble_waves: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # [K, 4] (k_a, k_b, phase, amplitude)


def random_orientation_model(
    rng: np.random.Generator,
    length_mm: float,
    half_width_mm: float,
    pattern_class: str,
    core_a_mm: float | None = None,
) -> OrientationModel:
    """Draw singular-point positions and field parameters for one finger of ``pattern_class``.

    The core (or the centre of a whorl's two cores, or of an arch's bulge) sits at ``core_a_mm``
    (default: ``0.4 * length_mm``, jittered) along the finger and near ``b = 0`` across it. A loop's delta
    lies toward the base on a random side, so the loop opens toward the other side; a whorl has
    one delta on each side.
    """
    if pattern_class not in PATTERN_CLASSES:
        raise ValueError(f"pattern_class must be one of {PATTERN_CLASSES}, got {pattern_class!r}")
    jitter = rng.normal(0.0, 0.02 * length_mm)
    centre_a = 0.4 * length_mm + jitter if core_a_mm is None else float(core_a_mm)
    centre_b = rng.normal(0.0, 0.05 * half_width_mm)
    theta_inf = np.pi / 2 + rng.normal(0.0, 0.05)
    sigma = (rng.uniform(0.2, 0.28) * length_mm, rng.uniform(0.3, 0.4) * half_width_mm)
    cores = np.zeros((0, 2))
    deltas = np.zeros((0, 2))
    if pattern_class == "arch":
        sigma = (sigma[0], rng.uniform(0.22, 0.32) * half_width_mm)
        height = rng.uniform(0.55, 0.9) * sigma[0]
    elif pattern_class == "loop":
        height = rng.uniform(0.1, 0.25) * sigma[0]
        side = rng.choice([-1.0, 1.0])
        distance = rng.uniform(4.5, 7.0)
        angle = np.deg2rad(rng.uniform(30.0, 55.0))  # below the horizontal, toward the base
        cores = np.array([[centre_a, centre_b]])
        deltas = np.array([[centre_a + distance * np.sin(angle), centre_b + side * distance * np.cos(angle)]])
    else:  # whorl
        height = rng.uniform(0.1, 0.25) * sigma[0]
        separation = rng.uniform(0.6, 1.8)
        tilt = rng.normal(0.0, 0.5)  # 0: cores one above the other along a
        offset = 0.5 * separation * np.array([np.cos(tilt), np.sin(tilt)])
        cores = np.array([[centre_a, centre_b]]) + np.stack([-offset, offset])
        deltas = np.array([
            [centre_a + rng.uniform(3.5, 5.5), centre_b - rng.uniform(5.0, 7.5)],
            [centre_a + rng.uniform(3.5, 5.5), centre_b + rng.uniform(5.0, 7.5)],
        ])
    return OrientationModel(
        pattern_class=pattern_class,
        cores=cores,
        deltas=deltas,
        theta_inf=float(theta_inf),
        arch_centre=(float(centre_a), float(centre_b)),
        arch_height=float(height),
        arch_sigma=(float(sigma[0]), float(sigma[1])),
        core_straightening=float(rng.uniform(0.5, 0.8)) if len(cores) else 0.0,
        core_radius=float(rng.uniform(4.0, 6.0)),
        wobble_waves=_random_waves(rng, WOBBLE_WAVES, WOBBLE_WAVELENGTH_MM, WOBBLE_RMS_RAD),
    )


def _random_waves(rng: np.random.Generator, count: int, wavelength: tuple[float, float], rms: float) -> np.ndarray:
    """``count`` plane waves (k_a, k_b in rad/mm, phase, amplitude) summing to ~``rms`` RMS."""
    direction = rng.uniform(0.0, np.pi, count)
    k = 2 * np.pi / rng.uniform(*wavelength, count)
    phase = rng.uniform(0.0, 2 * np.pi, count)
    amplitude = np.full(count, rms * np.sqrt(2.0 / count))
    return np.stack([k * np.cos(direction), k * np.sin(direction), phase, amplitude], axis=1)


def _arch_term(model: OrientationModel, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Orientation change from the arch bump: level curves of ``L = a - bump`` bulge to the tip."""
    ca, cb = model.arch_centre
    sa, sb = model.arch_sigma
    bump = model.arch_height * np.exp(-0.5 * (((a - ca) / sa) ** 2 + ((b - cb) / sb) ** 2))
    grad_a = 1.0 + bump * (a - ca) / sa**2  # stays > 0 while arch_height < 1.6 * sa
    grad_b = bump * (b - cb) / sb**2
    # The ridge tangent is perpendicular to grad L: (da, db) = (-L_b, L_a).
    return np.arctan2(grad_a, -grad_b) - np.pi / 2


def _zero_pole(model: OrientationModel, w: np.ndarray, skip_core: int = -1) -> np.ndarray:
    """Sherlock-Monro sum of the singular points (leaving out core ``skip_core``)."""
    theta = np.zeros(w.shape)
    for index, core in enumerate(model.cores):
        if index != skip_core:
            theta += 0.5 * np.angle(w - complex(core[0], core[1]))
    for delta in model.deltas:
        theta -= 0.5 * np.angle(w - complex(delta[0], delta[1]))
    return theta


def orientation_field(model: OrientationModel, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Ridge orientation ``theta = atan2(db, da)`` in ``[0, pi)`` at points ``(a, b)`` (any shape).

    On top of the zero-pole model, each core's angular term ``arg(w - c)`` is warped to
    ``alpha - k sin(alpha)`` (``alpha`` measured from the direction of the loop's legs, ``k``
    fading out over ``core_radius``): the orientation then stays nearly constant across the legs,
    which run parallel as in real loops instead of fanning out, and turns faster round the apex.
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    w = a + 1j * b
    theta = model.theta_inf + _zero_pole(model, w) + _arch_term(model, a, b)
    for k_a, k_b, phase, amplitude in model.wobble_waves:  # smooth irregularity of real ridge flow
        theta += amplitude * np.sin(k_a * a + k_b * b + phase)
    for index, core in enumerate(model.cores):
        c = complex(core[0], core[1])
        ca, cb = np.array([core[0]]), np.array([core[1]])
        rest = model.theta_inf + _zero_pole(model, np.array([c]), skip_core=index) + _arch_term(model, ca, cb)
        legs = 2.0 * rest[0]  # direction in which the ridges around the core run radially
        radius2 = np.abs(w - c) ** 2
        strength = model.core_straightening * np.exp(-0.5 * radius2 / model.core_radius**2)
        theta -= 0.5 * strength * np.sin(np.angle(w - c) - legs)
    return np.mod(theta, np.pi)
