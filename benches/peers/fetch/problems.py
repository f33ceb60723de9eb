#!/usr/bin/env python3
"""Fetch problems for `embodied bench mbm` and for VAMP, on the same spherized model.

  problems.py OUT_DIR [COUNT] [SEED] [--without-vamp]

Writes OUT_DIR/<family>/sceneNNNN.yaml + requestNNNN.yaml (the layout `bench mbm` reads) for three
families, COUNT problems each (default 50), and OUT_DIR/vamp.json (the problem file of
../../../../shared/peers/vamp/vamp_run.py). The planning group is fetch.srdf's `arm_with_torso`:
torso_lift_joint (prismatic, 0-0.386 m) and the seven arm joints, in the order of vamp.fetch.

  shelf_fetch  a bookshelf 0.85 m in front of the robot, three shelves of two compartments (0.5-1.55
               m high); the hand starts in one compartment and ends in another.
  table_fetch  a table 0.7 m high with a second board 0.55 m above it and three posts on it; the hand
               goes from one side of the posts to the other between the boards.
  cage_fetch   a cage on a table 0.7 m high (floor, roof, back and side walls, open towards the
               robot, 0.3 m wide, deep and high inside); the hand goes from above the table beside
               the cage into it.

Starts and goals are drawn uniformly within the joint limits until the hand (gripper_link) lies in
the wanted region and the configuration is valid; a pair whose straight motion is valid is drawn
again. The checker is vamp.fetch (validate, validate_motion, eefk). With --without-vamp, or where
the vamp module cannot be imported, it is a NumPy model of the same spheres read from
fetch_spherized.urdf (self-collision between the link pairs fetch.srdf does not disable, straight
motions sampled every 0.01 rad / 0.005 m): the problems are then valid for that model, not checked
by VAMP. Needs NumPy (and the vamp-planner wheel for VAMP's checker):

  ~/.cache/embodied-vamp-venv/bin/python benches/peers/fetch/problems.py /tmp/fetch
  embodied bench mbm --urdf benches/peers/fetch/fetch_spherized.urdf \
      --srdf benches/peers/fetch/fetch.srdf --problems /tmp/fetch --out ours.json
  ~/.cache/embodied-vamp-venv/bin/python ../shared/peers/vamp/vamp_run.py /tmp/fetch/vamp.json vamp.json
  ~/.cache/embodied-vamp-venv/bin/python benches/peers/mbm_vamp.py summarize vamp.json
"""
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import box_problems  # noqa: E402
from box_problems import vamp_row, write  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
JOINTS = ["torso_lift_joint", "shoulder_pan_joint", "shoulder_lift_joint", "upperarm_roll_joint",
          "elbow_flex_joint", "forearm_roll_joint", "wrist_flex_joint", "wrist_roll_joint"]
HAND = "gripper_link"
DRAWS = 400_000
BATCH = 4096


