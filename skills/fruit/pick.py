"""The fruit-picking mission's skills (thesis section 1.3, DemoV1 and DemoV2).

* ``fruit_setup``: which basket this run drops into (mission param or ``fruit.basket``).
* ``detect_fruit``: from each of ``fruit.look_poses`` in turn, detect the fruit in the
  wrist camera's frames, fit each one's barycentre (Algorithm 1.2), score them
  (Algorithm 1.3) and choose the best; ``count`` 0 when no fruit is left in view. Fruit
  skipped as unreachable (``fruit.attempts`` failed picks) are left out.
* ``click_fruit``: DemoV1: the operator's pixel -> depth -> surface point -> barycentre.
* ``pick_fruit``: the chosen fruit: Algorithm 1.1's candidates round its barycentre,
  the one at ``grasp.pick_fraction`` of those with collision-free IK; plan to its
  pre-grasp (back along the approach), open, straight-line approach, close, pull straight
  back (the magnet lets go), lift; the other fruit, the plant's trunk and the basket on
  the robot are planning obstacles.
* ``drop_fruit``: into the basket on the robot (the ``robot_basket.drop_poses`` in turn) or, with
  the base at the marker-tagged basket, above its release point; open; retract.
* ``fruit_give_up``: after a failed pick: let go of anything held, count the failure
  against that fruit (skipped once it reaches ``fruit.attempts``), back to the first
  look pose.
* ``fruit_summary``: how many were picked; fails naming the fruit left on the plant.

World model (``ctx.world``): ``fruit.target`` (the chosen :class:`FruitEstimate`),
``fruit.failures`` ([centre, count, last reason] per fruit that failed), ``fruit.picked``
(count) and ``fruit.detector``. Events: ``fruit_detections`` (view, every detection with
its label, confidence, z, score, barycentre in map, and ``chosen``), ``fruit_grasp``
(theta, candidates kept, chosen index), ``fruit_picked``, ``fruit_dropped``,
``fruit_skipped``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
    wait_goal,
)
from mmexec.skills.fruit.perception import (
    FruitEstimate,
    GraspPointError,
    PerceptionSettings,
    click_estimate,
    estimate_fruit,
    merge_estimates,
)
from mmexec.skills.fruit.profile import FruitProfile, fruit_profile
from mmexec.skills.manipulation import CANCELLED, PlanResult
from mmexec.skills.manipulation.arm import (
    GRIPPER_TIMEOUT,
    ArmWorkspace,
    T_armbase_map,
    arm_settings,
    execute,
    holding,
    ik_seeds,
    measured_joints,
    move_named,
    off_tick,
    planned,
    release,
    with_arm_status,
    workspace,
)
from mmexec.skills.manipulation.candidates import CandidateConfig, grasp_candidates, select_grasp
from mmexec.skills.perception.detect import markers, next_frame
from mmexec.skills.perception.detector import ColourBlobDetector, ObjectDetector
from mmexec.skills.perception.priority import choose_target
from mmexec.skills.poses import arm_joints

__all__ = ["click_fruit", "detect_fruit", "drop_fruit", "fruit_give_up", "fruit_setup", "fruit_summary", "pick_fruit"]

log = logging.getLogger(__name__)

WORLD_TARGET = "fruit.target"
WORLD_FAILURES = "fruit.failures"
WORLD_PICKED = "fruit.picked"
WORLD_DETECTOR = "fruit.detector"
WORLD_OTHERS = "fruit.others"  #: every fruit seen and not picked yet: planning obstacles
WORLD_LAST_COUNT = "fruit.last_count"
WORLD_LOST = "fruit.lost"
#: planning-scene names this package adds (cleared before each plan)
_PREFIX = "fruit:"
#: clock seconds the fruit is given to fall after the gripper opens
DROP_WAIT = 0.6
#: camera frames a look waits for at most [clock s]
FRAME_TIMEOUT = 2.0


def _settings(prof: FruitProfile) -> PerceptionSettings:
    return PerceptionSettings(max_depth=prof.max_depth, radius_range=tuple(prof.radius_range),  # type: ignore[arg-type]
                              min_confidence=prof.min_confidence, min_height=prof.min_height)


def fruit_detector(ctx: SkillContext) -> ObjectDetector:
    """The run's object detector (``fruit.detector`` in the world model; the classical
    colour/shape backend unless something put another one there)."""
    det = ctx.world.get(WORLD_DETECTOR)
    if det is None:
        det = ColourBlobDetector()
        ctx.world[WORLD_DETECTOR] = det
    return det


def _rng(ctx: SkillContext) -> np.random.Generator:
    """A generator per call, seeded from the clock: a seeded sim run reproduces."""
    return np.random.default_rng(round(ctx.clock.now() * 1000))


def _failures(ctx: SkillContext) -> list[list[Any]]:
    return ctx.world.setdefault(WORLD_FAILURES, [])


def _skipped(ctx: SkillContext, prof: FruitProfile) -> list[np.ndarray]:
    return [np.asarray(c) for c, n, _ in _failures(ctx) if n >= prof.attempts]


# --------------------------------------------------------------------------- setup


@skill("fruit_setup", params=[Param("basket", str, default="", doc="robot or marker; empty: profile fruit.basket")],
       outputs=[Output("basket", str, doc="the basket this run drops into: robot or marker"),
                Output("marker", int, doc="the marker id of the tagged basket"),
                Output("distance", float, doc="stand-off [m] from the tagged basket's marker")])
def fruit_setup(ctx: SkillContext, basket: str = "") -> SkillGen:
    """Resolve the run's basket (mission param, else the profile) and reset the counts."""
    prof = fruit_profile(ctx)
    mode = basket or prof.basket
    if mode not in ("robot", "marker"):
        raise SkillFailure(FailureKind.PRECONDITION, f"fruit_setup: basket must be 'robot' or 'marker', got {mode!r}")
    ctx.world[WORLD_PICKED] = 0
    ctx.world[WORLD_FAILURES] = []
    ctx.world[WORLD_LAST_COUNT] = None
    ctx.world[WORLD_LOST] = 0
    ctx.world[WORLD_OTHERS] = []
    ctx.world.pop(WORLD_TARGET, None)
    yield
    return {"basket": mode, "marker": prof.marker_basket.marker, "distance": prof.marker_basket.distance}


