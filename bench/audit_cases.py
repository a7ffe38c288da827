"""Audit cases of issue 12, items 1-3 and 6 (impacts), plus the shared helpers.

Each case is a function ``case(quick) -> list[row]``; a row is one expectation checked on one
variant of the scene (``check`` below).  Scenes use only the public API (ModelBuilder,
SimConfig, Simulator).  Tolerances are written next to each check with where they come from.
"""

from __future__ import annotations

import math

import numpy as np

from warp_sim import ModelBuilder, NoTerrain, PlaneTerrain, SimConfig, Simulator, cases
from warp_sim.builder import Material
from warp_sim.column_sag import contact_omega as contact_omega_of

G = 9.81
ZERO_G = (0.0, 0.0, 0.0)
CONVERGENCE = SimConfig().convergence_tolerance  # solver sweeps stop below this velocity change [m/s]


def check(case: str, item: int, variant: str, expectation: str, expected: float, measured: float,
          tolerance: float, unit: str = "", kind: str = "abs", note: str = "") -> dict:
    """One audit row.  kind: 'abs' |measured - expected| <= tol, 'max' measured <= expected + tol,
    'min' measured >= expected - tol.  A non-finite measurement fails."""
    measured = float(measured)
    if not math.isfinite(measured):
        ok = False
    elif kind == "abs":
        ok = abs(measured - expected) <= tolerance
    elif kind == "max":
        ok = measured <= expected + tolerance
    else:
        ok = measured >= expected - tolerance
    return {"case": case, "item": item, "variant": variant, "expectation": expectation,
            "expected": float(expected), "measured": measured, "tolerance": float(tolerance), "unit": unit,
            "kind": kind, "verdict": "PASS" if ok else "FAIL", "note": note}


def simulate(builder: ModelBuilder, **config) -> Simulator:
    return Simulator(builder.finalize("cpu"), SimConfig(**config))


def contact_omega(h: float) -> float:
    """Soft contact angular frequency at substep h (README: contact stiffness; column_sag.py)."""
    return contact_omega_of(h, SimConfig().contact_hertz)


def host(sim: Simulator, name: str) -> np.ndarray:
    return getattr(sim.state, name).numpy().astype(np.float64)


def momentum(sim: Simulator) -> np.ndarray:
    return (sim.model.body_mass[:, None] * host(sim, "body_vel")).sum(axis=0)


def angular_momentum(sim: Simulator) -> np.ndarray:
    """About the origin: sum of x cross m v plus each body's own (world) L."""
    m = sim.model.body_mass[:, None]
    return (np.cross(host(sim, "body_pos"), m * host(sim, "body_vel")) + host(sim, "body_angmom")).sum(axis=0)


def pair_depth(sim: Simulator) -> float:
    """Deepest body-body penetration of the current state [m] (a fresh broad + narrow phase)."""
    if sim.pairs is None:
        return 0.0
    return sim.pairs.probe_depth(sim.state, sim.probe_contacts())


# 1. A sleeping body hit by an awake one ------------------------------------------------------

