#!/usr/bin/env python3
"""Franka Panda problems for `embodied bench mbm` and for VAMP, on the same spherized model.

  problems.py OUT_DIR [COUNT] [SEED]

Writes OUT_DIR/<family>/sceneNNNN.yaml + requestNNNN.yaml (the layout `bench mbm` reads) for three
families, COUNT problems each (default 50), and OUT_DIR/vamp.json (the problem file of
../../../../shared/peers/vamp/vamp_run.py):

  shelf_panda  a bookshelf 0.65 m in front of the robot, three shelves of two compartments; the hand
               starts in one compartment and ends in another.
  table_panda  a table with a second board 0.55 m above it and three posts on it; the hand goes
               from one side of the posts to the other between the boards.
  cage_panda   a cage on a table (floor, roof, back and side walls, open at the front, 0.3 m
               wide, deep and high inside); the hand goes from above the table beside the cage
               into it.

Starts and goals are drawn uniformly within the joint limits until the hand lies in the wanted
region and VAMP calls the configuration valid; a pair whose straight motion VAMP finds valid is
drawn again. Needs NumPy and the vamp-planner wheel (the venv `compare-mbm` creates):

  ~/.cache/embodied-vamp-venv/bin/python benches/peers/panda/problems.py /tmp/panda
  embodied bench mbm --urdf benches/peers/panda/panda_spherized.urdf \
      --srdf benches/peers/panda/panda.srdf --problems /tmp/panda --out ours.json
  ~/.cache/embodied-vamp-venv/bin/python ../shared/peers/vamp/vamp_run.py /tmp/panda/vamp.json vamp.json
  ~/.cache/embodied-vamp-venv/bin/python benches/peers/mbm_vamp.py summarize vamp.json
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import box_problems  # noqa: E402
from box_problems import vamp_row, write  # noqa: E402
import vamp

JOINTS = [f"panda_joint{i}" for i in range(1, 8)]
LOWER = np.array(vamp.panda.lower_bounds())
UPPER = np.array(vamp.panda.upper_bounds())
DRAWS = 400_000


def shelf(rng):
    """Boxes (centre, half extents) and hand regions of a bookshelf scene."""
    x, y = 0.65 + rng.uniform(-0.05, 0.05), rng.uniform(-0.1, 0.1)
    depth, width, board = 0.3, 0.8, 0.02
    boxes = [((x + depth / 2, y, 0.8), (board, width / 2, 0.8))]
    for z in (0.0, 0.35, 0.7, 1.05, 1.4):
        boxes.append(((x, y, z + 0.2), (depth / 2, width / 2, board)))
    for side in (-1, 0, 1):
        boxes.append(((x, y + side * width / 2, 0.8), (depth / 2, board, 0.8)))
    regions = [((x - 0.05, y + side * 0.2, z + 0.37), (0.1, 0.12, 0.1))
               for z in (0.0, 0.35, 0.7) for side in (-1, 1)]
    return boxes, regions


def table(rng):
    return box_problems.table(rng, 0.6, 0.0)


def cage(rng):
    return box_problems.cage(rng, 0.55, 0.3)


def environment(boxes):
    env = vamp.Environment()
    for centre, half in boxes:
        env.add_cuboid(vamp.Cuboid(list(centre), [0, 0, 0], list(half)))
    return env


def draw(rng, env, region):
    """A valid configuration with the hand in the box region (centre, half extents), or None."""
    centre, half = np.array(region[0]), np.array(region[1])
    for _ in range(DRAWS):
        q = rng.uniform(LOWER, UPPER)
        hand = vamp.panda.eefk(q.tolist())[:3, 3]
        if np.all(np.abs(hand - centre) <= half) and vamp.panda.validate(q.tolist(), env):
            return q
    return None


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    count = int(sys.argv[2]) if len(sys.argv) > 2 else 50
    rng = np.random.default_rng(int(sys.argv[3]) if len(sys.argv) > 3 else 7)
    problems = {}
    for family, scene in (("shelf_panda", shelf), ("table_panda", table), ("cage_panda", cage)):
        rows = []
        while len(rows) < count:
            boxes, regions = scene(rng)
            env = environment(boxes)
            if family == "cage_panda":
                # From outside into the cage.
                a, b = rng.integers(0, len(regions) - 1), len(regions) - 1
            else:
                a, b = rng.choice(len(regions), 2, replace=False)
            start, goal = draw(rng, env, regions[a]), draw(rng, env, regions[b])
            if start is None or goal is None or vamp.panda.validate_motion(start.tolist(), goal.tolist(), env):
                continue
            index = len(rows) + 1
            write(os.path.join(out, family), index, boxes, start, goal, "panda", "panda_arm", JOINTS)
            rows.append(vamp_row(family, index, boxes, start, goal))
        problems[family] = rows
    with open(os.path.join(out, "vamp.json"), "w") as f:
        json.dump({"robot": "panda", "problems": problems}, f)


if __name__ == "__main__":
    main()
