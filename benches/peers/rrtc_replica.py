#!/usr/bin/env python3
"""VAMP's RRT-Connect loop written out in Python over VAMP's own collision checks and Halton
sampler, to count iterations under variants of the sampler and the dynamic domain.

  rrtc_replica.py PROBLEMS.json [FAMILY] [COUNT] [SEEDS]

PROBLEMS.json is a VAMP problem file (`mbm_vamp.py convert`, or ../shared/peers/vamp/ur5-public.json);
FAMILY one of its families (default: the first), COUNT its first problems (default 20), SEEDS the
runs of each variant with uniform samples (default 3). Run it in the virtual environment
`compare-mbm` makes (it needs the `vamp` module and NumPy).

For each valid problem it runs VAMP's compiled RRT-Connect (`rrtc`, Halton sampler reset per
problem, as `vamp_run.py`) and the replica with the same settings: the replica follows the same
steps (balance by tree sizes, dynamic domain, one extension of at most `range`, then the new node
run straight at the other tree's nearest node in equal increments), so with VAMP's Halton sampler
its iteration counts should equal the compiled planner's (they differ only where float rounding
of the two diverges: the line "same iterations" counts the problems where they agree). Then the
replica with the Halton sequence started one point later, with the dynamic domain off, and with
uniform random samples with and without it. It prints the median and mean iterations of each (an
iteration is one sample, rejected or not).
"""
import statistics
import sys


class Skipping:
    """A VAMP sampler whose `reset` also draws its first `k` points: the sequence from point k + 1."""

    def __init__(self, sampler, k):
        self.sampler, self.k = sampler, k

    def reset(self):
        self.sampler.reset()
        for _ in range(self.k):
            self.sampler.next()

    def next(self):
        return self.sampler.next()


def replica(module, settings, p, env, sampler, uniform_rng=None, dynamic_domain=True):
    """Iterations until the trees meet (None when `max_iterations` run out)."""
    import numpy as np

    dim = module.dimension()
    lo = np.array(module.lower_bounds(), dtype=np.float32)[:dim]
    hi = np.array(module.upper_bounds(), dtype=np.float32)[:dim]
    nodes = [np.array(p["start"], dtype=np.float32)] + [np.array(g, dtype=np.float32) for g in p["goals"]]
    radius = [np.inf] * len(nodes)
    trees = {0: [0], 1: list(range(1, len(nodes)))}
    # VAMP swaps before each iteration, starting from the goal tree: the start tree grows first.
    a, b = 1, 0
    sampler.reset()
    reach = settings.range

    def free(q, v):
        return module.validate_motion([float(x) for x in q], [float(x) for x in q + v], env)

    def nearest(tree, q):
        ids = trees[tree]
        dist = np.linalg.norm(np.array([nodes[i] for i in ids]) - q, axis=1)
        k = int(np.argmin(dist))
        return ids[k], float(dist[k])

    for it in range(1, settings.max_iterations + 1):
        if abs(len(trees[a]) - len(trees[b])) / len(trees[a]) < settings.tree_ratio or not settings.balance:
            a, b = b, a
        if uniform_rng is None:
            s = np.array(list(sampler.next()), dtype=np.float32)[:dim]
        else:
            s = (lo + (hi - lo) * uniform_rng.random(dim)).astype(np.float32)
        near, d = nearest(a, s)
        r = radius[near]
        if dynamic_domain and r < d:
            continue
        step = (s - nodes[near]) if d < reach else (s - nodes[near]) * (reach / d)
        if free(nodes[near], step):
            new = nodes[near] + step
            nodes.append(new)
            radius.append(np.inf)
            trees[a].append(len(nodes) - 1)
            if dynamic_domain and r != np.inf:
                radius[near] *= 1 + settings.alpha
            other, od = nearest(b, new)
            n = max(1, int(np.ceil(od / reach)))
            inc = (nodes[other] - new) / n
            prior, done = new, 0
            while done < n and free(prior, inc):
                prior = prior + inc
                nodes.append(prior)
                radius.append(np.inf)
                trees[a].append(len(nodes) - 1)
                done += 1
            if done == n:
                return it
        elif dynamic_domain:
            radius[near] = settings.radius if r == np.inf else max(r * (1 - settings.alpha), settings.min_radius)
    return None


def main():
    import json

    import numpy as np
    import vamp

    args = sys.argv[1:]
    if not 1 <= len(args) <= 4:
        sys.exit("usage: rrtc_replica.py PROBLEMS.json [FAMILY] [COUNT] [SEEDS]")
    try:
        with open(args[0]) as f:
            d = json.load(f)
        problems = d["problems"]
        robot = d["robot"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        sys.exit(f"{args[0]}: not a VAMP problem file with 'robot' and 'problems' ({e})")
    family = args[1] if len(args) > 1 else next(iter(problems), None)
    if family not in problems:
        sys.exit(f"{args[0]}: no family {family!r}; it has {', '.join(problems) or 'none'}")
    try:
        count = int(args[2]) if len(args) > 2 else 20
        seeds = int(args[3]) if len(args) > 3 else 3
    except ValueError as e:
        sys.exit(f"COUNT and SEEDS must be whole numbers ({e})")
    if count < 1 or seeds < 1:
        sys.exit("COUNT and SEEDS must be at least 1")
    module, plan, settings, _ = vamp.configure_robot_and_planner_with_kwargs(robot, "rrtc")
    sampler = module.halton()
    rows = {"VAMP (compiled)": [], "replica, Halton": [], "replica, Halton from its second point": [],
            "replica, Halton, no dynamic domain": [],
            "replica, uniform": [], "replica, uniform, no dynamic domain": []}
    same = 0
    for p in problems[family][:count]:
        if not p.get("valid"):
            continue
        env = vamp.problem_dict_to_vamp(p)
        sampler.reset()
        compiled = plan(p["start"], p["goals"], env, settings, sampler).iterations
        rows["VAMP (compiled)"].append(compiled)
        it = replica(module, settings, p, env, sampler)
        same += it == compiled
        rows["replica, Halton"].append(it)
        rows["replica, Halton from its second point"].append(replica(module, settings, p, env, Skipping(sampler, 1)))
        rows["replica, Halton, no dynamic domain"].append(replica(module, settings, p, env, sampler, dynamic_domain=False))
        for seed in range(seeds):
            rows["replica, uniform"].append(replica(module, settings, p, env, sampler, np.random.default_rng(seed)))
            rows["replica, uniform, no dynamic domain"].append(
                replica(module, settings, p, env, sampler, np.random.default_rng(seed), dynamic_domain=False))
    if not rows["VAMP (compiled)"]:
        sys.exit(f"{args[0]}: the first {count} problems of {family} hold no valid one")
    print(f"{family}: {len(rows['VAMP (compiled)'])} valid problems; same iterations as compiled: {same}")
    for name, its in rows.items():
        done = [i for i in its if i is not None]
        figures = f"median {statistics.median(done):8.1f}  mean {sum(done) / len(done):8.1f}" if done else "none solved"
        print(f"  {name:38s} {figures}  unsolved {len(its) - len(done)}")


if __name__ == "__main__":
    main()