def rotation(rpy):
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def axis_rotations(axis, angles):
    """Rotation matrices (n, 3, 3) about the unit axis by each angle (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


class Spheres:
    """The URDF's collision spheres, with batched forward kinematics and validity checks."""

    def __init__(self, urdf, srdf):
        root = ET.parse(urdf).getroot()
        vec = lambda e, key, default: np.array([float(v) for v in (e.get(key) if e is not None and e.get(key) else default).split()])
        self.links = [l.get("name") for l in root.findall("link")]
        self.balls = {}
        for l in root.findall("link"):
            for c in l.findall("collision"):
                o = c.find("origin")
                self.balls.setdefault(l.get("name"), []).append(
                    (vec(o, "xyz", "0 0 0"), float(c.find("geometry/sphere").get("radius"))))
        self.joints = {}
        for j in root.findall("joint"):
            o, a, lim = j.find("origin"), j.find("axis"), j.find("limit")
            self.joints[j.find("child").get("link")] = dict(
                name=j.get("name"), type=j.get("type"), parent=j.find("parent").get("link"),
                xyz=vec(o, "xyz", "0 0 0"), rot=rotation(vec(o, "rpy", "0 0 0")),
                axis=vec(a, "xyz", "1 0 0"),
                limits=(float(lim.get("lower")), float(lim.get("upper"))) if lim is not None else None)
        by_name = {j["name"]: j for j in self.joints.values()}
        self.lower = np.array([by_name[n]["limits"][0] for n in JOINTS])
        self.upper = np.array([by_name[n]["limits"][1] for n in JOINTS])
        disabled = {frozenset((d.get("link1"), d.get("link2")))
                    for d in ET.parse(srdf).getroot().findall("disable_collisions")}
        with_balls = [l for l in self.links if l in self.balls]
        self.pairs = [(a, b) for i, a in enumerate(with_balls) for b in with_balls[i + 1:]
                      if frozenset((a, b)) not in disabled]
        self.order = []  # links, parents first
        placed = {l for l in self.links if l not in self.joints}
        while len(placed) < len(self.links):
            for child, j in self.joints.items():
                if child not in placed and j["parent"] in placed:
                    self.order.append(child)
                    placed.add(child)
        self.roots = [l for l in self.links if l not in self.joints]

    def poses(self, qs):
        """Each link's world rotation (n, 3, 3) and translation (n, 3) at the configurations qs."""
        n = len(qs)
        out = {l: (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3))) for l in self.roots}
        for child in self.order:
            j = self.joints[child]
            pr, pt = out[j["parent"]]
            r = pr @ j["rot"]
            t = pt + pr @ j["xyz"]
            if j["name"] in JOINTS:
                v = qs[:, JOINTS.index(j["name"])]
                if j["type"] == "prismatic":
                    t = t + (r @ j["axis"]) * v[:, None]
                else:
                    r = r @ axis_rotations(j["axis"], v)
            out[child] = (r, t)
        return out

    def hands(self, qs):
        return self.poses(qs)[HAND][1]

    def valid(self, qs, boxes):
        """Per configuration: no sphere in a box (axis-aligned), no self-collision."""
        poses = self.poses(qs)
        centres = {l: poses[l][1][:, None, :] + np.einsum("nij,kj->nki", poses[l][0], np.array([c for c, _ in b]))
                   for l, b in self.balls.items()}
        radii = {l: np.array([r for _, r in b]) for l, b in self.balls.items()}
        ok = np.ones(len(qs), bool)
        for centre, half in boxes:
            lo, hi = np.array(centre) - half, np.array(centre) + half
            for l in self.balls:
                d = centres[l] - np.clip(centres[l], lo, hi)
                ok &= ~np.any(np.einsum("nki,nki->nk", d, d) <= radii[l] ** 2, axis=1)
        for a, b in self.pairs:
            d = centres[a][:, :, None, :] - centres[b][:, None, :, :]
            r = radii[a][:, None] + radii[b][None, :]
            ok &= ~np.any(np.einsum("nkmi,nkmi->nkm", d, d) <= r ** 2, axis=(1, 2))
        return ok

    def valid_motion(self, a, b, boxes):
        steps = np.abs(b - a) / np.where(np.arange(len(a)) == 0, 0.005, 0.01)
        n = max(2, int(np.ceil(steps.max())) + 1)
        return bool(np.all(self.valid(a + np.linspace(0, 1, n)[:, None] * (b - a), boxes)))


class VampChecker:
    def __init__(self, vamp):
        self.vamp = vamp
        self.lower, self.upper = np.array(vamp.fetch.lower_bounds()), np.array(vamp.fetch.upper_bounds())

    def env(self, boxes):
        env = self.vamp.Environment()
        for centre, half in boxes:
            env.add_cuboid(self.vamp.Cuboid(list(centre), [0, 0, 0], list(half)))
        return env

    def hands(self, qs):
        return np.array([self.vamp.fetch.eefk(q.tolist())[:3, 3] for q in qs])

    def valid(self, qs, boxes):
        env = self.env(boxes)
        return np.array([self.vamp.fetch.validate(q.tolist(), env) for q in qs])

    def valid_motion(self, a, b, boxes):
        return self.vamp.fetch.validate_motion(a.tolist(), b.tolist(), self.env(boxes))


