#!/usr/bin/env python3
"""Runs real cube tosses in an outside engine (MuJoCo or PyBullet) for `handblocks bench tosses`.

Driven by the bench (bench/src/tosses.rs, `outside`), never by hand: it reads one job (JSON) on
stdin, simulates every toss of it from its first state, writes each toss's path to the job's
`paths` file and prints one JSON line: the engine, its version and the nanoseconds spent in the
engine's own loop. The bench scores the paths with the same code as its own models.

Why a path file and not JSON: 400 tosses of ~100 samples are 40,000 poses; raw little-endian
float64 (x, y, z, qw, qx, qy, qz per sample, tosses one after another, each `steps + 1`
samples, the first its given state) is read back exactly and at once.

Frame: z up, the board the plane z = 0 (the bench takes its measured offset off), gravity
9.81 m/s^2 down z. A toss's spin is in the cube's own frame (the data's, and MuJoCo's free joint's).

What is timed, and only that: one call per sample, the engine doing its substeps inside it
(MuJoCo's `mj_step(nstep=substeps)`, PyBullet's `stepSimulation` with `numSubSteps`), the pose
read outside the timed span; less, per call, the binding's floor (a timed call that does no
work: `mj_version`, `getNumBodies`), so that the figure is the engine's, not Python's. MuJoCo's
`rollout` was not used: a rollout call costs ~250 us of set-up, 40 % of a 100-sample toss at
one substep.
"""

import json
import math
import sys
import time


def dampratio_of(restitution):
    """The damping ratio of a linear spring-damper whose bounce keeps `restitution` of the
    speed: e = exp(-z pi / sqrt(1 - z^2)); e = 0 is critical damping (1)."""
    if restitution <= 0.0:
        return 1.0
    ln = math.log(min(restitution, 0.999))
    return -ln / math.sqrt(math.pi ** 2 + ln ** 2)


def run_mujoco(job):
    import mujoco
    import numpy as np

    h = job["half_width"]
    mass = job["mass"]
    dt = 1.0 / (job["rate_hz"] * job["substeps"])
    p = job["params"]
    if p.get("own_defaults"):
        contact = ""
    else:
        # MuJoCo has no restitution: its contact is a spring-damper (solref = time constant,
        # damping ratio); the bounce is the damping ratio of the wanted restitution. Friction
        # of a pair is the larger of the two geoms': both get the value.
        hz = p.get("contact_hz")
        timeconst = 0.02 if hz is None else 1.0 / (2.0 * math.pi * hz)
        contact = 'friction="{f} 0.005 0.0001" solref="{tc} {dr}"'.format(
            f=p["friction"], tc=timeconst, dr=dampratio_of(p["restitution"])
        )
    xml = """
<mujoco>
  <option timestep="{dt}" gravity="0 0 -{g}"/>
  <worldbody>
    <geom name="board" type="plane" size="0 0 1" {contact}/>
    <body name="cube">
      <freejoint/>
      <geom type="box" size="{h} {h} {h}" mass="{m}" {contact}/>
    </body>
  </worldbody>
</mujoco>""".format(dt=dt, g=job["gravity"], contact=contact, h=h, m=mass)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    sub = job["substeps"]
    calls = 0
    ns = 0
    out = []
    for toss in job["tosses"]:
        mujoco.mj_resetData(model, data)
        data.qpos[0:3] = toss["position"]
        data.qpos[3:7] = toss["quaternion"]
        data.qvel[0:3] = toss["velocity"]
        data.qvel[3:6] = toss["spin_body"]
        mujoco.mj_forward(model, data)
        path = np.empty((toss["steps"] + 1, 7))
        path[0] = data.qpos[0:7]
        for k in range(toss["steps"]):
            t0 = time.perf_counter_ns()
            mujoco.mj_step(model, data, nstep=sub)
            ns += time.perf_counter_ns() - t0
            path[k + 1] = data.qpos[0:7]
        calls += toss["steps"]
        out.append(path)
    return ns, calls, binding_floor_ns(mujoco.mj_version), out, mujoco.__version__