def sleeping_target(quick: bool) -> list[dict]:
    """mu 0: ball A (r 0.5) at x = -3 sliding at +3 m/s hits ball B resting at x = 0, asleep by
    then (still for 0.5 s; contact at t = 2/3 s).  Newton's law of impact with Poisson
    restitution: vA' = (mA - e mB) u / (mA + mB), vB' = (1 + e) mA u / (mA + mB).  The issue's
    scene has no gravity, where nothing sleeps now (sleep.py: a slow free body is not at rest), so
    the balls lie on a frictionless plane under gravity, which holds B for its sleep."""
    rows = []
    variants = [(1.0, 1.0, 1.0, True), (100.0, 1.0, 1.0, True), (1.0, 1.0, 1.0, False)]
    if not quick:
        variants += [(1.0, 1.0, 0.5, True), (1.0, 100.0, 1.0, True), (3.0, 1.0, 0.8, True)]
    u = 3.0
    for ma, mb, e, sleep in variants:
        b = ModelBuilder(Material(restitution=e, friction=0.0))
        b.set_terrain(PlaneTerrain())
        b.add_sphere(0.5, ma, position=(-3.0, 0.5, 0.0), velocity=(u, 0.0, 0.0))
        b.add_sphere(0.5, mb, position=(0.0, 0.5, 0.0))
        sim = simulate(b, sleep=sleep)
        sim.step(36)  # t = 0.6 s, A 0.2 m short of B
        asleep = sim.awake_count() < 2
        sim.step(54)
        v = host(sim, "body_vel")[:, 0]
        want = np.array([(ma - e * mb) * u / (ma + mb), (1 + e) * ma * u / (ma + mb)])
        tag = f"mA {ma:g} mB {mb:g} e {e:g}" + ("" if sleep else " (sleep off: control)")
        note = f"B asleep before the hit: {asleep}; vA {v[0]:.3f} vB {v[1]:.3f}"
        # A single-point impact is resolved exactly by an impulse solver; what is left is the
        # convergence tolerance per sweep (1e-5 m/s, 3 sweeps x 4 substeps) and float32:
        # 1e-3 u bounds both with a wide margin.
        rows.append(check("sleep_hit_velocity", 1, tag, "velocities after the hit (Newton, Poisson e)", 0.0,
                          np.abs(v - want).max(), 1e-3 * u, "m/s", "max", note))
        p0 = ma * u
        rows.append(check("sleep_hit_momentum", 1, tag, "total momentum kept: P'/P = 1", 1.0,
                          momentum(sim)[0] / p0, 1e-3, "", "abs"))
    rows += sleeping_stack(quick)
    return rows


def sleeping_stack(quick: bool) -> list[dict]:
    """A 3 kg ball dropped on the edge of a 3-box stack: awake, it knocks the top box off; asleep
    (after 0.5 s still) the stack must react the same way."""
    rows = []
    masses = [3.0] if quick else [3.0, 10.0]
    half = 0.25
    for mass in masses:
        moved = {}
        for sleep in (False, True):
            b = ModelBuilder(Material(friction=0.5))
            b.set_terrain(PlaneTerrain())
            for k in range(3):
                b.add_box((half, half, half), 1.0, position=(0.0, half + 2 * half * k, 0.0))
            top_y = 6 * half
            # 7 m of fall: it lands at t = 1.2 s, after the stack has been still for 0.5 s
            b.add_sphere(0.25, mass, position=(half, top_y + 0.25 + 7.0, 0.0))
            sim = simulate(b, sleep=sleep)
            sim.step(66)  # 1.1 s
            asleep = sim.awake_count() <= 1
            start = host(sim, "body_pos")[2].copy()
            sim.step(90)
            d = host(sim, "body_pos")[2] - start
            moved[sleep] = float(math.hypot(d[0], d[2]))
            tag = f"ball {mass:g} kg, " + ("sleeping stack" if sleep else "awake stack (control)")
            note = f"stack asleep before the hit: {asleep}" if sleep else ""
            # knocked off = moved sideways by more than one box width (2 half) within 1.5 s
            rows.append(check("sleep_hit_stack", 1, tag, "top box knocked off (moves > 1 box width)", 2 * half,
                              moved[sleep], 0.0, "m", "min", note))
    return rows


# 2. Restitution on multi-point contacts ------------------------------------------------------

