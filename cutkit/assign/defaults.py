"""Default tissue materials for ``cutkit assign`` (one row per tissue name).

Units as in :data:`cutkit.model.MATERIAL_FIELDS`.  Sources of the mechanical
figures (order-of-magnitude values for soft tissue at small strain; real
tissue varies by a factor of several between studies, sites and subjects):

* E, skin 0.15 MPa: within the 0.1-0.9 MPa range of in-vivo measurements
  (Agache et al. 1980, Arch. Dermatol. Res. 269:221; Pailler-Mattei et al.
  2008, Med. Eng. Phys. 30:599).
* E, fat 3 kPa: Samani, Zubovits & Plewes 2007, Phys. Med. Biol. 52:1565
  (normal fat, 3.25 kPa).
* E, muscle 30 kPa: passive skeletal muscle along the fibres, shear modulus
  about 10 kPa from shear-wave elastography (Gennisson et al. 2010,
  Ultrasound Med. Biol. 36:789) times 3 for an incompressible solid.
* E, tendon 1.2 GPa: human tendon in vivo (Maganaris & Paul 1999,
  J. Physiol. 521:307).
* E, bone 17 GPa: cortical bone (Reilly & Burstein 1975, J. Biomech. 8:393).
  Bone is normally held rigid by a boundary condition instead.
* Poisson ratio: soft tissue is nearly incompressible (0.45-0.5; e.g.
  skin and muscle 0.45-0.49 in Fung 1993, *Biomechanics*, and the
  elastography literature, which assumes 0.499).  0.45 is used for every
  soft tissue: closer to 0.5, linear tetrahedra lock (a known limit of P1
  elements) and the solver converges more slowly; 0.3 for cortical bone
  (Reilly & Burstein 1975).
* density: IT'IS Foundation tissue property database v4 (Hasgall et al.
  2018): skin 1109, fat 911, muscle 1090, tendon 1142, cortical bone
  1908 kg/m^3.
* J_c, fracture toughness of the fracture scalpel model
  (docs/scalpel-model.md), J/m^2 = N/m = 1e-3 N per mm of cut depth; the
  ranges are those collected in the review of soft-tissue cutting in the
  Chinese Journal of Mechanical Engineering (2022),
  doi 10.1186/s10033-022-00767-4:
  skin 1,136 (porcine skin, measured with a sharp tool: needle insertion;
  the same review lists 17,100-30,400 from trouser-tear and notched tests,
  which measure tearing: the tearing arms' own deformation is paid too,
  and at 20,000 the demo incision's blade would pull 90-160 N through
  8 mm of skin and drag the knee along, docs/scalpel-model.md); fat 4,100
  (about 4,100, trouser tear: no sharp-tool figure in these sources);
  muscle 2,000 (550-8,000; the value within the range used for every soft
  tissue a recipe does not describe).  Liver, for comparison: porcine
  187-225 cut with a blade, bovine 164 +- 6 (Chanthasopeephan et al. 2003).
  Tendon 20,000 and bone 50,000 have no published cutting toughness in
  these sources: they are set at skin's tear toughness and above, so that
  the blade does not cut through them easily (bone is normally held rigid
  anyway).
* damping: no published value for this model; 8/s is a numerical choice
  (the mass-proportional damping of eq. (1)).

The damping and the cut parameters of section 6 (F_enter, mu, rho, alpha,
c_edge, c_shape) have no published values for this model; the paper gives
none.  They are chosen so that a sharp scalpel (c_edge = 1) needs about
1-2 N to enter skin and well under 1 N to go on cutting fat and muscle,
the range reported for scalpel and needle insertion into soft tissue
(e.g. Okamura, Simone & O'Leary 2004, IEEE TBME 51:1707, 0.5-2 N).  With
eta = E and the blade depth d in mm, F_open = mu * E * c_edge * d (eq. 13),
so mu is about F / (E * d).

Every default has its source in :data:`DEFAULT_SOURCES` (one line per
tissue and column); ``cutkit assign`` recipes may set any column,
``J_c`` included.
"""

from __future__ import annotations

from cutkit.model.tetmodel import MATERIAL_FIELDS

