#!/usr/bin/env python3
"""MotionBenchMaker folders for VAMP, and VAMP's figures per family.

  mbm_vamp.py convert PROBLEMS_DIR OUT.json [ROBOT]
      Every <family>_<robot>/sceneNNNN.yaml + requestNNNN.yaml pair (as `embodied bench mbm` reads
      them, e.g. the output of `embodied bench mbm-generate`) as the problem file of VAMP's
      MotionBenchMaker loop (the layout of ../shared/peers/vamp/ur5-public.json: boxes by half
      extents, cylinders by length and radius, world poses with XYZ Euler angles and quaternions).
      ROBOT is one of VAMP's robots (ur5 by default; another, such as baxter with the
      MotionBenchMaker problems VAMP ships for it, takes its joints in the order of
      vamp.<robot>.joint_names(), so it needs the vamp module). Needs PyYAML, NumPy and SciPy. On
      the three public families it reproduces ur5-public.json to 1e-15.
  mbm_vamp.py summarize VAMP_OUT.json
      Per family: VAMP's planning and planning + simplification p50 / p95 / max and the share
      within 1 ms, from the output of ../shared/peers/vamp/vamp_run.py.
  mbm_vamp.py lengths PROBLEMS.json OUT.json [OURS.jsonl]
      Plans every valid problem of a VAMP problem file as vamp_run.py does (RRT-Connect, the
      Halton sampler reset per problem, then its simplification) and writes the joint-space
      length of each simplified path (Euclidean, as `bench mbm` measures a path of joints that do
      not wrap). Given the `--jsonl` file of a `bench mbm` run on the same problems, it prints per
      family both planners' median lengths and the median and mean of ours / VAMP's per problem.
      Needs the vamp module (the virtual environment compare-mbm makes).
"""
import glob
import json
import os
import sys

ARM = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
       "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]


def convert(root, out, robot="ur5"):
    import numpy as np
    import yaml
    from scipy.spatial.transform import Rotation

    joints = ARM
    if robot != "ur5":
        import vamp
        joints = list(getattr(vamp, robot).joint_names())
    problems = {}
    for family in sorted(os.listdir(root)):
        rows = []
        for scene_file in sorted(glob.glob(os.path.join(root, family, "scene*.yaml"))):
            index = int(os.path.basename(scene_file)[5:9])
            scene = yaml.safe_load(open(scene_file))
            request = yaml.safe_load(open(os.path.join(root, family, f"request{index:04d}.yaml")))
            row = {"sphere": [], "cylinder": [], "box": [], "index": index,
                   "problem": family.removesuffix(f"_{robot}")}
            for obj in scene["world"]["collision_objects"]:
                pose = obj.get("pose", {"position": [0, 0, 0], "orientation": [0, 0, 0, 1]})
                r_obj, t_obj = Rotation.from_quat(pose["orientation"]), np.array(pose["position"])
                for prim, prim_pose in zip(obj["primitives"], obj["primitive_poses"]):
                    r = r_obj * Rotation.from_quat(prim_pose["orientation"])
                    t = r_obj.apply(np.array(prim_pose["position"])) + t_obj
                    shape = {"name": obj["id"], "position": t.tolist(),
                             "orientation_euler_xyz": r.as_euler("xyz").tolist(),
                             "orientation_quat_xyzw": r.as_quat().tolist()}
                    size = prim["dimensions"]
                    if prim["type"] == "box":
                        shape["half_extents"] = [s / 2 for s in size]
                        row["box"].append(shape)
                    elif prim["type"] == "cylinder":
                        shape["length"], shape["radius"] = size[0], size[1]
                        row["cylinder"].append(shape)
                    elif prim["type"] == "sphere":
                        shape["radius"] = size[0]
                        row["sphere"].append(shape)
                    else:
                        sys.exit(f"{scene_file}: object {obj['id']}: no VAMP shape for a {prim['type']}")
            state = request["start_state"]["joint_state"]
            start = dict(zip(state["name"], state["position"]))
            goal = {c["joint_name"]: c["position"]
                    for c in request["goal_constraints"][0]["joint_constraints"]}
            row["start"] = [start[j] for j in joints]
            row["goals"] = [[goal[j] for j in joints]]
            row["valid"] = True
            rows.append(row)
        problems[family.removesuffix(f"_{robot}")] = rows
    json.dump({"robot": robot, "joints": joints, "problems": problems}, open(out, "w"))
    print({family: len(rows) for family, rows in problems.items()})


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, max(0, int(round(q * len(xs) + 0.5)) - 1))]


