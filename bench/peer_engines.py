"""Engine adapters for bench/peers.py: the scene description every engine builds, the frame
change between warp_sim's y-up and the peers' z-up worlds, and one class per engine (warp_sim,
MuJoCo, PyBullet, Newton) with the same build / step / read-back interface.  See peers.py's
docstring for how each engine is configured and why.
"""

from __future__ import annotations

import importlib.util
import math
import os
import sys
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from warp_sim import ModelBuilder, PlaneTerrain, SimConfig, Simulator, cases  # noqa: E402
from warp_sim.builder import Material, quat_to_matrix  # noqa: E402
from warp_sim.types import SHAPE_SPHERE  # noqa: E402

DT = 1.0 / 240.0
G = cases.GRAVITY
ENGINES = ("warp_sim", "warp_sim-1t", "mujoco", "pybullet", "newton")
MODULE = {"warp_sim": "warp", "warp_sim-1t": "warp", "mujoco": "mujoco", "pybullet": "pybullet", "newton": "newton"}
SCENES = ("rain", "stack", "bounce", "roll", "slide")

# warp_sim frame (y up) -> peer frame (z up): (x, y, z) -> (x, -z, y)
M = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

RESTITUTION = 0.5
STACK_COUNT = 10


# Frames and quaternions ------------------------------------------------------------------------

def to_peer(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, dtype=np.float64) @ M.T


def from_peer(v: np.ndarray) -> np.ndarray:
    return np.asarray(v, dtype=np.float64) @ M