# --------------------------------------------------------------------------- perception


def _frames(ctx: SkillContext, n: int) -> SkillGen:
    """``n`` camera frames, one per tick (SkillFailure EXECUTION when none comes within
    :data:`FRAME_TIMEOUT`)."""
    cam = ctx.robot.camera
    if cam is None:
        raise SkillFailure(FailureKind.PRECONDITION, "the robot has no camera")
    out = []
    while len(out) < n:
        out.append((yield from next_frame(ctx, cam, FRAME_TIMEOUT)))
        yield
    return out


def _wait(ctx: SkillContext, seconds: float) -> SkillGen:
    end = ctx.clock.now() + seconds
    while ctx.clock.now() < end:
        yield
    return None


def _choose(ctx: SkillContext, prof: FruitProfile, found: list[FruitEstimate], view: str) -> FruitEstimate | None:
    skipped = _skipped(ctx, prof)
    cands = [e for e in found if all(np.linalg.norm(e.centre - s) >= prof.same_fruit for s in skipped)]
    k = choose_target([e.confidence for e in cands], [e.z for e in cands], prof.max_depth) if cands else None
    known: list[FruitEstimate] = ctx.world.setdefault(WORLD_OTHERS, [])
    for e in found:  # remember what each look saw: a fruit out of this view is still an obstacle
        j = next((i for i, o in enumerate(known) if np.linalg.norm(o.centre - e.centre) < prof.same_fruit), None)
        if j is None:
            known.append(e)
        else:
            known[j] = e
    ctx.emit("fruit_detections", view=view, detections=[e.to_json() for e in cands], chosen=k,
             skipped=len(found) - len(cands), node=ctx.node_path)
    return None if k is None else cands[k]


@skill("detect_fruit", params=[Param("look_poses", list, doc="named arm poses to look from (default: fruit.look_poses)")],
       outputs=[Output("count", int, doc="fruit seen in the view used (0: none left)"),
                Output("label", str, doc="the chosen fruit's class"),
                Output("score", float, doc="its priority score")],
       needs=("arm", "camera"))
