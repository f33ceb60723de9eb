"""Writing box-scene problems for `embodied bench mbm` and for VAMP (shared by
panda/problems.py and fetch/problems.py).

A scene is a list of boxes (centre, half extents), axis-aligned in the robot's base frame; a
problem is a start and a goal of the planning group's joints.
"""
import os


def table(rng, x0, lift):
    """Boxes and hand regions of a two-board table with posts: the boards at 0.35 and 0.9 m
    plus `lift`, centred `x0` (± 0.05) in front of the robot."""
    x = x0 + rng.uniform(-0.05, 0.05)
    boxes = [((x, 0, 0.35 + lift), (0.3, 0.6, 0.02)), ((x, 0, 0.9 + lift), (0.3, 0.6, 0.02))]
    for _ in range(3):
        boxes.append(((x + rng.uniform(-0.2, 0.2), rng.uniform(-0.5, 0.5), 0.45 + lift), (0.04, 0.04, 0.08)))
    regions = [((x - 0.1, side * 0.35, 0.6 + lift), (0.12, 0.15, 0.1)) for side in (-1, 1)]
    return boxes, regions


def cage(rng, x0, floor):
    """Boxes and hand regions of a cage open towards the robot, on a table: its floor at `floor`
    m, centred `x0` (± 0.05) in front of the robot; two regions outside it, one inside."""
    x, y = x0 + rng.uniform(-0.05, 0.05), rng.uniform(-0.15, 0.15)
    inner, wall = 0.15, 0.02
    top = floor + 2 * inner
    boxes = [((x + 0.1, y, floor - 0.02), (0.35, 0.6, 0.02))]  # the table
    boxes.append(((x, y, floor - wall), (inner + wall, inner + wall, wall)))  # the cage's floor
    boxes.append(((x, y, top + wall), (inner + wall, inner + wall, wall)))  # its roof
    boxes.append(((x + inner + wall, y, floor + inner), (wall, inner + wall, inner)))  # its back
    for side in (-1, 1):
        boxes.append(((x, y + side * (inner + wall), floor + inner), (inner + wall, wall, inner)))
    outside = [((x - 0.1, y + side * 0.4, floor + 0.25), (0.1, 0.1, 0.1)) for side in (-1, 1)]
    inside = ((x + 0.02, y, floor + inner), (0.06, 0.06, 0.06))
    return boxes, outside + [inside]


def numbers(values):
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def write(folder, index, boxes, start, goal, robot, group, joints):
    """FOLDER/sceneNNNN.yaml and requestNNNN.yaml, the layout `bench mbm` reads."""
    os.makedirs(folder, exist_ok=True)
    scene = [f"robot_model_name: {robot}", "name: \"\"", "world:", "  collision_objects:"]
    for k, (centre, half) in enumerate(boxes):
        scene += [f"    - id: box{k}", "      primitives:", "        - type: box",
                  f"          dimensions: {numbers(2 * h for h in half)}",
                  "      primitive_poses:", f"        - position: {numbers(centre)}",
                  "          orientation: [0, 0, 0, 1]"]
    with open(os.path.join(folder, f"scene{index:04d}.yaml"), "w") as f:
        f.write("\n".join(scene) + "\n")
    request = ["goal_constraints:", "  - joint_constraints:"]
    for name, v in zip(joints, goal):
        request += [f"      - joint_name: {name}", f"        position: {float(v)!r}"]
    request += [f"group_name: {group}", "start_state:", "  joint_state:",
                f"    position: {numbers(start)}", f"    name: [{', '.join(joints)}]"]
    with open(os.path.join(folder, f"request{index:04d}.yaml"), "w") as f:
        f.write("\n".join(request) + "\n")


def vamp_row(family, index, boxes, start, goal):
    """The problem as a row of VAMP's problem file (see ../../shared/peers/vamp/vamp_run.py)."""
    return {"problem": family, "index": index, "valid": True,
            "start": [float(v) for v in start], "goals": [[float(v) for v in goal]],
            "sphere": [], "cylinder": [],
            "box": [{"name": f"box{k}", "position": [float(c) for c in centre],
                     "orientation_euler_xyz": [0.0, 0.0, 0.0], "half_extents": [float(h) for h in half]}
                    for k, (centre, half) in enumerate(boxes)]}
