"""Contact stiffness in N/m (N/mm at the user's edge) turned into MuJoCo's solref/solimp.

MuJoCo's soft contacts (direct solref format (-s, -b), constant impedance d: solimp = d d ...)
obey, for one contact at rest, f = -k r / R with k = s / d and the regulariser
R = (1 - d) / d * A_hat, where A_hat is the solver's diagonal approximation of the inverse
effective mass of the contact: the sum of the two bodies' translational ``body_invweight0``
(1/m for a free body, 1/m_v for a flex vertex, 0 for the world). Hence the static stiffness of
one contact is

    K_c = s / ((1 - d) * A_hat)        [N/m]

and to realise K_c we set s = K_c (1 - d) A_hat. The same derivation holds for many contacts
(R is diagonal), so contacts in parallel add up.

Flex contacts: MuJoCo collides a 2-D flex per triangle element, creating one contact per
triangle corner that touches. Its Jacobian weights the corner vertex by w (the solver's
regulariser gives A_hat * m_v = 0.4442 = w^2 with w = 2/3, for every mesh spacing and vertex mass
tried). The contact force reaches the vertex scaled by w and the vertex's motion changes the
penetration scaled by w, so the static stiffness seen by the vertex is K_c = s w^2 / ((1-d) A_hat)
= s / ((1 - d) / m_v): the mapping uses the plain inverse masses, A_eff = 1/m_v + 1/m_other. The
indentation test measures exactly this.

Meaning of the parameters (k_CoPa, k_BePa, k_MePa): the normal stiffness of a whole-face
contact, i.e. the parcel (or its content) lying flat with one face on the counter-surface. That
face makes n_face contacts (`ShellMesh.face_contacts`: the corners of bottom-sheet triangles on
the flat face), so K_c = K / n_face; the same per-contact stiffness applies wherever the
packaging touches that material (stiffness per unit contact area, the physically meaningful
quantity), e.g. at an edge pressed against a guide plate. The virtual indentation test
(`parcelfit.sim.mujoco.indentation`) checks the realised stiffness.

Choosing d: the contact's constraint-space dynamics have angular frequency omega = sqrt(s)
[rad/s], the time scale of an impact. It is a property of the contact, not of the integrator:
omega = min(omega_c, omega_dt / dt) with omega_c = 300 rad/s
(``SceneOptions.contact_frequency``) and omega_dt = 0.5, i.e. 1 - d = omega^2 / (K_c A_hat),
capped to [1e-4, 0.1] (MuJoCo clamps d to at most 0.9999). At 1/600 s both terms are equal (at
the default 1/2400 and 1/1200 s, omega_c rules); a finer step resolves the same contact dynamics
more accurately (so impacts such as a corner catching on a plate converge as the step shrinks),
and a coarser step, which could not resolve omega_c, softens the contact to omega_dt / dt.
(Before, omega was always 0.5 / dt: every halving of the step made impacts twice as fast, and a
catch on a plate could not converge in the step.) Damping: b = 2 zeta omega (zeta = 1:
critically damped). The static stiffness K_c is the same for any omega.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from parcelfit.errors import ParcelfitError

OMEGA_DT = 0.5  # the largest omega * dt used: a coarser step softens the contact to this
CONTACT_FREQUENCY = 300.0  # omega_c [rad/s], the contact's own angular frequency (= 0.5 at 1/600 s)
MIN_ONE_MINUS_D = 1e-4  # MuJoCo's mjMAXIMP = 0.9999
MAX_ONE_MINUS_D = 0.1  # d >= 0.9, MuJoCo's default impedance


@dataclass(frozen=True)
class ContactParams:
    """solref (direct format) and solimp for MJCF, with the impedance chosen and the frequency."""

    stiffness: float  # s [1/s^2]
    damping: float  # b [1/s]
    impedance: float  # d
    omega_dt: float  # sqrt(s) * dt actually realised

    @property
    def solref(self) -> str:
        """MJCF solref attribute value."""
        return f"{-self.stiffness:.9g} {-self.damping:.9g}"

    @property
    def solimp(self) -> str:
        """MJCF solimp attribute value (constant impedance)."""
        return f"{self.impedance:.9g} {self.impedance:.9g} 0.001 0.5 2"


def contact_params(
    stiffness: float,
    n_face: int,
    inverse_mass: float,
    zeta: float,
    timestep: float,
    omega_dt: float = OMEGA_DT,
    frequency: float = CONTACT_FREQUENCY,
) -> ContactParams:
    """solref/solimp realising a whole-face stiffness [N/m] over ``n_face`` contacts.

    ``inverse_mass`` is A_hat [1/kg] of one contact (sum of the two bodies' inverse masses),
    ``zeta`` the contact damping ratio, ``timestep`` [s], ``frequency`` the contact's angular
    frequency [rad/s] (used unless it exceeds ``omega_dt / timestep``).
    """
    if (
        stiffness <= 0
        or n_face < 1
        or inverse_mass <= 0
        or zeta < 0
        or timestep <= 0
        or frequency <= 0
    ):
        raise ParcelfitError(
            f"bad contact inputs: stiffness={stiffness} N/m, n_face={n_face}, inverse_mass={inverse_mass} 1/kg, "
            f"zeta={zeta}, timestep={timestep} s, frequency={frequency} rad/s"
        )
    k_c = stiffness / n_face
    x = k_c * inverse_mass  # = s / (1 - d)
    # the step's own limit wherever it does not exceed omega_c (within rounding: at 1/600 s the
    # two agree, and the old formula keeps runs bit-identical there)
    resolved = frequency * timestep < omega_dt * (1 - 1e-9)
    omega = frequency if resolved else omega_dt / timestep
    one_minus_d = min(MAX_ONE_MINUS_D, max(MIN_ONE_MINUS_D, omega**2 / x))
    s = x * one_minus_d
    return ContactParams(
        stiffness=s,
        damping=2 * zeta * math.sqrt(s),
        impedance=1 - one_minus_d,
        omega_dt=math.sqrt(s) * timestep,
    )


def realised_stiffness(params: ContactParams, n_face: int, inverse_mass: float) -> float:
    """The whole-face static stiffness [N/m] that ``params`` give (inverse of `contact_params`)."""
    return n_face * params.stiffness / ((1 - params.impedance) * inverse_mass)