def detect_fruit(ctx: SkillContext, look_poses: list[str] | None = None) -> SkillGen:
    """Look from each look pose until fruit are seen; choose the highest-priority one
    (Algorithm 1.3) as ``fruit.target``. Success with ``count`` 0 when none is seen from
    any of them."""
    prof = fruit_profile(ctx)
    settings = _settings(prof)
    ctx.world.pop(WORLD_TARGET, None)
    det = fruit_detector(ctx)
    for name in look_poses or prof.look_poses:
        yield from with_arm_status(ctx, move_named(ctx, str(name)), f"arm to {name}")
        yield from _wait(ctx, prof.settle)
        rng = _rng(ctx)
        views = []
        for _ in range(prof.frames):  # one frame's perception per tick (2-23 ms of CPU each)
            frames = yield from _frames(ctx, 1)
            views.append(estimate_fruit(frames[0], det, settings, rng))
        found = merge_estimates(views, prof.same_fruit)
        target = _choose(ctx, prof, found, str(name))
        if target is not None:
            ctx.world[WORLD_TARGET] = target
            ctx.world[WORLD_LAST_COUNT] = len(found)
            return {"count": len(found), "label": target.label, "score": target.score}
    ctx.world[WORLD_LAST_COUNT] = 0
    return {"count": 0, "label": "", "score": 0.0}


@skill("click_fruit", params=[Param("pixel", list, required=True, doc="[u, v] pixel the operator clicked")],
       outputs=[Output("label", str, doc="'clicked'"), Output("radius", float, doc="fitted radius [m]")],
       needs=("camera",))
def click_fruit(ctx: SkillContext, pixel: list[float]) -> SkillGen:
    """DemoV1: the fruit under the operator's pixel (the current view) becomes
    ``fruit.target``: depth at the pixel, surface point, barycentre along the ray (or the
    sphere fitted round it)."""
    prof = fruit_profile(ctx)
    if len(pixel) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in pixel):
        raise SkillFailure(FailureKind.PRECONDITION, f"click_fruit: pixel must be [u, v], got {pixel!r}")
    frames = yield from _frames(ctx, 1)
    f = frames[0]
    try:
        centre, radius, how = click_estimate(f, (float(pixel[0]), float(pixel[1])), _settings(prof), _rng(ctx))
    except GraspPointError as e:
        raise SkillFailure(FailureKind.PRECONDITION, f"click_fruit: no depth at pixel {pixel}: {e}") from None
    T = np.asarray(f.T_map_base) @ np.asarray(f.T_base_camera)
    z = float((np.linalg.inv(T) @ np.append(centre, 1.0))[2])
    est = FruitEstimate("clicked", 1.0, (int(pixel[0]), int(pixel[1]), 1, 1), centre, np.zeros(3), radius, z, 1.0, 0, 1.0)
    ctx.world[WORLD_TARGET] = est
    ctx.emit("fruit_clicked", pixel=[float(pixel[0]), float(pixel[1])], centre=[round(float(v), 4) for v in centre],
             radius=round(radius, 4), method=how, node=ctx.node_path)
    return {"label": "clicked", "radius": radius}


# --------------------------------------------------------------------------- planning scene