def shelf(rng):
    """Boxes (centre, half extents) and hand regions of a bookshelf scene."""
    x, y = 0.85 + rng.uniform(-0.05, 0.05), rng.uniform(-0.1, 0.1)
    depth, width, board = 0.3, 0.8, 0.02
    boxes = [((x + depth / 2, y, 0.9), (board, width / 2, 0.9))]
    for z in (0.5, 0.85, 1.2, 1.55):
        boxes.append(((x, y, z), (depth / 2, width / 2, board)))
    for side in (-1, 0, 1):
        boxes.append(((x, y + side * width / 2, 0.9), (depth / 2, board, 0.9)))
    regions = [((x - 0.05, y + side * 0.2, z + 0.17), (0.1, 0.12, 0.08))
               for z in (0.5, 0.85, 1.2) for side in (-1, 1)]
    return boxes, regions


def table(rng):
    return box_problems.table(rng, 0.8, 0.35)


def cage(rng):
    return box_problems.cage(rng, 0.8, 0.72)


def draw(rng, check, boxes, region):
    """A valid configuration with the hand in the box region (centre, half extents), or None."""
    centre, half = np.array(region[0]), np.array(region[1])
    for _ in range(DRAWS // BATCH):
        qs = rng.uniform(check.lower, check.upper, (BATCH, len(JOINTS)))
        inside = qs[np.all(np.abs(check.hands(qs) - centre) <= half, axis=1)]
        if len(inside):
            good = inside[check.valid(inside, boxes)]
            if len(good):
                return good[0]
    return None


def checker(without_vamp):
    if not without_vamp:
        # In a child first: a wheel built for another processor dies on import (SIGILL).
        probe = subprocess.run([sys.executable, "-c", "import vamp"], capture_output=True)
        if probe.returncode == 0:
            import vamp
            return VampChecker(vamp), "vamp.fetch"
        print(f"vamp cannot be imported (exit status {probe.returncode}): the NumPy model of the "
              "spheres checks instead", file=sys.stderr)
    return Spheres(os.path.join(HERE, "fetch_spherized.urdf"), os.path.join(HERE, "fetch.srdf")), "NumPy spheres"


def main():
    args = [a for a in sys.argv[1:] if a != "--without-vamp"]
    if not args:
        sys.exit(__doc__)
    out = args[0]
    count = int(args[1]) if len(args) > 1 else 50
    rng = np.random.default_rng(int(args[2]) if len(args) > 2 else 7)
    check, name = checker("--without-vamp" in sys.argv)
    problems = {}
    for family, scene in (("shelf_fetch", shelf), ("table_fetch", table), ("cage_fetch", cage)):
        rows = []
        while len(rows) < count:
            boxes, regions = scene(rng)
            boxes = [(c, np.array(h)) for c, h in boxes]
            if family == "cage_fetch":
                # From outside into the cage.
                a, b = rng.integers(0, len(regions) - 1), len(regions) - 1
            else:
                a, b = rng.choice(len(regions), 2, replace=False)
            start, goal = draw(rng, check, boxes, regions[a]), draw(rng, check, boxes, regions[b])
            if start is None or goal is None or check.valid_motion(start, goal, boxes):
                continue
            index = len(rows) + 1
            write(os.path.join(out, family), index, boxes, start, goal, "fetch", "arm_with_torso", JOINTS)
            rows.append(vamp_row(family, index, boxes, start, goal))
        problems[family] = rows
        print(f"{family}: {len(rows)} problems", file=sys.stderr)
    with open(os.path.join(out, "vamp.json"), "w") as f:
        json.dump({"robot": "fetch", "checked_by": name, "problems": problems}, f)


if __name__ == "__main__":
    main()