def multipoint_restitution(quick: bool) -> list[dict]:
    rows = []
    drops = [(0.5, 2.0)] if quick else [(0.5, 2.0), (0.8, 1.0), (0.3, 2.0)]
    half = 0.25
    for e, height in drops:
        b = ModelBuilder(Material(restitution=e, friction=0.5))
        b.set_terrain(PlaneTerrain())
        b.add_box((half, half, half), 1.0, position=(0.0, height + half, 0.0))
        dt, substeps = 1.0 / 60.0, 4
        h = dt / substeps
        sim = simulate(b, sleep=False, dt=dt, substeps=substeps)
        bounced, apex, spin = False, -1.0, 0.0
        for _ in range(int(2.0 * math.sqrt(2 * height / G) / dt) + 60):
            sim.step()
            vy = host(sim, "body_vel")[0, 1]
            if not bounced and vy > 0.0:
                bounced = True
            if bounced:
                apex = max(apex, host(sim, "body_pos")[0, 1] - half)
                spin = max(spin, float(np.linalg.norm(sim.angular_velocity()[0])))
                if vy < 0.0 and apex > 0.0:
                    break
        tag = f"cube dropped flat from {height:g} m, e {e:g}"
        want = e * e * height
        v = math.sqrt(2 * G * height)
        # as tests/test_contacts.py: the impact is taken at its time in the substep, so semi-implicit
        # Euler's lag is left, e (1 + e) v h / 2 (the fall arrives g h / 2 slow, the rise at e v
        # peaks e v h / 2 low); the apex is sampled once per step (g dt^2 / 2), the soft contact's
        # rest deflection g / omega^2 shifts it
        tol = e * (1 + e) * v * h / 2 + 0.5 * G * dt * dt + G / contact_omega(h) ** 2
        rows.append(check("flat_cube_apex", 2, tag, "first rebound apex e^2 H", want, apex, tol, "m"))
        # symmetric impact: no spin in exact arithmetic; float32 differences of the 4 corner
        # impulses (~1e-5 of m v) times the lever arm over I give well under 0.05 rad/s
        rows.append(check("flat_cube_spin", 2, tag, "no spin after a symmetric impact", 0.0, spin, 0.05, "rad/s",
                          "max"))
    rows += face_on_cubes(quick)
    rows += ball_row(quick)
    return rows


def face_on_cubes(quick: bool) -> list[dict]:
    """Zero gravity, two aligned cubes (half 0.25), A moving +2 m/s into B at rest."""
    rows = []
    variants = [(1.0, 0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.125)]  # (e, mu, mA/mB - 1, y offset of A)
    if not quick:
        variants += [(0.5, 0.5, 0.0, 0.0), (1.0, 0.5, 1.0, 0.0), (1.0, 0.0, 0.0, 0.2)]
    u, half = 2.0, 0.25
    for e, mu, extra, offset in variants:
        ma, mb = 1.0 + extra, 1.0
        b = ModelBuilder(Material(restitution=e, friction=mu))
        b.set_terrain(NoTerrain())
        b.add_box((half, half, half), ma, position=(-1.0, offset, 0.0), velocity=(u, 0.0, 0.0))
        b.add_box((half, half, half), mb, position=(0.0, 0.0, 0.0))
        sim = simulate(b, gravity=ZERO_G, sleep=False)
        ke0 = sim.kinetic_energy()
        sim.step(45)  # contact at t = 0.25 s
        tag = f"e {e:g} mu {mu:g} mA/mB {ma / mb:g}" + (f" offset {offset:g} m" if offset else " aligned")
        if offset == 0.0:
            spin = float(np.abs(sim.angular_velocity()).max())
            # symmetric: 0 exactly but for float32 (see flat_cube_spin)
            rows.append(check("face_on_spin", 2, tag, "aligned face-on impact: no spin", 0.0, spin, 0.05, "rad/s",
                              "max"))
            v = host(sim, "body_vel")[:, 0]
            want = np.array([(ma - e * mb) * u / (ma + mb), (1 + e) * ma * u / (ma + mb)])
            # see sleep_hit_velocity: impulse exchange exact to convergence and float32
            rows.append(check("face_on_velocity", 2, tag, "velocities after the hit (Newton, Poisson e)", 0.0,
                              np.abs(v - want).max(), 1e-3 * u, "m/s", "max"))
        else:
            # e = 1 without friction conserves kinetic energy whatever the contact patch; the
            # impulses converge to 1e-5 m/s per sweep, so 1e-3 of KE bounds the rest
            rows.append(check("off_centre_energy", 2, tag, "e = 1, mu 0: KE'/KE = 1", 1.0,
                              sim.kinetic_energy() / ke0, 1e-3, ""))
    return rows