def _box_T(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _scene_setup(ctx: SkillContext, ws: ArmWorkspace, prof: FruitProfile, T_am: np.ndarray,
                 others: list[FruitEstimate], target: FruitEstimate | None) -> Callable[[], None]:
    """A worker-thread job: the static boxes, the basket on the robot and the other fruit
    (and the target, when given) as planning obstacles, in the arm base frame."""
    boxes = ctx.robot.scene
    arm = ctx.robot.arm
    assert arm is not None
    T_armbase_base = np.linalg.inv(np.asarray(arm.mount, dtype=float))
    bx = prof.robot_basket.box
    clear = prof.grasp.clearance

    def job() -> None:
        ws.scene.set_static_boxes(boxes, T_am)
        for name in [n for n in ws.scene.items if n.startswith(_PREFIX)]:
            ws.scene.remove_item(name)
        ws.scene.add_item(_PREFIX + "robot_basket", (bx[3], bx[4], bx[5]), T_armbase_base @ _box_T(*bx[:3]))
        for i, e in enumerate(others):
            s = 2.0 * (e.radius + clear)
            ws.scene.add_item(f"{_PREFIX}other_{i}", (s, s, s), T_am @ _box_T(*e.centre))
        if target is not None:
            s = 2.0 * target.radius
            ws.scene.add_item(_PREFIX + "target", (s, s, s), T_am @ _box_T(*target.centre))

    return job


# --------------------------------------------------------------------------- pick


def _target(ctx: SkillContext) -> FruitEstimate:
    t = ctx.world.get(WORLD_TARGET)
    if not isinstance(t, FruitEstimate):
        raise SkillFailure(FailureKind.PRECONDITION, "pick_fruit: no fruit chosen (run detect_fruit or click_fruit first)")
    return t


@skill("pick_fruit", params=[Param("time_limit", float, unit="s", doc="planning time per attempt (default: profile)")],
       outputs=[Output("theta", float, doc="the chosen candidate's theta [rad]")],
       needs=("arm", "gripper"))
def pick_fruit(ctx: SkillContext, time_limit: float | None = None) -> SkillGen:
    """Grasp the chosen fruit (Algorithm 1.1), pull it off its branch and lift it."""
    return (yield from with_arm_status(ctx, _pick(ctx, time_limit), "pick fruit"))


def _pick(ctx: SkillContext, time_limit: float | None) -> SkillGen:
    prof, arm = fruit_profile(ctx), arm_settings(ctx)
    target = _target(ctx)
    ws = workspace(ctx)
    cfg = ws.config(None, time_limit, None)
    T_am = T_armbase_map(ctx)
    p = (T_am @ np.append(target.centre, 1.0))[:3]
    g = prof.grasp
    cc = CandidateConfig(count=g.count, theta_range=tuple(g.theta_range), distance=g.distance,  # type: ignore[arg-type]
                         pre_grasp_distance=g.pre_grasp, pick_fraction=g.pick_fraction)
    try:
        cands = grasp_candidates(p, ws.kin.approach_axis, cc)
    except ValueError as e:
        raise SkillFailure(FailureKind.PLANNING, f"pick_fruit: {e}") from None
    others = [e for e in ctx.world.get(WORLD_OTHERS, []) if np.linalg.norm(e.centre - target.centre) > prof.same_fruit]
    setup = _scene_setup(ctx, ws, prof, T_am, others, target)
    q0 = measured_joints(ctx)
    seeds = ik_seeds(ctx, ws, cands.poses[len(cands) // 2])
    chosen: list[Any] = []

    def choose_and_plan() -> PlanResult:
        setup()
        ws.scene.remove_item(_PREFIX + "target")  # the pads close round it: not an obstacle at the grasp

        def reachable(T: np.ndarray) -> np.ndarray | None:
            for s in seeds:
                q = ws.kin.ik(T, s, attempts=2, is_valid=ws.scene.is_valid)
                if q is not None:
                    return q
            return None

        choice = select_grasp(cands, reachable, g.pick_fraction)
        if choice is None:
            return PlanResult(False, f"no collision-free IK for any of the {len(cands)} grasp candidates", 0.0)
        # the thesis's choice first; when its pre-grasp cannot be reached, the next ones in list order
        order = list(choice.feasible)
        k = order.index(choice.index)
        res = PlanResult(False, "no candidate", 0.0)
        s2 = 2.0 * target.radius
        for i in order[k:] + order[:k][::-1]:
            ws.scene.add_item(_PREFIX + "target", (s2, s2, s2), T_am @ _box_T(*target.centre))
            res = ws.planner.plan_to_pose(q0, cands.pre_grasps[i], ik_seeds=seeds, config=cfg)
            ws.scene.remove_item(_PREFIX + "target")
            if res.success:
                chosen.append((i, choice))
                break
            if res.reason == CANCELLED:
                break
        return res

    gr = ctx.robot.gripper
    assert gr is not None
    opening = gr.open(force=arm.grasp_force)
    res = yield from off_tick(ctx, ws, choose_and_plan)
    pre = planned(ctx, res, "fruit pre-grasp")
    i, choice = chosen[0]
    ctx.emit("fruit_grasp", theta=round(float(cands.thetas[i]), 4), thesis_choice=choice.index, used=i,
             feasible=len(choice.feasible), candidates=len(cands), label=target.label,
             centre=[round(float(v), 4) for v in target.centre], node=ctx.node_path)
    yield from wait_goal(ctx, opening, timeout=GRIPPER_TIMEOUT)
    yield from execute(ctx, pre, "fruit pre-grasp")
    a = cands.approach[i]

    def line(T_goal: np.ndarray) -> Callable[[], PlanResult]:
        q = measured_joints(ctx)
        return lambda: ws.planner.cartesian_path(q, T_goal, config=cfg)

    res = yield from off_tick(ctx, ws, line(cands.poses[i]))
    yield from execute(ctx, planned(ctx, res, "fruit approach"), "fruit approach")
    yield from wait_goal(ctx, gr.close(force=arm.grasp_force), timeout=GRIPPER_TIMEOUT)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.POSTCONDITION, f"nothing held after closing on the {target.label} ({why})")
    T_pull = cands.poses[i].copy()
    T_pull[:3, 3] -= g.pull * a
    res = yield from off_tick(ctx, ws, line(T_pull))
    yield from execute(ctx, planned(ctx, res, "fruit pull"), "fruit pull")
    if g.lift > 0:
        T_lift = T_pull.copy()
        T_lift[2, 3] += g.lift
        res = yield from off_tick(ctx, ws, line(T_lift))
        if res.success:
            yield from execute(ctx, planned(ctx, res, "fruit lift"), "fruit lift")
        else:
            log.info("fruit lift: %s; leaving from the pull's end", res.reason)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.POSTCONDITION, f"the {target.label} was lost while pulling it off ({why})")
    ctx.emit("fruit_picked", label=target.label, centre=[round(float(v), 4) for v in target.centre],
             node=ctx.node_path)
    ctx.world[WORLD_OTHERS] = [e for e in ctx.world.get(WORLD_OTHERS, [])
                               if np.linalg.norm(e.centre - target.centre) >= prof.same_fruit]
    return {"theta": float(cands.thetas[i])}


# --------------------------------------------------------------------------- drop


def _release_pose(ctx: SkillContext, prof: FruitProfile) -> np.ndarray:
    """Tool pose in map above the tagged basket's release point, tool axis down."""
    mid = prof.marker_basket.marker
    est = markers(ctx).get(mid)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"drop_fruit: no estimate of the basket's marker {mid} (find it first)")
    pt = est.T_map_marker @ np.append(np.asarray(prof.marker_basket.release, dtype=float), 1.0)
    base = ctx.robot.base
    bx, by = (base.state().pose.x, base.state().pose.y) if base is not None else (0.0, 0.0)
    fwd = np.array([pt[0] - bx, pt[1] - by, 0.0])
    fwd = fwd / max(float(np.linalg.norm(fwd)), 1e-9)
    z = np.array([0.0, 0.0, -1.0])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = fwd, np.cross(z, fwd), z, pt[:3]
    return T


