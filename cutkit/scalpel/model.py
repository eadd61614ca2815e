"""The haptic scalpel: parameters, state, control and the 1 ms step (paper section 6).

Following warp.sim, what never changes during a cut (:class:`ScalpelParams`)
is kept apart from what changes every step (:class:`ScalpelState`) and from
the input (:class:`Control`, the device pose).  :func:`step` checks nothing
in the hot path; the constructors and :func:`enter` normalise their input.

Units: lengths in mm, forces in N, velocities in mm/s, stiffness in N/mm,
mass in kg, eta = E in Pa, time in s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from cutkit.errors import InputError
from cutkit.scalpel import _fracture_kernels as FK
from cutkit.scalpel import _kernels as K

#: The fixed haptic time step, s (1 kHz), independent of the wall clock.
HAPTIC_DT = 1e-3

#: Default cut parameters: the "muscle" row of cutkit.assign.defaults
#: (E = 30 kPa, F_enter = 0.8 N, ...); see docs/scalpel-model.md.
DEFAULT_MATERIAL: dict[str, float] = dict(
    E=30e3, F_enter=0.8, mu_static=2.5e-6, mu_dynamic=1.0e-6, rho_dynamic=5.0e-8,
    alpha_static=0.3, alpha_dynamic=0.15, c_edge=1.0, c_shape=1.0, J_c=2000.0,
)

#: Material columns (cutkit.model.MATERIAL_FIELDS) the scalpel reads, in the
#: order of the haptics protocol's material block.
CUT_FIELDS = ("E", "F_enter", "mu_static", "mu_dynamic", "rho_dynamic",
              "alpha_static", "alpha_dynamic", "c_edge", "c_shape")
#: Material columns only the fracture model reads (not in the haptics
#: protocol's material block: the service keeps the J_c it was started with).
FRACTURE_FIELDS = ("J_c",)
#: Force models :class:`ScalpelParams` can name (``--scalpel``).
SCALPEL_MODELS = K.MODEL_NAMES


@dataclass
class ScalpelParams:
    """Everything that stays constant during one cut.

    Attributes
    ----------
    eta, F_enter, mu_static, mu_dynamic, rho_dynamic, alpha_static,
    alpha_dynamic, c_edge, c_shape : float
        Material at the entry point (eta = E, Pa; units of MATERIAL_FIELDS).
    k_spring : float
        Tip-proxy coupling spring in the blade plane, N/mm.
    k_plane : float
        Stiffness of the force pulling the tip back to the blade plane, N/mm.
    mass : float
        Proxy (blade) mass, kg; sets how fast a cut accelerates (eq. 15).
    blade_depth : float
        d_d of eq. (17), mm: the blade thickness pushing tissue aside.
    blade_taper : float
        d_n = min(blade_taper * d_a, blade_breadth): breadth per mm of depth.
    blade_breadth : float
        Widest breadth of the blade, mm.
    dt : float
        Time step, s.
    J_c : float
        Fracture toughness of the tissue at the entry point, J/m^2 (fracture model).
    crack_step : float
        Crack increment da of the fracture model, mm.
    edge_radius : float
        Radius of the blade's sharp edge, mm: the fracture model's contact
        zone stiffness is c_shape * E * blade_depth * depth / edge_radius.
    model : str
        ``"paper"`` (section 6, eqs. 12-18) or ``"fracture"`` (docs/scalpel-model.md).
    """

    eta: float = DEFAULT_MATERIAL["E"]
    F_enter: float = DEFAULT_MATERIAL["F_enter"]
    mu_static: float = DEFAULT_MATERIAL["mu_static"]
    mu_dynamic: float = DEFAULT_MATERIAL["mu_dynamic"]
    rho_dynamic: float = DEFAULT_MATERIAL["rho_dynamic"]
    alpha_static: float = DEFAULT_MATERIAL["alpha_static"]
    alpha_dynamic: float = DEFAULT_MATERIAL["alpha_dynamic"]
    c_edge: float = DEFAULT_MATERIAL["c_edge"]
    c_shape: float = DEFAULT_MATERIAL["c_shape"]
    k_spring: float = 0.8
    k_plane: float = 0.8
    mass: float = 0.01
    blade_depth: float = 0.4
    blade_taper: float = 0.6
    blade_breadth: float = 8.0
    dt: float = HAPTIC_DT
    J_c: float = DEFAULT_MATERIAL["J_c"]
    crack_step: float = 0.1
    edge_radius: float = 0.01
    model: str = "paper"

    def __post_init__(self):
        if self.model not in SCALPEL_MODELS:
            raise InputError(f"scalpel model {self.model!r} is not one of {', '.join(SCALPEL_MODELS)}")
        for f in fields(self):
            if f.name == "model":
                continue
            v = float(getattr(self, f.name))
            if not math.isfinite(v) or v < 0.0:
                raise InputError(f"scalpel parameter {f.name} = {v!r} must be finite and >= 0")
            setattr(self, f.name, v)
        for name in ("mass", "dt", "k_spring", "crack_step", "edge_radius"):
            if getattr(self, name) <= 0.0:
                raise InputError(f"scalpel parameter {name} must be > 0")
        if self.model == "fracture":
            return  # the fracture model balances its springs exactly: no explicit integrator
        # explicit spring term of the proxy integrator: stable for omega * dt < 2
        omega_dt = math.sqrt(self.k_spring * K.MM_PER_M / self.mass) * self.dt
        if omega_dt >= 1.0:
            raise InputError(
                f"scalpel spring too stiff for its mass: sqrt(k_spring/mass)*dt = {omega_dt:.2f} must be < 1"
            )

    @classmethod
    def from_material(cls, material: dict, **blade) -> "ScalpelParams":
        """Parameters from a material row (keys of :data:`CUT_FIELDS`, E as eta)."""
        missing = [k for k in CUT_FIELDS if k not in material]
        if missing:
            raise InputError(f"material lacks the cut parameters {', '.join(missing)}")
        kw = {("eta" if k == "E" else k): float(material[k]) for k in CUT_FIELDS}
        kw.update({k: float(material[k]) for k in FRACTURE_FIELDS if k in material})
        kw.update(blade)
        return cls(**kw)

    def material(self) -> tuple[float, ...]:
        """The material block in :data:`CUT_FIELDS` order."""
        return tuple(self.eta if k == "E" else getattr(self, k) for k in CUT_FIELDS)

    def array(self) -> np.ndarray:
        """(N_PARAMS,) float64 vector laid out as the kernel's ``P_*`` indices."""
        p = np.zeros(K.N_PARAMS, np.float64)
        p[K.P_DT] = self.dt
        p[K.P_K_SPRING] = self.k_spring
        p[K.P_K_PLANE] = self.k_plane
        p[K.P_MASS] = self.mass
        p[K.P_ETA] = self.eta
        p[K.P_F_ENTER] = self.F_enter
        p[K.P_MU_STATIC] = self.mu_static
        p[K.P_MU_DYNAMIC] = self.mu_dynamic
        p[K.P_RHO_DYNAMIC] = self.rho_dynamic
        p[K.P_ALPHA_STATIC] = self.alpha_static
        p[K.P_ALPHA_DYNAMIC] = self.alpha_dynamic
        p[K.P_C_EDGE] = self.c_edge
        p[K.P_C_SHAPE] = self.c_shape
        p[K.P_BLADE_DEPTH] = self.blade_depth
        p[K.P_BLADE_TAPER] = self.blade_taper
        p[K.P_BLADE_BREADTH] = self.blade_breadth
        p[K.P_MODEL] = SCALPEL_MODELS.index(self.model)
        p[K.P_J_C] = self.J_c
        p[K.P_CRACK_STEP] = self.crack_step
        p[K.P_EDGE_RADIUS] = self.edge_radius
        return p


