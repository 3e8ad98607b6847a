"""rcssservermj with a trial's T1, for t1-trial: the server's own main,
with its robot loader wrapped so that the T1's MuJoCo spec is edited before
the robot joins. `warm_up` imports what the server needs without starting
one; `run` starts it (it never returns). The edits (all optional, factors of
the stock T1's):

  thigh, shank   the segment's length (hip to knee, knee to ankle), with
                 its collision capsule; the torso spawns higher or lower
                 by what the legs gained or lost
  foot           the foot's length (its collision box), about the ankle
  trunk_mass     the torso's mass and inertia
  friction       the feet's sliding friction
  motor          every joint's torque range (the motors' strength)
"""

import sys

import rcsssmj.resources.spec_provider as provider

SIDES = ("Left", "Right")


def edit(spec, e):
    thigh, shank = float(e.get("thigh", 1.0)), float(e.get("shank", 1.0))
    foot, mass = float(e.get("foot", 1.0)), float(e.get("trunk_mass", 1.0))
    friction, motor = float(e.get("friction", 1.0)), float(e.get("motor", 1.0))
    gained = 0.0
    for side in SIDES:
        low = side.lower()
        hip_yaw, shank_body = spec.body(f"Hip_Yaw_{side}"), spec.body(f"Shank_{side}")
        before = -(hip_yaw.pos[2] + shank_body.pos[2])
        hip_yaw.pos[2] *= thigh
        shank_body.pos[:] = shank_body.pos * thigh
        capsule = spec.geom(f"{low}_thigh")
        capsule.size[1] *= thigh
        capsule.pos[2] *= thigh
        ankle = spec.body(f"Ankle_Cross_{side}")
        before += -ankle.pos[2]
        ankle.pos[2] *= shank
        calf = spec.geom(f"{low}_calf")
        calf.size[1] *= shank
        calf.pos[2] *= shank
        after = -(hip_yaw.pos[2] + shank_body.pos[2] + ankle.pos[2])
        gained = after - before
        sole = spec.geom(f"{low}_foot")
        sole.size[0] *= foot
        sole.pos[0] *= foot
        sole.friction[0] *= friction
    torso = spec.body("torso")
    torso.pos[2] += gained
    torso.mass *= mass
    torso.inertia[:] = torso.inertia * mass
    if motor != 1.0:
        for j in spec.joints:
            j.actfrcrange[:] = j.actfrcrange * motor
    return spec


def warm_up():
    """Imports the server's modules (but not its main, which sets up logging
    into the working directory when imported) and compiles the stock T1 once,
    which fills MuJoCo's cache of processed meshes: a trial's server, forked
    from here, compiles its T1 in a third of the time."""
    import mujoco  # noqa: F401
    import rcsssmj.games.soccer.server.soccer_server  # noqa: F401
    import rcsssmj.games.soccer.sim.soccer_referee  # noqa: F401
    import rcsssmj.games.soccer.sim.soccer_sim  # noqa: F401
    import rcsssmj.games.soccer.soccer_fields  # noqa: F401
    import rcsssmj.games.soccer.soccer_rules  # noqa: F401

    provider.ModelSpecProvider().load_robot_spec("T1").compile()


def run(args, edits, sockets):
    """Runs the server with `args` (rcssservermj's own), its T1 edited by
    `edits`, until it is killed. Its listeners adopt `sockets` (listening
    sockets by port, made by the caller) instead of binding their ports."""
    from rcsssmj.server.communication.tcp_connection_listener import TCPConnectionListener

    bind = TCPConnectionListener.bind

    def adopt(self):
        if self._sock is None and self.port in sockets:
            self._sock = sockets[self.port]
        bind(self)

    TCPConnectionListener.bind = adopt
    load = provider.ModelSpecProvider.load_robot_spec

    def load_edited(self, robot, variant=None):
        spec = load(self, robot, variant)
        return edit(spec, edits) if robot == "T1" and spec is not None else spec

    provider.ModelSpecProvider.load_robot_spec = load_edited
    from rcsssmj.__main__ import soccer_sim

    sys.argv = ["rcssservermj", *args]
    soccer_sim()
