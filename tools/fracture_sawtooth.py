"""Fracture scalpel on a slab: steady force per mm of cut depth against J_c, and the sawtooth plot.

Drives the fracture model (docs/scalpel-model.md) kinematically: the device
tip moves at a constant low speed along the cut at a fixed depth, 1 ms a
step.  Prints one JSON object (the steady force per mm of depth for each
case, against J_c in N/mm) and draws the force against the blade's travel
into ``docs/images/fracture-sawtooth.png``.

    python tools/fracture_sawtooth.py [--png PATH] [--no-png]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

#: (label, J_c J/m^2, E Pa): liver-like and muscle-like toughness; E varied 4x at fixed J_c.
CASES = (
    ("liver-like", 200.0, 30e3),
    ("liver-like, E x4", 200.0, 120e3),
    ("muscle-like", 2000.0, 30e3),
    ("muscle-like, E x4", 2000.0, 120e3),
)
DEPTH_MM = 5.0
SPEED_MM_S = 3.0
SECONDS = 60.0
K_SPRING = 5.0  # N/mm, the device coupling
CRACK_STEP_MM = 0.1


def run_case(J_c: float, E: float) -> dict:
    from cutkit.scalpel import N_OUT, O_CRACK, O_CUT, Control, ScalpelParams, ScalpelState, enter, step

    p = ScalpelParams(model="fracture", J_c=J_c, eta=E, k_spring=K_SPRING, crack_step=CRACK_STEP_MM).array()
    s, c, out = ScalpelState(), Control(), np.zeros(N_OUT)
    enter(s, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.zeros(3))
    n = int(SECONDS * 1000)
    travel = SPEED_MM_S * np.arange(n) * 1e-3
    force, crack = np.zeros(n), np.zeros(n)
    for i in range(n):
        c.set((travel[i], DEPTH_MM, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0))
        step(p, s, c, np.zeros(3), out)
        force[i] = -out[O_CUT]
        crack[i] = out[O_CRACK]
    jumps = np.flatnonzero(np.diff(crack) > 0) + 1
    steady = float(force[jumps[0]:jumps[-1]].mean()) if jumps.size >= 2 else float("nan")
    return {"J_c_J_per_m2": J_c, "E_Pa": E, "steady_force_N": steady,
            "steady_force_per_mm_N_per_mm": steady / DEPTH_MM, "J_c_N_per_mm": J_c * 1e-3,
            "ratio_to_J_c": steady / DEPTH_MM / (J_c * 1e-3), "crack_advances": int(jumps.size),
            "sawtooth_drop_N": float(np.median(force[jumps - 1] - force[jumps])) if jumps.size else 0.0,
            "_travel": travel, "_force": force}


def plot(results: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, (label, r) in zip(axes, [(c[0], r) for c, r in zip(CASES, results)][::2]):
        ax.plot(r["_travel"], r["_force"], lw=0.8, label="blade force")
        ax.axhline(r["J_c_N_per_mm"] * DEPTH_MM, color="k", ls="--", lw=0.8, label="J_c x depth")
        ax.set_title(f"{label}: J_c = {r['J_c_J_per_m2']:.0f} J/m², E = {r['E_Pa'] / 1e3:.0f} kPa, "
                     f"depth {DEPTH_MM:.0f} mm", fontsize=9)
    zoom = axes[2]
    for (label, _, _), r in list(zip(CASES, results))[:2]:
        keep = (r["_travel"] >= 20.0) & (r["_travel"] <= 20.6)
        zoom.plot(r["_travel"][keep], r["_force"][keep], lw=0.9, label=f"{label}, E = {r['E_Pa'] / 1e3:.0f} kPa")
    zoom.axhline(results[0]["J_c_N_per_mm"] * DEPTH_MM, color="k", ls="--", lw=0.8, label="J_c x depth")
    zoom.set_title("liver-like, steady state: load, then unload as the crack jumps", fontsize=9)
    for ax in axes:
        ax.set_xlabel("blade travel, mm")
        ax.set_ylabel("force along the cut, N")
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--png", default="docs/images/fracture-sawtooth.png")
    ap.add_argument("--no-png", action="store_true")
    args = ap.parse_args()
    results = [run_case(J, E) for _, J, E in CASES]
    if not args.no_png:
        plot(results, args.png)
    report = {"depth_mm": DEPTH_MM, "speed_mm_s": SPEED_MM_S, "k_spring_N_per_mm": K_SPRING,
              "crack_step_mm": CRACK_STEP_MM,
              "cases": {c[0]: {k: v for k, v in r.items() if not k.startswith("_")} for c, r in zip(CASES, results)}}
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