def blade_breadth(d_a, params: ScalpelParams):
    """Blade breadth d_n at penetration depth d_a (mm): a blade tapering to its tip.

    ``d_n = min(blade_taper * d_a, blade_breadth)``.
    """
    return np.minimum(params.blade_taper * np.asarray(d_a, np.float64), params.blade_breadth)


def _vec3(x, what: str) -> np.ndarray:
    v = np.asarray(x, np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what} must be 3 finite numbers, got {x!r}")
    return v


@dataclass
class ScalpelState:
    """What changes every step.

    Attributes
    ----------
    proxy : (3,) float64
        Proxy position = the scalpel's actual position P_s, mm.
    velocity : (3,) float64
        Proxy velocity, mm/s.
    code : (1,) int64
        FREE, STATIC, CUTTING or WITHDRAWING (``cutkit.scalpel.FREE`` ...).
    entry : (3,) float64
        Entry point P_e, mm.
    normal : (3,) float64
        Unit normal of the blade plane through P_e.
    crack : (1,) float64
        Fracture model: crack length from P_e along a, mm.
    """

    proxy: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    code: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int64))
    entry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    crack: np.ndarray = field(default_factory=lambda: np.zeros(1))

    @property
    def name(self) -> str:
        return K.STATE_NAMES[int(self.code[0])]