def quat_matrices(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (x, y, z, w) -> (N, 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return np.array([quat_to_matrix(row) for row in q]) if len(q) else np.zeros((0, 3, 3))


def matrix_quats(r: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices -> (N, 4) quaternions (x, y, z, w), w >= 0."""
    r = np.asarray(r, dtype=np.float64)
    out = np.zeros((len(r), 4))
    for i, m in enumerate(r):
        t = np.trace(m)
        if t > 0:
            s = 2.0 * math.sqrt(1.0 + t)
            q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
        elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
            s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
        elif m[1, 1] > m[2, 2]:
            s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
            q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
        else:
            s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
            q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
        q = np.asarray(q)
        out[i] = q if q[3] >= 0 else -q
    return out


def rot_to_peer(r: np.ndarray) -> np.ndarray:
    return np.einsum("ij,njk,lk->nil", M, r, M)


def rot_from_peer(r: np.ndarray) -> np.ndarray:
    return np.einsum("ji,njk,kl->nil", M, r, M)


def align_z(normal) -> np.ndarray:
    """Quaternion (x, y, z, w) turning +z onto ``normal`` (shortest arc)."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    axis = np.cross([0.0, 0.0, 1.0], n)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return np.array([0.0, 0.0, 0.0, 1.0]) if n[2] > 0 else np.array([1.0, 0.0, 0.0, 0.0])
    angle = math.atan2(s, n[2])
    axis = axis / s
    return np.array([*(axis * math.sin(angle / 2)), math.cos(angle / 2)])


# Scene specifications --------------------------------------------------------------------------

class Spec:
    """One scene, in warp_sim's frame, from which every engine builds its own copy.

    bodies: shape (N,) 'sphere'/'box', size (N,) radius or cube half edge, pos (N, 3), quat (N, 4);
    ground: ('fourier', terrain) or ('plane', normal, offset); material: friction, restitution,
    rolling (torque / normal force [m], spheres); ours(): the warp_sim Simulator of the scene.
    """

    def __init__(self, scene, ours, body_contact, friction, restitution=0.0, rolling_resistance=0.0,
                 settle_steps=0, steps=0, sample_every=0, label=""):
        self.scene = scene
        self.ours = ours
        self.body_contact = body_contact
        self.friction = friction
        self.restitution = restitution
        self.rolling_resistance = rolling_resistance  # warp_sim's c_r: torque <= c_r r j_n
        self.settle_steps = settle_steps
        self.steps = steps
        self.sample_every = sample_every
        self.label = label
        template = ours()  # read the bodies back from the warp_sim model so every engine gets the same
        host = template.model.host
        self.count = template.model.body_count
        self.shape = np.where(host["body_shape"] == SHAPE_SPHERE, "sphere", "box")
        self.size = host["body_size"][:, 0].astype(np.float64)  # sphere radius or cube half edge
        if np.any(self.shape == "box"):
            boxes = host["body_size"][self.shape == "box"]
            if not np.allclose(boxes, boxes[:, :1]):
                raise ValueError("peer scenes use cubes only (half extents all equal)")
        self.pos = host["body_pos"].astype(np.float64)
        self.quat = host["body_quat"].astype(np.float64)
        self.mass = template.model.body_mass.astype(np.float64)
        self.inertia = host["body_inertia"].astype(np.float64)
        terrain = template.model.terrain
        if isinstance(terrain, PlaneTerrain):
            self.ground = ("plane", np.asarray(terrain.normal), float(terrain.offset))
        else:
            self.ground = ("fourier", terrain)
        self.probe_sim = None

    def rolling_length(self, i: int) -> float:
        return self.rolling_resistance * self.size[i] if self.shape[i] == "sphere" else 0.0

    def probe(self) -> Simulator:
        """A warp_sim model of the same bodies and ground, terrain contact only: the depth oracle."""
        if self.probe_sim is None:
            b = ModelBuilder(Material(friction=self.friction))
            if self.ground[0] == "plane":
                b.set_terrain(PlaneTerrain(normal=tuple(self.ground[1]), offset=self.ground[2]))
            else:
                b.set_terrain(self.ground[1])
            for i in range(self.count):
                if self.shape[i] == "sphere":
                    b.add_sphere(self.size[i], self.mass[i], position=self.pos[i], orientation=self.quat[i])
                else:
                    b.add_box((self.size[i],) * 3, self.mass[i], position=self.pos[i], orientation=self.quat[i])
            self.probe_sim = Simulator(b.finalize("cpu"), SimConfig(dt=DT, substeps=1, body_contact=False,
                                                                     sleep=False))
        return self.probe_sim


def heightfield(spec: Spec, spacing: float, margin: float):
    """Samples of the Fourier terrain in the peer frame: (xs, H[row = y, col = x], half)."""
    extent = float(np.abs(spec.pos[:, [0, 2]]).max()) if spec.count else 0.0
    half = extent + margin
    cells = int(math.ceil(2.0 * half / spacing))
    xs = np.linspace(-half, half, cells + 1)
    grid_x, grid_y = np.meshgrid(xs, xs, indexing="xy")  # [row, col]: row along peer y, col along x
    heights = spec.ground[1].height(grid_x, -grid_y)  # peer (X, Y) is warp_sim (x, -z)
    return xs, heights, half


def rain_spec(count, shape, body_contact, settle, steps, samples) -> Spec:
    def ours():
        return cases.terrain_drop(count, shape, dt=DT, substeps=1, body_contact=body_contact)

    sample_every = max(1, steps // max(samples, 1))
    return Spec("rain", ours, body_contact, friction=0.6, rolling_resistance=0.1,
                settle_steps=int(round(settle / DT)), steps=steps, sample_every=sample_every,
                label=f"rain {count} {shape}{'' if body_contact else ' (terrain only)'}")


def stack_spec(duration=5.0) -> Spec:
    def ours():
        b = ModelBuilder(Material(friction=0.6))
        b.set_terrain(PlaneTerrain())
        for k in range(STACK_COUNT):
            b.add_box((0.5, 0.5, 0.5), 1.0, position=(0.0, 0.5 + k, 0.0))
        return Simulator(b.finalize(), SimConfig(dt=DT, substeps=1, sleep=False))

    return Spec("stack", ours, True, friction=0.6, steps=int(round(duration / DT)), label="stack of 10 unit cubes")


def bounce_spec(duration=1.6) -> Spec:
    return Spec("bounce", lambda: cases.bounce(RESTITUTION, dt=DT, substeps=1), False, friction=0.0,
                restitution=RESTITUTION, steps=int(round(duration / DT)), label="bounce e = 0.5 from 1 m")


def roll_spec(duration=1.0) -> Spec:
    return Spec("roll", lambda: cases.rolling_sphere(20.0, dt=DT, substeps=1), False, friction=0.5,
                steps=int(round(duration / DT)), label="sphere rolling on 20 deg")


def slide_spec(duration=1.0) -> Spec:
    return Spec("slide", lambda: cases.sliding_box(30.0, 0.3, dt=DT, substeps=1), False, friction=0.3,
                steps=int(round(duration / DT)), label="cube sliding on 30 deg, mu 0.3")


# Engines ---------------------------------------------------------------------------------------

class Engine:
    """build(spec) once, then step(k) and read() -> (pos, rot, vel, omega) in warp_sim's frame."""

    name = ""
    settings = ""

    def __init__(self, spec: Spec, hfield_spacing: float, hfield_margin: float):
        self.spec = spec
        self.hfield_spacing = hfield_spacing
        self.hfield_margin = hfield_margin
        self.field_half = math.inf
        self.hfield_error = None

    def close(self):
        pass

    def contact_count(self) -> int | str:
        return ""


class WarpSimEngine(Engine):
    name = "warp_sim"

    def __init__(self, spec, hfield_spacing, hfield_margin, threads: int | None = None):
        super().__init__(spec, hfield_spacing, hfield_margin)
        self.threads = threads
        self._saved = os.environ.get("WARP_SIM_CPU_THREADS")
        if threads:
            os.environ["WARP_SIM_CPU_THREADS"] = str(threads)
        from warp_sim.launch import cpu_threads

        self.sim = spec.ours()
        cfg = self.sim.config
        self.settings = (f"dt 1/240 x {cfg.substeps}, {cfg.solver} {cfg.iterations}+{cfg.relax_iterations} it, "
                         f"{cfg.integrator}, analytic terrain, body contact {'on' if self.sim.pairs else 'off'}"
                         f"{' (' + cfg.broad_phase + ')' if self.sim.pairs else ''}, sleep "
                         f"{'on' if cfg.sleep else 'off'}, {cpu_threads()} CPU thread(s)")
        self.hfield_error = 0.0 if spec.ground[0] == "fourier" else None

    def step(self, k: int):
        self.sim.step(k, check=False)

    def read(self):
        s = self.sim.state
        return (s.body_pos.numpy().astype(np.float64), s.body_rot.numpy().astype(np.float64),
                s.body_vel.numpy().astype(np.float64), self.sim.angular_velocity())

    def contact_count(self):
        return self.sim.contact_count()

    def close(self):
        self.sim.check_finite()
        if self.threads:
            if self._saved is None:
                os.environ.pop("WARP_SIM_CPU_THREADS", None)
            else:
                os.environ["WARP_SIM_CPU_THREADS"] = self._saved


class MuJoCoEngine(Engine):
    name = "mujoco"

    def __init__(self, spec, hfield_spacing, hfield_margin):
        super().__init__(spec, hfield_spacing, hfield_margin)
        import mujoco

        self.mj = mujoco
        s = spec
        mu = s.friction
        solref = ""
        if s.restitution > 0:
            ln_e = math.log(s.restitution)
            zeta = -ln_e / math.sqrt(math.pi ** 2 + ln_e ** 2)
            solref = f' solref="0.02 {zeta:.6f}"'
        body_mask = ' contype="1" conaffinity="1"' if s.body_contact else ' contype="1" conaffinity="2"'
        ground_mask = ' contype="2" conaffinity="1"'

        def contact_attrs(rolling: float) -> str:
            if mu == 0:
                return f' condim="1"{solref}'
            if rolling > 0:
                return f' condim="6" friction="{mu} {rolling} {rolling}"{solref}'
            return f' condim="3" friction="{mu} 0.005 0.0001"{solref}'

        asset, ground = "", ""
        if s.ground[0] == "fourier":
            xs, heights, half = heightfield(s, hfield_spacing, hfield_margin)
            self.field_half = half
            lo, hi = float(heights.min()), float(heights.max())
            n = len(xs)
            asset = f'<asset><hfield name="terrain" nrow="{n}" ncol="{n}" size="{half} {half} {hi - lo} 1"/></asset>'
            ground = (f'<geom name="ground" type="hfield" hfield="terrain" pos="0 0 {lo}"{ground_mask}'
                      f'{contact_attrs(s.rolling_length(0) if s.count else 0.0)}/>')
        else:
            _, normal, offset = s.ground
            n_peer = to_peer(normal)
            q = align_z(n_peer)
            p = n_peer * offset
            ground = (f'<geom name="ground" type="plane" size="0 0 1" pos="{p[0]} {p[1]} {p[2]}" '
                      f'quat="{q[3]} {q[0]} {q[1]} {q[2]}"{ground_mask}{contact_attrs(0.0)}/>')
        pos = to_peer(s.pos)
        rq = matrix_quats(rot_to_peer(quat_matrices(s.quat)))
        bodies = []
        for i in range(s.count):
            geom = (f'type="sphere" size="{s.size[i]}"' if s.shape[i] == "sphere"
                    else f'type="box" size="{s.size[i]} {s.size[i]} {s.size[i]}"')
            bodies.append(
                f'<body pos="{pos[i, 0]} {pos[i, 1]} {pos[i, 2]}" quat="{rq[i, 3]} {rq[i, 0]} {rq[i, 1]} {rq[i, 2]}">'
                f'<freejoint/><geom {geom} mass="{s.mass[i]}"{body_mask}{contact_attrs(s.rolling_length(i))}/></body>')
        xml = (f'<mujoco><option timestep="{DT}" integrator="implicitfast" gravity="0 0 {-G}"/>{asset}'
               f'<worldbody>{ground}{"".join(bodies)}</worldbody></mujoco>')
        self.model = mujoco.MjModel.from_xml_string(xml)
        if s.ground[0] == "fourier":
            self.model.hfield_data[:] = ((heights - lo) / max(hi - lo, 1e-12)).ravel()
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        if s.ground[0] == "fourier":
            self.hfield_error = self._hfield_error(asset, ground, heights, lo, hi)
        m = self.model
        self.settings = (f"dt 1/240, integrator implicitfast, solver {['PGS', 'CG', 'Newton'][m.opt.solver]}, "
                         f"{m.opt.iterations} it, {'pyramidal' if m.opt.cone == 0 else 'elliptic'} cone, "
                         f"default solref/solimp{', bounce solref ' + solref.split('=')[1] if solref else ''}, "
                         f"hfield {len(xs) if s.ground[0] == 'fourier' else 0}^2 samples, MuJoCo {mujoco.__version__}")

    def _hfield_error(self, asset: str, ground: str, heights: np.ndarray, lo: float, hi: float) -> float:
        """Ray casts straight down onto a copy of the ground alone, against the analytic height."""
        mj, s = self.mj, self.spec
        model = mj.MjModel.from_xml_string(f"<mujoco>{asset}<worldbody>{ground}</worldbody></mujoco>")
        model.hfield_data[:] = ((heights - lo) / max(hi - lo, 1e-12)).ravel()
        data = mj.MjData(model)
        mj.mj_forward(model, data)
        rng = np.random.default_rng(0)
        pts = rng.uniform(-self.field_half + 0.5, self.field_half - 0.5, (2000, 2))
        geom_id = np.zeros(1, dtype=np.int32)
        down = np.array([0.0, 0.0, -1.0])
        err = 0.0
        for x, y in pts:
            dist = mj.mj_ray(model, data, np.array([x, y, 50.0]), down, None, 1, -1, geom_id)
            if dist >= 0:
                err = max(err, abs(50.0 - dist - s.ground[1].height(x, -y)))
        return float(err)

    def step(self, k: int):
        self.mj.mj_step(self.model, self.data, nstep=k)

    def read(self):
        n = self.spec.count
        q = self.data.qpos.reshape(n, 7)
        v = self.data.qvel.reshape(n, 6)
        quat = q[:, [4, 5, 6, 3]]  # MuJoCo stores w x y z
        rot = quat_matrices(quat)
        omega_world = np.einsum("nij,nj->ni", rot, v[:, 3:6])  # free joint angular velocity is local
        return from_peer(q[:, :3]), rot_from_peer(rot), from_peer(v[:, :3]), from_peer(omega_world)

    def contact_count(self):
        return int(self.data.ncon)


class PyBulletEngine(Engine):
    name = "pybullet"

    def __init__(self, spec, hfield_spacing, hfield_margin):
        super().__init__(spec, hfield_spacing, hfield_margin)
        import pybullet

        self.pb = pb = pybullet
        s = spec
        self.client = pb.connect(pb.DIRECT)
        c = self.client
        pb.setGravity(0, 0, -G, physicsClientId=c)
        pb.setTimeStep(DT, physicsClientId=c)
        if s.ground[0] == "fourier":
            xs, heights, half = heightfield(s, hfield_spacing, hfield_margin)
            self.field_half = half
            step = xs[1] - xs[0]
            n = len(xs)
            shape = pb.createCollisionShape(pb.GEOM_HEIGHTFIELD, meshScale=[step, step, 1.0],
                                            heightfieldData=heights.ravel().tolist(), numHeightfieldRows=n,
                                            numHeightfieldColumns=n, physicsClientId=c)
            # Bullet centres the heightfield's height range on the body origin
            ground = pb.createMultiBody(0, shape, basePosition=[0, 0, 0.5 * (heights.min() + heights.max())],
                                        physicsClientId=c)
            self.hfield_error = self._hfield_error()  # before any body exists, so rays hit only the ground
        else:
            _, normal, offset = s.ground
            n_peer = to_peer(normal)
            shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
            ground = pb.createMultiBody(0, shape, basePosition=list(n_peer * offset),
                                        baseOrientation=list(align_z(n_peer)), physicsClientId=c)
        # Bullet combines friction and restitution as products (the ground carries 1.0) and rolling /
        # spinning friction as r_a mu_b + r_b mu_a (the ground carries 0, so a body's r counts once)
        pb.changeDynamics(ground, -1, lateralFriction=1.0, restitution=1.0, rollingFriction=0.0,
                          spinningFriction=0.0, physicsClientId=c)
        if not s.body_contact:
            pb.setCollisionFilterGroupMask(ground, -1, 2, 1, physicsClientId=c)
        pos = to_peer(s.pos)
        rq = matrix_quats(rot_to_peer(quat_matrices(s.quat)))
        shapes = {}
        self.bodies = []
        for i in range(s.count):
            key = (s.shape[i], float(s.size[i]))
            if key not in shapes:
                shapes[key] = (pb.createCollisionShape(pb.GEOM_SPHERE, radius=key[1], physicsClientId=c)
                               if key[0] == "sphere" else
                               pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[key[1]] * 3, physicsClientId=c))
            body = pb.createMultiBody(float(s.mass[i]), shapes[key], basePosition=list(pos[i]),
                                      baseOrientation=list(rq[i]), physicsClientId=c)
            rolling = s.rolling_length(i)
            pb.changeDynamics(body, -1, lateralFriction=s.friction, restitution=s.restitution,
                              rollingFriction=rolling, spinningFriction=rolling, physicsClientId=c)
            if not s.body_contact:
                pb.setCollisionFilterGroupMask(body, -1, 1, 2, physicsClientId=c)
            self.bodies.append(body)
        params = pb.getPhysicsEngineParameters(physicsClientId=c)
        self.settings = (f"dt 1/240, defaults: {params.get('numSolverIterations', '?')} solver it, "
                         f"{params.get('numSubSteps', 0)} substeps, other engine parameters as shipped, "
                         f"ground friction and "
                         f"restitution 1.0 (Bullet multiplies), ground rolling/spinning 0 (r_a mu_b + r_b mu_a)"
                         + (f", hfield {len(xs)}^2 samples" if s.ground[0] == "fourier" else ""))

    def _hfield_error(self) -> float:
        s = self.spec
        rng = np.random.default_rng(0)
        pts = rng.uniform(-self.field_half + 0.5, self.field_half - 0.5, (2000, 2))
        hits = []
        for chunk in np.array_split(pts, max(1, len(pts) // 500)):
            res = self.pb.rayTestBatch([[x, y, 50.0] for x, y in chunk], [[x, y, -50.0] for x, y in chunk],
                                       physicsClientId=self.client)
            hits += [(x, y, r[3][2]) for (x, y), r in zip(chunk, res) if r[0] >= 0]
        if not hits:
            return float("nan")
        h = np.array(hits)
        return float(np.abs(h[:, 2] - s.ground[1].height(h[:, 0], -h[:, 1])).max())

    def step(self, k: int):
        for _ in range(k):
            self.pb.stepSimulation(physicsClientId=self.client)

    def read(self):
        pb, c = self.pb, self.client
        pos, quat, vel, omega = [], [], [], []
        for b in self.bodies:
            p, q = pb.getBasePositionAndOrientation(b, physicsClientId=c)
            v, w = pb.getBaseVelocity(b, physicsClientId=c)
            pos.append(p)
            quat.append(q)
            vel.append(v)
            omega.append(w)
        rot = quat_matrices(np.array(quat)) if quat else np.zeros((0, 3, 3))
        return from_peer(np.array(pos)), rot_from_peer(rot), from_peer(np.array(vel)), from_peer(np.array(omega))

    def contact_count(self):
        return len(self.pb.getContactPoints(physicsClientId=self.client))

    def close(self):
        self.pb.disconnect(physicsClientId=self.client)


class NewtonEngine(Engine):
    name = "newton"

    def __init__(self, spec, hfield_spacing, hfield_margin, device="cpu"):
        super().__init__(spec, hfield_spacing, hfield_margin)
        import newton

        s = spec
        b = newton.ModelBuilder()  # z up, gravity -9.81
        cfg = newton.ModelBuilder.ShapeConfig

        def material(i=None, **kw):
            rolling = s.rolling_length(i) if i is not None else (s.rolling_length(0) if s.count else 0.0)
            return cfg(mu=float(s.friction), restitution=float(s.restitution), mu_rolling=float(rolling),
                       mu_torsional=float(rolling), **kw)

        hf_samples = 0
        if s.ground[0] == "fourier":
            xs, heights, half = heightfield(s, hfield_spacing, hfield_margin)
            self.field_half = half
            hf_samples = len(xs)
            hf = newton.Heightfield(data=heights, nrow=len(xs), ncol=len(xs), hx=half, hy=half)
            b.add_shape_heightfield(heightfield=hf, cfg=material())
        else:
            _, normal, offset = s.ground
            n_peer = to_peer(normal)
            b.add_shape_plane(plane=tuple(float(v) for v in (*n_peer, -offset)), width=0.0, length=0.0, cfg=material())
        pos = to_peer(s.pos)
        rq = matrix_quats(rot_to_peer(quat_matrices(s.quat)))
        group = 1 if s.body_contact else -1  # negative groups never collide within the group
        for i in range(s.count):
            body = b.add_body(xform=wp.transform(wp.vec3(*(float(v) for v in pos[i])),
                                                 wp.quat(*(float(v) for v in rq[i]))))
            r = float(s.size[i])
            if s.shape[i] == "sphere":
                density = float(s.mass[i] / (4.0 / 3.0 * math.pi * r ** 3))
                b.add_shape_sphere(body=body, radius=r, cfg=material(i, density=density, collision_group=group))
            else:
                density = float(s.mass[i] / (2.0 * r) ** 3)
                b.add_shape_box(body=body, hx=r, hy=r, hz=r, cfg=material(i, density=density, collision_group=group))
        self.model = b.finalize(device=device)
        self.solver = newton.solvers.SolverXPBD(self.model, enable_restitution=s.restitution > 0)
        self.pipeline = newton.CollisionPipeline(self.model)
        self.contacts = self.pipeline.contacts()
        self.state_0, self.state_1 = self.model.state(), self.model.state()
        self.control = self.model.control()
        self.settings = (f"dt 1/240, SolverXPBD defaults (2 it), CollisionPipeline defaults, restitution "
                         f"{'on' if s.restitution > 0 else 'off'}"
                         + (f", hfield {hf_samples}^2 samples" if hf_samples else "") + f", Newton {newton.__version__}")

    def step(self, k: int):
        for _ in range(k):
            self.state_0.clear_forces()
            self.pipeline.collide(self.state_0, self.contacts)
            self.solver.step(self.state_0, self.state_1, self.control, self.contacts, DT)
            self.state_0, self.state_1 = self.state_1, self.state_0

    def read(self):
        q = self.state_0.body_q.numpy().astype(np.float64)
        qd = self.state_0.body_qd.numpy().astype(np.float64)  # (linear, angular), both world frame
        rot = quat_matrices(q[:, 3:7])
        return from_peer(q[:, :3]), rot_from_peer(rot), from_peer(qd[:, :3]), from_peer(qd[:, 3:6])

    def contact_count(self):
        count = getattr(self.contacts, "rigid_contact_count", None)
        return int(count.numpy()[0]) if count is not None else ""


ENGINE_CLASSES = {"warp_sim": WarpSimEngine, "mujoco": MuJoCoEngine, "pybullet": PyBulletEngine,
                  "newton": NewtonEngine}


def make_engine(name: str, spec: Spec, hfield_spacing: float, hfield_margin: float) -> Engine:
    if name == "warp_sim-1t":
        engine = WarpSimEngine(spec, hfield_spacing, hfield_margin, threads=1)
        engine.name = name
        return engine
    return ENGINE_CLASSES[name](spec, hfield_spacing, hfield_margin)


def available(name: str) -> str:
    """'' if the engine can be imported, else why not."""
    module = MODULE[name]
    if importlib.util.find_spec(module) is None:
        return f"not installed (pip install {module}, or pip install -e '.[peers]')"
    try:
        __import__(module)
    except Exception as exc:  # an installed but broken package is reported, not fatal
        return f"import failed: {type(exc).__name__}: {exc}"[:200]
    return ""


# Measurements ----------------------------------------------------------------------------------
