"""Physical constants (SI). Earth values follow EGM2008 / WGS-84."""

MU_EARTH: float = 3.986004418e14
"""Earth's gravitational parameter [m^3/s^2]."""
R_EARTH: float = 6378137.0
"""Earth's equatorial radius [m] (the J2 reference radius)."""
J2_EARTH: float = 1.08262668e-3
"""Earth's second zonal harmonic (unnormalised)."""
OMEGA_EARTH: float = 7.2921159e-5
"""Earth's rotation rate [rad/s] (the atmosphere co-rotates with it)."""