@dataclass
class Control:
    """The device pose.

    Attributes
    ----------
    tip : (3,) float64
        Blade tip, mm.
    a : (3,) float64
        Unit direction the sharp edge faces (forward cutting direction).
    n : (3,) float64
        Unit in-plane direction along the blade, perpendicular to ``a``.
    """

    tip: np.ndarray = field(default_factory=lambda: np.zeros(3))
    a: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    n: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))

    def set(self, tip, a, n) -> None:
        """Copy a new pose into the preallocated arrays (no allocation)."""
        self.tip[:] = tip
        self.a[:] = a
        self.n[:] = n


def enter(state: ScalpelState, entry, normal, tip) -> None:
    """Put the blade into tissue at ``entry``: static cut friction from now on.

    Parameters
    ----------
    entry : (3,) float
        Entry point P_e, mm.
    normal : (3,) float
        Normal of the blade plane (need not be unit; must not be zero).
    tip : (3,) float
        Current device tip; the proxy starts at its projection on the plane.
    """
    entry = _vec3(entry, "entry point")
    normal = _vec3(normal, "blade plane normal")
    tip = _vec3(tip, "tip")
    length = float(np.linalg.norm(normal))
    if length < K.AXIS_EPS:
        raise InputError("blade plane normal must not be zero")
    b = normal / length
    state.entry[:] = entry
    state.normal[:] = b
    state.proxy[:] = tip - np.dot(tip - entry, b) * b
    state.velocity[:] = 0.0
    state.crack[0] = 0.0
    state.code[0] = K.STATIC


def leave(state: ScalpelState) -> None:
    """The blade left the tissue: no contact, no cut force."""
    state.code[0] = K.FREE
    state.velocity[:] = 0.0


def step(params: np.ndarray, state: ScalpelState, control: Control, f_sim: np.ndarray, out: np.ndarray) -> None:
    """Advance ``state`` by one step of ``params[P_DT]`` seconds (in place).

    Parameters
    ----------
    params : (N_PARAMS,) float64
        ``ScalpelParams.array()``.
    f_sim : (3,) float64
        External force from the tissue simulation, N.
    out : (N_OUT,) float64
        Receives the device force, the cut force, F_perp, d_a, d_n, the
        blade frame (a, n) and the crack length; see the ``O_*`` indices of
        ``cutkit.scalpel._kernels``.  ``params[P_MODEL]`` picks the paper's
        model or the fracture model.
    """
    blade = K.BladeState(state.proxy, state.velocity, state.code, state.crack, state.entry, state.normal)
    pose = (control.tip, control.a, control.n)
    if params[K.P_MODEL] == K.FRACTURE:
        FK.fracture_step(params, blade, pose, f_sim, out)
        return
    K.scalpel_step(params, blade, pose, f_sim, out)