def ball_row(quick: bool) -> list[dict]:
    """Zero gravity, a row of touching balls (r 0.25, sleep off) struck by one more at 3 m/s,
    e = 1.  The chain follows whatever model of simultaneous impacts: with e = 1 and no friction
    it must keep momentum and kinetic energy."""
    rows = []
    variants = [(5, False)] if quick else [(3, False), (5, False), (8, False), (5, True)]
    r, u = 0.25, 3.0
    for n, ground in variants:
        b = ModelBuilder(Material(restitution=1.0, friction=0.0))
        # on a frictionless plane under gravity the ground contacts join the impact, but take no
        # energy (mu 0, and they do not approach)
        b.set_terrain(PlaneTerrain() if ground else NoTerrain())
        y = r if ground else 0.0
        b.add_sphere(r, 1.0, position=(-1.0, y, 0.0), velocity=(u, 0.0, 0.0))
        for k in range(n):
            b.add_sphere(r, 1.0, position=(2 * r * k, y, 0.0))
        sim = simulate(b, gravity=(0.0, -G, 0.0) if ground else ZERO_G, sleep=False)
        ke0, p0 = sim.kinetic_energy(), momentum(sim)[0]
        sim.step(60)
        tag = f"{n} balls struck at {u:g} m/s, e 1" + (", on a plane, mu 0" if ground else ", zero g")
        v = host(sim, "body_vel")[:, 0]
        note = "velocities " + " ".join(f"{x:.2f}" for x in v)
        # as off_centre_energy and sleep_hit_momentum: exact but for convergence and float32
        rows.append(check("ball_row_energy", 2, tag, "KE'/KE = 1", 1.0, sim.kinetic_energy() / ke0, 1e-3, "",
                          "abs", note))
        rows.append(check("ball_row_momentum", 2, tag, "P'/P = 1", 1.0, momentum(sim)[0] / p0, 1e-3, ""))
    return rows


# 3. Friction in impact impulses --------------------------------------------------------------

def impact_friction(quick: bool) -> list[dict]:
    """Zero gravity, a sphere (r 0.25) hits a floor (the plane y = 0, or a static box whose top is
    there) at (v_t, -v_n).  Coulomb friction with Poisson restitution: the tangential impulse is
    min(mu (1 + e) m v_n, 2/7 m v_t) (the second once the contact point stops sliding: a sphere
    rolls when v_t drops by 2/7).  And a cube (half 0.25) landing flat while sliding: one force F
    against the slide, a below the centre, so v_x = v_t - F / m, L_z = -a F and no sideways
    velocity; F = min(mu (1 + e) m v_n, 0.4 m v_t) (the face sticks at k_t = 2.5 / m)."""
    rows = []
    variants = [(0.5, 0.1, 3.0, 5.0), (0.0, 0.1, 3.0, 5.0)]
    if not quick:
        variants += [(0.5, 0.05, 3.0, 5.0), (0.8, 0.2, 4.0, 3.0), (0.5, 0.5, 3.0, 5.0)]
    r = 0.25
    for floor in ("plane", "static box"):
        for e, mu, vt, vn in variants:
            b = ModelBuilder(Material(restitution=e, friction=mu))
            add_floor(b, floor)
            b.add_sphere(r, 1.0, position=(0.0, r + 0.5, 0.0), velocity=(vt, -vn, 0.0))
            sim = simulate(b, gravity=ZERO_G, sleep=False)
            sim.step(30)  # contact at t = 0.1 s, gone by t = 0.2 s
            v = host(sim, "body_vel")[-1]
            want_t = vt - min(mu * (1 + e) * vn, 2.0 / 7.0 * vt)
            tag = f"{floor}, v ({vt:g}, -{vn:g}) e {e:g} mu {mu:g}"
            # impulses exact to the solver's convergence (1e-5 m/s a sweep) and float32; 0.02 m/s
            # (0.4 % of the approach speed) is a wide bound on both
            rows.append(check("impact_friction_vt", 3, tag, "v_t' = v_t - min(mu (1+e) v_n, 2/7 v_t)", want_t,
                              v[0], 0.02, "m/s"))
            rows.append(check("impact_friction_vn", 3, tag, "v_n' = e v_n", e * vn, v[1], 0.02, "m/s"))
    half, vt, vn = 0.25, 3.0, 5.0
    for floor in ("plane", "static box"):
        for e, mu in [(0.5, 0.1), (0.5, 1.0)] if not quick else [(0.5, 0.1)]:
            b = ModelBuilder(Material(restitution=e, friction=mu))
            add_floor(b, floor)
            b.add_box((half, half, half), 1.0, position=(0.0, half + 0.05, 0.0), velocity=(vt, -vn, 0.0))
            sim = simulate(b, gravity=ZERO_G, sleep=False)
            sim.step(6)
            v = host(sim, "body_vel")[-1]
            spin = host(sim, "body_angmom")[-1] / half  # as a speed at the arm (m = 1)
            force = min(mu * (1 + e) * vn, 0.4 * vt)
            tag = f"{floor}, cube, e {e:g} mu {mu:g}"
            # a converged impact is exact to float32: 1e-4 of the approach speed
            rows.append(check("impact_friction_cube_vt", 3, tag, "v_t' = v_t - F / m", vt - force, v[0], 5e-4, "m/s"))
            rows.append(check("impact_friction_cube_spin", 3, tag, "L_z / a = -F", -force, spin[2], 5e-4, "m/s"))
            rows.append(check("impact_friction_cube_sideways", 3, tag, "|v_z| + |L_x| / a + |L_y| / a = 0", 0.0,
                              abs(v[2]) + abs(spin[0]) + abs(spin[1]), 5e-4, "m/s", kind="max"))
    return rows