@skill("drop_fruit", params=[Param("basket", str, default="robot", choices=("robot", "marker"),
                                   doc="the basket on the robot, or the marker-tagged one the base stands at")],
       needs=("arm", "gripper"))
def drop_fruit(ctx: SkillContext, basket: str = "robot") -> SkillGen:
    """Carry the held fruit above the basket, open, and leave the arm clear of it."""
    return (yield from with_arm_status(ctx, _drop(ctx, basket), f"drop fruit ({basket} basket)"))


def _drop(ctx: SkillContext, basket: str) -> SkillGen:
    prof, arm = fruit_profile(ctx), arm_settings(ctx)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.PRECONDITION, f"drop_fruit: nothing held ({why})")
    ws = workspace(ctx)
    T_am = T_armbase_map(ctx)
    setup = _scene_setup(ctx, ws, prof, T_am, [], None)
    if basket == "robot":
        yield from off_tick(ctx, ws, setup)
        poses = prof.robot_basket.drop_poses
        yield from move_named(ctx, poses[int(ctx.world.get(WORLD_PICKED, 0)) % len(poses)])
    else:
        T_rel = T_am @ _release_pose(ctx, prof)
        q0 = measured_joints(ctx)
        seeds = ik_seeds(ctx, ws, T_rel)
        cfg = ws.config()

        def plan() -> PlanResult:
            setup()
            return ws.planner.plan_to_pose(q0, T_rel, free_approach_rotation=True, ik_seeds=seeds, config=cfg)

        res = yield from off_tick(ctx, ws, plan)
        yield from execute(ctx, planned(ctx, res, "fruit release pose"), "fruit release pose")
    yield from release(ctx, arm.grasp_force)
    yield from _wait(ctx, DROP_WAIT)
    ctx.world[WORLD_PICKED] = int(ctx.world.get(WORLD_PICKED, 0)) + 1
    ctx.emit("fruit_dropped", basket=basket, picked=ctx.world[WORLD_PICKED], node=ctx.node_path)
    ctx.world.pop(WORLD_TARGET, None)
    return {}


