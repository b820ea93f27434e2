"""Push robustness of the balance controller, closed loop vs open loop, on a standing robot.

For each push direction (torso, 0.1 s, at 0.5 s of a 3 s stand), the largest force the robot
survives (torso tilt stays under 60 degrees) is found by bisection, open loop and with the
balance controller, on the nominal model and with the servo stiffness +-20 % and the link
masses +-10 % (the goals are always computed for the nominal model: the mismatch is the
point).  Prints a table and writes benchmarks/results/balance_push_ROBOT.json.

    python benchmarks/balance_push.py --robot op3_like
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import RESULTS_DIR, print_table, write_json  # noqa: E402

from motok_robot.feasibility import BalanceConfig, BalanceController, build_plan  # noqa: E402
from motok_robot.feasibility.physics import ServoPhysics, servo_model  # noqa: E402
from motok_robot.robots import load  # noqa: E402
from motok_robot.robots.index import index_robot  # noqa: E402
from motok_robot.sim import synthetic as S  # noqa: E402
from motok_robot.sim.trajectory import RobotTrajectory  # noqa: E402
from motok_robot.sim.validate import validate_trajectory  # noqa: E402

FPS = 20.0
DIRECTIONS = {"forward": (1.0, 0.0), "backward": (-1.0, 0.0), "left": (0.0, 1.0), "right": (0.0, -1.0)}
VARIANTS = {"nominal": (1.0, 1.0), "stiffness -20%": (0.8, 1.0), "stiffness +20%": (1.2, 1.0),
            "mass -10%": (1.0, 0.9), "mass +10%": (1.0, 1.1)}


def varied_model(index, stiffness: float, mass: float):
    model, _ = servo_model(index)
    model.actuator_gainprm[:, 0] *= stiffness
    model.actuator_biasprm[:, 1] *= stiffness
    model.body_mass[:] *= mass
    model.body_inertia[:] *= mass
    return model


def max_tilt(index, model, goals, plan, force, direction, balance: bool) -> float:
    qpos = S.standing(index, 3.0, FPS)
    physics = ServoPhysics(index, model=model)
    datas = physics.new_datas(physics.initial_state(qpos[0], np.zeros(index.model.nv), goals[0])[None])
    controller = BalanceController(plan, index.joint_range) if balance else None
    tilt = [0.0]

    def push(step, b, data):
        t = step * physics.dt
        on = 0.5 <= t < 0.6
        data.xfrc_applied[index.root_body, :2] = (force * direction[0], force * direction[1]) if on else (0.0, 0.0)

    def watch(tick, datas):
        up = datas[0].xmat[index.root_body].reshape(3, 3)[:, 2]
        tilt[0] = max(tilt[0], float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0)))))

    physics.advance(datas, goals, FPS, 0, int(round(3.0 / physics.tick_s)), controller, on_tick=watch, perturb=push)
    return tilt[0]


def survivable(index, model, goals, plan, direction, balance, high=40.0, iterations=7) -> float:
    """Largest push (N, 0.1 s) with the tilt under 60 degrees, by bisection on [0, high]."""
    low = 0.0
    if max_tilt(index, model, goals, plan, 0.0, direction, balance) > 60.0:
        return 0.0
    for _ in range(iterations):
        mid = 0.5 * (low + high)
        if max_tilt(index, model, goals, plan, mid, direction, balance) > 60.0:
            high = mid
        else:
            low = mid
    return low


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="op3_like")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    index = index_robot(load(args.robot))
    qpos = S.standing(index, 3.0, FPS)
    goals = validate_trajectory(RobotTrajectory(qpos, FPS, index.joint_names, index.name), index, plots=False,
                                balance=BalanceConfig(enabled=False)).goals
    plan = build_plan(index, qpos, FPS, np.ones((qpos.shape[0], 2), bool), BalanceConfig())
    rows = []
    start = time.perf_counter()
    for variant, (k, m) in VARIANTS.items():
        model = varied_model(index, k, m)
        for name, direction in DIRECTIONS.items():
            row = {"variant": variant, "direction": name}
            for balance in (False, True):
                row["closed_loop_n" if balance else "open_loop_n"] = survivable(index, model, goals, plan, direction, balance)
            row["ratio"] = row["closed_loop_n"] / row["open_loop_n"] if row["open_loop_n"] > 0 else None
            rows.append(row)
            print(f"{variant:15s} {name:8s} open {row['open_loop_n']:5.1f} N  closed {row['closed_loop_n']:5.1f} N",
                  flush=True)
    print_table(rows, ["variant", "direction", "open_loop_n", "closed_loop_n", "ratio"],
                title=f"largest 0.1 s torso push survived ({args.robot}, standing)")
    out = Path(args.out) if args.out else RESULTS_DIR / f"balance_push_{args.robot}.json"
    write_json(out, {"robot": args.robot, "push_s": 0.1, "fall_tilt_deg": 60.0, "balance": BalanceConfig().to_dict(),
                     "rows": rows, "wall_s": time.perf_counter() - start})
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
