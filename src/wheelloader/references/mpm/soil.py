"""Continuum soil of the MPM plant: what it takes from the project's :class:`SoilParams`.

The project's soil has the eight parameters of the modified FEE. The continuum uses the five that are
material properties (density, internal friction, cohesion, soil-steel friction, adhesion) and adds two
elastic constants; the Bekker parameters ``k_c, k_phi, n`` belong to the force model and are not used.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from wheelloader.estimator import SoilParams, as_soil

#: Default Young's modulus [Pa]. Far softer than real soil (tens of MPa): the time step grows with
#: 1/sqrt(E), and the prototype trial measured < 1 % change of the blade force between 2 and 5 MPa.
DEFAULT_YOUNGS_MODULUS = 2.0e6


def jaky_poisson_ratio(friction_angle: float) -> float:
    """Poisson ratio whose plane-strain at-rest ratio ``nu / (1 - nu)`` equals Jaky's ``K0 = 1 - sin(phi)``.

    With it, soil settled elastically under gravity carries the at-rest lateral stress of a normally
    consolidated soil of that friction angle [rad]. Capped at 0.45 (phi near 0).
    """
    k0 = 1.0 - math.sin(friction_angle)
    return min(k0 / (1.0 + k0), 0.45)


@dataclass(frozen=True)
class ContinuumSoil:
    """Material of the plane-strain MPM continuum (SI units).

    Parameters
    ----------
    density : float
        Bulk density [kg/m^3] (the FEE's gamma).
    friction_angle : float
        Internal friction angle phi [rad], Mohr-Coulomb, in [0, pi/2).
    cohesion : float
        Cohesion c [Pa] >= 0 (tensile strength at the apex: c / tan(phi)).
    wall_friction_angle : float
        Soil-tool friction angle delta [rad] in [0, pi/2).
    adhesion : float
        Soil-tool adhesion c_a [Pa] >= 0: shear stress the soil sustains on the tool with no normal load.
    youngs_modulus : float
        Young's modulus E [Pa] > 0 of the Hencky elasticity.
    poisson_ratio : float
        Poisson ratio nu in (0, 0.5).
    """

    density: float
    friction_angle: float
    cohesion: float = 0.0
    wall_friction_angle: float = 0.0
    adhesion: float = 0.0
    youngs_modulus: float = DEFAULT_YOUNGS_MODULUS
    poisson_ratio: float = 0.3

    def __post_init__(self) -> None:
        for name in ("density", "friction_angle", "cohesion", "wall_friction_angle", "adhesion", "youngs_modulus",
                     "poisson_ratio"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
                raise ValueError(f"ContinuumSoil.{name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.density <= 0.0:
            raise ValueError(f"ContinuumSoil.density must be > 0 kg/m^3, got {self.density!r}")
        if self.youngs_modulus <= 0.0:
            raise ValueError(f"ContinuumSoil.youngs_modulus must be > 0 Pa, got {self.youngs_modulus!r}")
        for name in ("friction_angle", "wall_friction_angle"):
            value = getattr(self, name)
            if not 0.0 <= value < math.pi / 2:
                hint = " (angles are in radians)" if value >= math.pi / 2 else ""
                raise ValueError(f"ContinuumSoil.{name} must be in [0, pi/2) rad, got {value!r}{hint}")
        for name in ("cohesion", "adhesion"):
            if getattr(self, name) < 0.0:
                raise ValueError(f"ContinuumSoil.{name} must be >= 0 Pa, got {getattr(self, name)!r}")
        if not 0.0 < self.poisson_ratio < 0.5:
            raise ValueError(f"ContinuumSoil.poisson_ratio must be in (0, 0.5), got {self.poisson_ratio!r}")
        if self.friction_angle == 0.0 and self.cohesion == 0.0:
            raise ValueError("ContinuumSoil needs friction_angle > 0 or cohesion > 0 (else it has no strength)")

    # ------------------------------------------------------------- derived
    @property
    def shear_modulus(self) -> float:
        """Lame mu [Pa]."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lame_lambda(self) -> float:
        """Lame lambda [Pa]."""
        nu = self.poisson_ratio
        return self.youngs_modulus * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))

    @property
    def p_wave_speed(self) -> float:
        """Plane-strain P-wave speed sqrt((lambda + 2 mu) / rho) [m/s] (sets the time step)."""
        return math.sqrt((self.lame_lambda + 2.0 * self.shear_modulus) / self.density)

    @property
    def at_rest_ratio(self) -> float:
        """Elastic plane-strain at-rest lateral stress ratio nu / (1 - nu) [-]."""
        return self.poisson_ratio / (1.0 - self.poisson_ratio)

    def to_dict(self) -> dict[str, float]:
        """JSON-serialisable mapping (SI units)."""
        return asdict(self)

    @classmethod
    def from_soil(cls, soil: SoilParams | str, *, youngs_modulus: float = DEFAULT_YOUNGS_MODULUS,
                  poisson_ratio: float | None = None) -> ContinuumSoil:
        """Map the project's soil (a :class:`SoilParams` or a preset name) onto the continuum.

        ``gamma`` -> density, ``phi`` -> friction angle, ``cohesion`` -> c, ``delta`` -> wall friction,
        ``adhesion`` -> c_a; ``k_c, k_phi, n`` are not used. ``poisson_ratio`` defaults to
        :func:`jaky_poisson_ratio` of phi (at-rest ratio = 1 - sin phi).
        """
        try:
            params = as_soil(soil)
        except Exception as exc:
            raise ValueError(f"soil: {exc}") from None
        nu = jaky_poisson_ratio(params.phi) if poisson_ratio is None else poisson_ratio
        return cls(density=params.gamma, friction_angle=params.phi, cohesion=params.cohesion,
                   wall_friction_angle=params.delta, adhesion=params.adhesion, youngs_modulus=youngs_modulus,
                   poisson_ratio=nu)
