"""Writing box-scene problems for `embodied bench mbm` and for VAMP (shared by
panda/problems.py and fetch/problems.py).

A scene is a list of boxes (centre, half extents), axis-aligned in the robot's base frame; a
problem is a start and a goal of the planning group's joints.
"""
import os


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
