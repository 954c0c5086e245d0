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
indentation test measures exactly this for the full shell, whose vertices are bodies. An
interpolated shell's contact moves node bodies, whose inverse mass MuJoCo's solver takes instead,
and MuJoCo keeps at most 50 contacts of a shell with one geom: `contact_cap.py` measures both and
maps to them (`SceneOptions.contact_mapping = "solver"`; the default "vertex" maps as here).

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

**Two laws** (`SceneOptions.contact_law`). What the derivation above leaves out is how the
contact moves. For one contact of inverse effective mass A on a body of mass m = 1/A, MuJoCo's
soft constraint behaves (measured: an impact on a plate, `tests/test_sim_config.py`) as a spring
of the static stiffness K_c with the frequency omega = sqrt(s), i.e. as a penalty spring K_c on
a body whose inertia along the contact normal is K_c / omega^2 instead of m: the contact adds

    m_added = K_c / omega^2 - m = m d / (1 - d)        [kg, along the normal, per contact]

* ``impedance`` (the law before 2026-12-01): omega fixed (``contact_frequency``, 300 rad/s,
  below), d from it. With the catalogue's stiffnesses the added mass of a whole face is
  K_face / omega^2, several kilograms on a parcel of 80-380 g, and that of an edge on a guide
  plate tens to hundreds of grams: an impact lasts pi / omega = 10 ms whatever the stiffness, and
  k_CoPa, k_MePa and E_Pa change only the static penetration.
* ``penalty`` (default): the penalty law of multibody solvers, f = K_c delta + c_c d(delta)/dt
  per contact, as the published solver's standard contact force (its manual) with linear
  exponents. MuJoCo reaches it with the smallest impedance it accepts, d = 1e-4
  (`MIN_ONE_MINUS_D`'s mirror, mjMINIMP): the added mass is 1e-4 m, and

      s = K_c A (1 - d)       (static stiffness K_c, as above)
      b = c_c A (1 - d)       (damping coefficient c_c [N s/m] of the contact)

  so the impact's frequency is the spring's own, sqrt(K_c A), and a stiffer packaging makes a
  shorter, harder impact. The damping is a property of the parcel on its face, not of one
  vertex: the whole face is a Kelvin-Voigt layer of stiffness K_face and damping
  c_face = 2 zeta sqrt(K_face M) (M the mass that rests on it: the whole parcel on a belt or
  plate, the content on its packaging), shared by the face's contacts, c_c = c_face / n_face.
  MuJoCo integrates the constraint implicitly in velocity, so the spring is stable at any step;
  where omega dt is large the step damps the impact numerically (an undamped drop on a plate at
  omega dt = 0.35 rebounds with 0.61 of its speed, at 0.09 with 0.87), which is why the run's
  outcome is checked at half the step (docs/research/contact-law.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from parcelfit.errors import ParcelfitError

OMEGA_DT = 0.5  # the largest omega * dt used: a coarser step softens the contact to this
CONTACT_FREQUENCY = 300.0  # omega_c [rad/s], the contact's own angular frequency (= 0.5 at 1/600 s)
MIN_ONE_MINUS_D = 1e-4  # MuJoCo's mjMAXIMP = 0.9999
MAX_ONE_MINUS_D = 0.1  # d >= 0.9, MuJoCo's default impedance
PENALTY_IMPEDANCE = 1e-4  # MuJoCo's mjMINIMP: the penalty law's d (no added inertia)


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


def penalty_contact(
    stiffness: float, n_face: int, inverse_mass: float, zeta: float, mass: float, timestep: float
) -> ContactParams:
    """solref/solimp of the penalty law (module docstring): a whole face of stiffness
    ``stiffness`` [N/m] and damping 2 zeta sqrt(stiffness * mass) [N s/m] (``mass`` [kg]: what
    rests on the face) spread over ``n_face`` contacts of inverse effective mass
    ``inverse_mass`` [1/kg]; ``timestep`` [s] only reports omega * dt."""
    if stiffness <= 0 or n_face < 1 or inverse_mass <= 0 or zeta < 0 or mass <= 0 or timestep <= 0:
        raise ParcelfitError(
            f"bad contact inputs: stiffness={stiffness} N/m, n_face={n_face}, "
            f"inverse_mass={inverse_mass} 1/kg, zeta={zeta}, mass={mass} kg, timestep={timestep} s"
        )
    one_minus_d = 1.0 - PENALTY_IMPEDANCE
    k_c = stiffness / n_face
    c_c = 2.0 * zeta * math.sqrt(stiffness * mass) / n_face
    s = k_c * inverse_mass * one_minus_d
    return ContactParams(
        stiffness=s,
        damping=c_c * inverse_mass * one_minus_d,
        impedance=PENALTY_IMPEDANCE,
        omega_dt=math.sqrt(s) * timestep,
    )


def realised_stiffness(params: ContactParams, n_face: int, inverse_mass: float) -> float:
    """The whole-face static stiffness [N/m] that ``params`` give (inverse of `contact_params`)."""
    return n_face * params.stiffness / ((1 - params.impedance) * inverse_mass)