def add_floor(builder: ModelBuilder, floor: str):
    """The plane y = 0, or a static box with its top face there."""
    if floor == "plane":
        builder.set_terrain(PlaneTerrain())
    else:
        builder.add_box((5.0, 0.5, 5.0), 1.0, position=(0.0, -0.5, 0.0), static=True)


# 6. Impacts later in a step ------------------------------------------------------------------

def late_impact_tunnel(quick: bool) -> list[dict]:
    """Zero gravity, e = 1, mu 0: ball A hits ball B resting at the origin, B then meets a thin
    static wall within the same step; eight start phases of A (fractions of one step's travel).
    No ball may end beyond the wall."""
    rows = []
    scales = [("40 m/s, r 0.1, wall 0.02", 0.1, 40.0, 0.02, 0.25, -0.7, 1.0),
              ("billiard 8 m/s, r 0.028, wall 0.01", 0.028, 8.0, 0.01, 0.07, -0.2, 1.0)]
    if not quick:
        scales.append(("40 m/s, r 0.1, wall 0.02, mA 2", 0.1, 40.0, 0.02, 0.25, -0.7, 2.0))
    phases = range(0, 8, 2) if quick else range(8)
    for name, r, u, wall_half, wall_x, start, ma in scales:
        passed = 0
        for k in phases:
            b = ModelBuilder(Material(restitution=1.0, friction=0.0))
            b.set_terrain(NoTerrain())
            x0 = start - k / 8.0 * u / 60.0
            b.add_sphere(r, ma, position=(x0, 0.0, 0.0), velocity=(u, 0.0, 0.0))
            b.add_sphere(r, 1.0, position=(0.0, 0.0, 0.0))
            b.add_box((wall_half, 0.5, 0.5), 1.0, position=(wall_x, 0.0, 0.0), static=True)
            sim = simulate(b, gravity=ZERO_G, sleep=False)
            sim.step(int(0.3 * 60))
            passed += int((host(sim, "body_pos")[:2, 0] > wall_x).any())
        rows.append(check("late_impact_tunnel", 6, name, f"start phases (of {len(phases)}) with a ball through the wall", 0,
                          passed, 0, "phases", "max"))
    return rows


# Properties on random impacts ----------------------------------------------------------------

def random_impacts(seed: int, count: int = 12):
    """Spheres and boxes of random size, mass, orientation and spin on a lattice, flying at the
    centre at 2-4 m/s; random e in [0, 1] and mu in [0, 1]; zero gravity, no terrain
    (warp_sim.cases.pileup_builder)."""
    return simulate(cases.pileup_builder(seed, count), gravity=ZERO_G, sleep=False)