#: Default material of each tissue name (without label).
DEFAULT_MATERIALS: dict[str, dict[str, float]] = {
    "skin": dict(poisson_ratio=0.45, E=150e3, density=1109.0, damping=8.0, F_enter=1.5, mu_static=1.0e-6, mu_dynamic=4.0e-7,
                 rho_dynamic=2.0e-8, alpha_static=0.3, alpha_dynamic=0.15, c_edge=1.0, c_shape=1.0, J_c=1136.0),
    "fat": dict(poisson_ratio=0.45, E=3e3, density=911.0, damping=8.0, F_enter=0.3, mu_static=1.0e-5, mu_dynamic=4.0e-6,
                rho_dynamic=2.0e-7, alpha_static=0.2, alpha_dynamic=0.1, c_edge=1.0, c_shape=1.0, J_c=4100.0),
    "muscle": dict(poisson_ratio=0.45, E=30e3, density=1090.0, damping=8.0, F_enter=0.8, mu_static=2.5e-6, mu_dynamic=1.0e-6,
                   rho_dynamic=5.0e-8, alpha_static=0.3, alpha_dynamic=0.15, c_edge=1.0, c_shape=1.0, J_c=2000.0),
    "tendon": dict(poisson_ratio=0.45, E=1.2e9, density=1142.0, damping=8.0, F_enter=3.0, mu_static=2.0e-10, mu_dynamic=8.0e-11,
                   rho_dynamic=4.0e-12, alpha_static=0.3, alpha_dynamic=0.15, c_edge=1.0, c_shape=1.0, J_c=20000.0),
    "bone": dict(poisson_ratio=0.3, E=17e9, density=1908.0, damping=8.0, F_enter=50.0, mu_static=3.0e-10, mu_dynamic=3.0e-10,
                 rho_dynamic=1.0e-12, alpha_static=0.5, alpha_dynamic=0.5, c_edge=1.0, c_shape=1.0, J_c=50000.0),
}

_CUT = "section 6 cut parameter; no published value: chosen for 0.5-2 N scalpel forces (Okamura et al. 2004)"
_REVIEW = "review of soft-tissue cutting, Chin. J. Mech. Eng. (2022), doi 10.1186/s10033-022-00767-4"
_NU = "nearly incompressible soft tissue 0.45-0.5 (Fung 1993); 0.45 keeps P1 tetrahedra from locking worst"
_DENSITY = "IT'IS tissue property database v4 (Hasgall et al. 2018)"
_DAMPING = "no published value for this model: a numerical choice"

#: Source of every default: ``DEFAULT_SOURCES[tissue][column]``.
DEFAULT_SOURCES: dict[str, dict[str, str]] = {
    name: {
        **{k: _CUT for k in ("F_enter", "mu_static", "mu_dynamic", "rho_dynamic", "alpha_static",
                             "alpha_dynamic", "c_edge", "c_shape")},
        "poisson_ratio": _NU if name != "bone" else "cortical bone (Reilly & Burstein 1975, J. Biomech. 8:393)",
        "density": _DENSITY,
        "damping": _DAMPING,
        "E": e_source,
        "J_c": j_source,
    }
    for name, e_source, j_source in (
        ("skin", "0.1-0.9 MPa in vivo (Agache et al. 1980; Pailler-Mattei et al. 2008)",
         f"porcine skin 1,136 J/m^2 by needle insertion (sharp tool; tear tests 17,100-30,400), {_REVIEW}"),
        ("fat", "normal fat 3.25 kPa (Samani, Zubovits & Plewes 2007, Phys. Med. Biol. 52:1565)",
         f"fat about 4,100 J/m^2, {_REVIEW}"),
        ("muscle", "shear modulus about 10 kPa, shear-wave elastography (Gennisson et al. 2010), times 3",
         f"muscle 550-8,000 J/m^2, {_REVIEW}"),
        ("tendon", "human tendon in vivo (Maganaris & Paul 1999, J. Physiol. 521:307)",
         "no published cutting toughness: set to skin's tear toughness (20,000 J/m^2)"),
        ("bone", "cortical bone (Reilly & Burstein 1975, J. Biomech. 8:393)",
         "no published cutting toughness: set above skin's tear toughness (bone is held rigid)"),
    )
}

#: Material used for a label the recipe names but does not describe.
GENERIC_SOFT_TISSUE = dict(DEFAULT_MATERIALS["muscle"])

assert all(set(v) == set(MATERIAL_FIELDS) for v in DEFAULT_MATERIALS.values())
assert all(set(DEFAULT_SOURCES[k]) == set(MATERIAL_FIELDS) for k in DEFAULT_MATERIALS)