def binding_floor_ns(call, n=20000):
    """What one timed call into the engine's binding costs with no work in it (the median of
    `n` timed calls of `call`, as the step calls are timed): the bench takes it off every step
    call, so that Python's share is not counted as the engine's."""
    spans = []
    for _ in range(n):
        t0 = time.perf_counter_ns()
        call()
        spans.append(time.perf_counter_ns() - t0)
    spans.sort()
    return spans[n // 2]


def run_pybullet(job):
    import numpy as np
    import pybullet as pb

    h = job["half_width"]
    mass = job["mass"]
    p = job["params"]
    client = pb.connect(pb.DIRECT)
    pb.setGravity(0, 0, -job["gravity"], physicsClientId=client)
    # One call steps one sample: the engine's own substeps inside it.
    pb.setPhysicsEngineParameter(
        fixedTimeStep=1.0 / job["rate_hz"],
        numSubSteps=job["substeps"],
        physicsClientId=client,
    )
    board = pb.createMultiBody(
        0, pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client), physicsClientId=client
    )
    cube = pb.createMultiBody(
        mass,
        pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[h, h, h], physicsClientId=client),
        physicsClientId=client,
    )
    if not p.get("own_defaults"):
        # Bullet multiplies the two bodies' friction and restitution: the board's are 1, so a
        # pair's is the cube's. No air damping (Bullet's default is 0.04 per second).
        pb.changeDynamics(
            board, -1, lateralFriction=1.0, restitution=1.0, physicsClientId=client
        )
        extra = {}
        hz = p.get("contact_hz")
        if hz is not None:
            # A compliant contact: a spring of natural frequency hz on the cube's mass,
            # critically damped (the bounce is the restitution's, not the spring's).
            w = 2.0 * math.pi * hz
            extra = {"contactStiffness": mass * w * w, "contactDamping": 2.0 * mass * w}
        pb.changeDynamics(
            cube,
            -1,
            lateralFriction=p["friction"],
            restitution=p["restitution"],
            linearDamping=0.0,
            angularDamping=0.0,
            physicsClientId=client,
            **extra,
        )
    ns = 0
    calls = 0
    out = []
    for toss in job["tosses"]:
        w, x, y, z = toss["quaternion"]
        pb.resetBasePositionAndOrientation(
            cube, toss["position"], [x, y, z, w], physicsClientId=client
        )
        # PyBullet takes the spin in the world's frame.
        m = pb.getMatrixFromQuaternion([x, y, z, w])
        s = toss["spin_body"]
        spin = [m[3 * i] * s[0] + m[3 * i + 1] * s[1] + m[3 * i + 2] * s[2] for i in range(3)]
        pb.resetBaseVelocity(cube, toss["velocity"], spin, physicsClientId=client)
        path = np.empty((toss["steps"] + 1, 7))
        path[0, 0:3] = toss["position"]
        path[0, 3:7] = toss["quaternion"]
        for k in range(toss["steps"]):
            t0 = time.perf_counter_ns()
            pb.stepSimulation(physicsClientId=client)
            ns += time.perf_counter_ns() - t0
            pos, q = pb.getBasePositionAndOrientation(cube, physicsClientId=client)
            path[k + 1, 0:3] = pos
            path[k + 1, 3:7] = (q[3], q[0], q[1], q[2])
        calls += toss["steps"]
        out.append(path)
    floor = binding_floor_ns(lambda: pb.getNumBodies(physicsClientId=client))
    pb.disconnect(physicsClientId=client)
    version = "3.2.7"
    try:
        from importlib.metadata import version as v

        version = v("pybullet")
    except Exception:  # noqa: BLE001 - the version is only reported
        pass
    return ns, calls, floor, out, version


def main():
    job = json.load(sys.stdin)
    engine = job["engine"]
    if engine == "mujoco":
        ns, calls, floor, paths, version = run_mujoco(job)
    elif engine == "pybullet":
        ns, calls, floor, paths, version = run_pybullet(job)
    else:
        sys.exit("toss_engines.py: unknown engine {!r} (mujoco or pybullet)".format(engine))
    with open(job["paths"], "wb") as f:
        for path in paths:
            f.write(path.astype("<f8").tobytes())
    print(
        json.dumps(
            {
                "engine": engine,
                "version": version,
                "engine_ns": max(0, ns - calls * floor),
                "timed_ns": ns,
                "step_calls": calls,
                "binding_floor_ns": floor,
            }
        )
    )


if __name__ == "__main__":
    main()