def impact_properties(quick: bool) -> list[dict]:
    rows = []
    seeds = range(2) if quick else range(6)
    steps = 120 if quick else 180
    eps32 = 2.0**-24
    for seed in seeds:
        sim = random_impacts(seed)
        m = sim.model.body_mass
        p0, l0, ke0 = momentum(sim), angular_momentum(sim), sim.kinetic_energy()
        p_scale = float((m * np.linalg.norm(host(sim, "body_vel"), axis=1)).sum())
        l_scale = float(np.linalg.norm(np.cross(host(sim, "body_pos"), m[:, None] * host(sim, "body_vel")), axis=1).sum()
                        + np.linalg.norm(host(sim, "body_angmom"), axis=1).sum())
        dp = dl = rise = depth = 0.0
        ke_prev = ke0
        for k in range(steps):
            sim.step()
            dp = max(dp, float(np.linalg.norm(momentum(sim) - p0)) / p_scale)
            dl = max(dl, float(np.linalg.norm(angular_momentum(sim) - l0)) / l_scale)
            ke = sim.kinetic_energy()
            rise = max(rise, (ke - ke_prev) / ke0)
            ke_prev = ke
            if k % 3 == 0:
                depth = max(depth, pair_depth(sim))
        tag = f"seed {seed}, 12 bodies, {steps} steps"
        n_sub = steps * sim.substeps
        # every contact impulse acts equal and opposite: momentum is exact but for float32
        # round-off, a few eps of each body's |p| per substep, summed: 4 eps sum m|v| per substep
        tol_p = 4 * n_sub * eps32
        rows.append(check("property_momentum", 0, tag, "|P - P0| / sum m|v| = 0 (zero gravity)", 0.0, dp, tol_p, "",
                          "max"))
        # equal and opposite impulses at one point: angular momentum about the origin is exact too
        # (world L is the stored variable), same round-off bound
        rows.append(check("property_angular_momentum", 0, tag, "|L - L0| / sum |L_i| = 0 (free space)", 0.0, dl,
                          tol_p, "", "max"))
        # contacts with e <= 1 only remove energy; the step's float32 rounding of KE is ~1e-6
        rows.append(check("property_energy_rise", 0, tag, "KE never rises in a step: max dKE / KE0 <= 0", 0.0, rise,
                          1e-5, "", "max"))
        # the soft contact allows its own slop; the goal for body-body depth is 1 cm
        rows.append(check("property_no_pass_through", 0, tag, "body-body depth < 1 cm", 0.0, depth, 0.01, "m",
                          "max"))
    rows += glancing_spheres(quick)
    return rows


def glancing_spheres(quick: bool) -> list[dict]:
    """Zero gravity, e = 1, mu 0: a ball (r 0.3) grazes a heavier one (offset 0.2 m).  The impulse
    acts along the line of centres, so angular momentum about the origin and kinetic energy are
    both kept exactly; a contact normal frozen while the centres turn about each other breaks
    the first."""
    rows = []
    for update in (["step"] if quick else ["step", "substep"]):
        b = ModelBuilder(Material(restitution=1.0, friction=0.0))
        b.set_terrain(NoTerrain())
        b.add_sphere(0.3, 1.0, position=(-2.0, 0.2, 0.0), velocity=(3.0, 0.0, 0.0))
        b.add_sphere(0.3, 2.0, position=(0.0, 0.0, 0.0))
        sim = simulate(b, gravity=ZERO_G, sleep=False, contact_update=update)
        l0, ke0 = angular_momentum(sim), sim.kinetic_energy()
        sim.step(60)
        n_sub = 60 * sim.substeps
        tag = f"glancing spheres, contacts once per {update}"
        # as property_angular_momentum: exact but for float32, 4 eps per substep of |L|
        rows.append(check("property_angular_momentum", 0, tag, "|L - L0| / |L0| = 0", 0.0,
                          np.linalg.norm(angular_momentum(sim) - l0) / np.linalg.norm(l0), 4 * n_sub * 2.0**-24, "",
                          "max"))
        rows.append(check("property_energy_elastic", 0, tag, "e = 1, mu 0: KE'/KE = 1", 1.0, sim.kinetic_energy() / ke0,
                          1e-3, ""))
    return rows