# --------------------------------------------------------------------------- failures


@skill("fruit_give_up", params=[Param("reason", str, default="", doc="why the pick failed (for the report)")],
       outputs=[Output("skipped", bool, doc="the fruit has now failed fruit.attempts times and is skipped")],
       needs=("arm", "gripper"))
def fruit_give_up(ctx: SkillContext, reason: str = "") -> SkillGen:
    """After a failed pick or drop: open the gripper (anything held falls), count the
    failure against the chosen fruit, and return the arm to the first look pose."""
    prof, arm = fruit_profile(ctx), arm_settings(ctx)
    g = ctx.robot.gripper
    target = ctx.world.pop(WORLD_TARGET, None)
    if g is not None:
        if holding(ctx, arm.min_held_width)[0]:
            # it came off the plant but never reached a basket: it is lost (dropped here)
            ctx.world[WORLD_LOST] = int(ctx.world.get(WORLD_LOST, 0)) + 1
            ctx.emit("fruit_lost", label=getattr(target, "label", ""), reason=reason, node=ctx.node_path)
            target = None
        yield from release(ctx, arm.grasp_force)
    skipped = False
    if isinstance(target, FruitEstimate):
        fails = _failures(ctx)
        row = next((r for r in fails if np.linalg.norm(np.asarray(r[0]) - target.centre) < prof.same_fruit), None)
        if row is None:
            row = [target.centre.tolist(), 0, ""]
            fails.append(row)
        row[1] += 1
        row[2] = reason
        skipped = row[1] >= prof.attempts
        if skipped:
            ctx.emit("fruit_skipped", label=target.label, centre=[round(float(v), 4) for v in target.centre],
                     attempts=row[1], reason=reason, node=ctx.node_path)
    try:
        arm_joints(ctx.profile, prof.look_poses[0])
        yield from move_named(ctx, prof.look_poses[0])
    except SkillFailure as e:  # the arm may be where it cannot plan from: stop there (safe) and report
        log.warning("fruit_give_up: arm not back at %s: %s", prof.look_poses[0], e.reason)
        ctx.emit("report", message=f"arm not back at {prof.look_poses[0]}: {e.reason}", level="warning",
                 node=ctx.node_path)
    return {"skipped": skipped}


@skill("fruit_summary", params=[Param("stopped", str, default="", doc="why the picking loop ended (last_failure)")],
       outputs=[Output("picked", int, doc="fruit dropped into a basket")])
def fruit_summary(ctx: SkillContext, stopped: str = "") -> SkillGen:
    """Success when the last look saw no fruit left and every fruit seen was picked;
    FAILURE (EXECUTION) when the loop stopped before (``stopped`` says why), or naming the
    fruit left on the plant (skipped after ``fruit.attempts`` failed picks) and why."""
    prof = fruit_profile(ctx)
    picked = int(ctx.world.get(WORLD_PICKED, 0))
    left = [r for r in _failures(ctx) if r[1] >= prof.attempts]
    lost = int(ctx.world.get(WORLD_LOST, 0))
    ctx.emit("fruit_summary", picked=picked, skipped=len(left), lost=lost, node=ctx.node_path)
    yield
    if lost:
        raise SkillFailure(FailureKind.EXECUTION, f"{lost} fruit lost on the way to the basket ({picked} picked)")
    if ctx.world.get(WORLD_LAST_COUNT) != 0:
        raise SkillFailure(FailureKind.EXECUTION, f"picking stopped before the plant was cleared ({picked} picked): "
                                                  f"{stopped or 'no look finished'}")
    if left:
        what = "; ".join(f"at ({r[0][0]:.2f}, {r[0][1]:.2f}, {r[0][2]:.2f}): {r[2]}" for r in left)
        raise SkillFailure(FailureKind.EXECUTION, f"{len(left)} fruit not picked after {prof.attempts} attempts "
                                                  f"each ({picked} picked): {what}")
    return {"picked": picked}