def summarize(path):
    rows = json.load(open(path))["problems"]
    families = sorted({r["family"] for r in rows})
    print(f"{'family':<18} {'valid':>5}  {'plan p50/p95/max us, <=1 ms':>34}  {'plan+simplify p50/p95/max us':>30}")
    for family in families + ["all"]:
        rs = [r for r in rows if r["valid"] and family in ("all", r["family"])]
        plan = [r["plan_us"] for r in rs if r.get("solved")]
        simp = [r["plan_simplify_us"] for r in rs if r.get("solved")]
        within = sum(t <= 1000 for t in plan) / len(rs)
        print(f"{family:<18} {len(rs):>5}  {pct(plan, .5):8.0f} {pct(plan, .95):8.0f} {max(plan):8.0f} {100 * within:6.1f}%"
              f"  {pct(simp, .5):8.0f} {pct(simp, .95):8.0f} {max(simp):8.0f}")


def lengths(problems_path, out_path, ours_path=None):
    import statistics

    import numpy as np
    import vamp

    d = json.load(open(problems_path))
    module, plan, plan_settings, simp_settings = vamp.configure_robot_and_planner_with_kwargs(d["robot"], "rrtc")
    sampler = module.halton()
    theirs = {}
    for family, problems in d["problems"].items():
        for p in problems:
            if not p["valid"]:
                continue
            env = vamp.problem_dict_to_vamp(p)
            sampler.reset()
            r = plan(p["start"], p["goals"], env, plan_settings, sampler)
            if not r.solved:
                continue
            path = module.simplify(r.path, env, simp_settings, sampler).path
            # Indexed: the path object's iterator does not stop at its end.
            points = [np.asarray(path[k], dtype=float) for k in range(len(path))]
            length = sum(float(np.linalg.norm(b - a)) for a, b in zip(points, points[1:]))
            theirs.setdefault(family, {})[int(p["index"])] = length
    json.dump({f: sorted(v.items()) for f, v in theirs.items()}, open(out_path, "w"))
    if ours_path is None:
        for family, v in theirs.items():
            print(f"{family:<24} {len(v):>4} solved  VAMP median length {statistics.median(v.values()):.3f}")
        return
    ours = {}
    for n, line in enumerate(open(ours_path)):
        row = json.loads(line)
        if n == 0 or not row.get("solved"):
            continue
        # `bench mbm` names a family by its folder (`table_pick_ur5`), VAMP's file without the robot.
        family = row["family"].rsplit("_", 1)[0] if row["family"] not in theirs else row["family"]
        ours.setdefault((family, int(row["index"])), []).append(row["path_length"])
    print(f"{'family':<24} {'both':>5}  {'VAMP':>7}  {'ours':>7}  ours / VAMP per problem: median, mean")
    for family, v in theirs.items():
        pairs = [(t, o) for i, t in v.items() for o in ours.get((family, i), []) if t > 0]
        if not pairs:
            print(f"{family:<24} no problem solved by both")
            continue
        ratios = [o / t for t, o in pairs]
        print(f"{family:<24} {len(pairs):>5}  {statistics.median(t for t, _ in pairs):7.3f}  "
              f"{statistics.median(o for _, o in pairs):7.3f}  {statistics.median(ratios):.3f}, {statistics.mean(ratios):.3f}")


if __name__ == "__main__":
    if len(sys.argv) in (4, 5) and sys.argv[1] == "convert":
        convert(*sys.argv[2:])
    elif len(sys.argv) == 3 and sys.argv[1] == "summarize":
        summarize(sys.argv[2])
    elif len(sys.argv) in (4, 5) and sys.argv[1] == "lengths":
        lengths(*sys.argv[2:])
    else:
        sys.exit(__doc__)
